"""The Digital Calibration Certificate written for a run, kept in the run database as written
(issue 41): ``station export-dcc`` records its bytes here, so that the OPC UA server and the
fleet store (and through it the QA dashboard) offer the same bytes as the file.

A certificate is not rebuilt where it is offered: it is made from the issuer file (laboratory,
customer, approver), which no cell file holds, and from the run's whole record, which the fleet
store does not keep. One certificate per run: exporting again (another issuer or operator)
replaces it, and the new one is sent to the fleet again.

A certificate certifies the ending it was made from: ``summary_utc`` is the stored summary's time
when it was written, and it goes to the fleet with that ending's publication. A run resumed after
the export ends again as a new publication (a new UUID), which carries no certificate until one is
exported for it; the earlier one stays with the ending it describes.
"""

from __future__ import annotations

import hashlib
import sqlite3
from dataclasses import dataclass
from pathlib import Path

from station.cell.records.run_records import utc_now

__all__ = ["CERTIFICATE_TABLE", "StoredCertificate", "ensure_certificate_table", "record_certificate",
           "stored_certificate"]

CERTIFICATE_TABLE = """CREATE TABLE IF NOT EXISTS certificates (
    run_id          INTEGER PRIMARY KEY REFERENCES runs(id) ON DELETE CASCADE,
    schema_version  TEXT NOT NULL,          -- the DCC schema it was validated against
    sha256          TEXT NOT NULL,          -- of xml, hex
    xml             BLOB NOT NULL,          -- the certificate as written, byte for byte
    written_utc     TEXT NOT NULL,
    fleet_sent_utc  TEXT,                   -- NULL: not yet in the fleet store
    summary_utc     TEXT                    -- the ending it certifies (results.t_utc of 'summary')
)"""


@dataclass(frozen=True)
class StoredCertificate:
    run_id: int
    schema_version: str
    sha256: str
    xml: bytes
    written_utc: str
    fleet_sent: bool


def _open(db_path: str | Path) -> sqlite3.Connection:
    conn = sqlite3.connect(str(db_path), timeout=30.0, isolation_level=None)
    conn.execute("PRAGMA busy_timeout = 30000")
    conn.execute("PRAGMA foreign_keys = ON")
    return conn


def ensure_certificate_table(conn: sqlite3.Connection) -> None:
    """The table, with ``summary_utc`` added to one written before it existed (such a row is sent
    with the run's latest ending, as it was then)."""
    conn.execute(CERTIFICATE_TABLE)
    columns = {r[1] for r in conn.execute("PRAGMA table_info(certificates)")}
    if "summary_utc" not in columns:
        conn.execute("ALTER TABLE certificates ADD COLUMN summary_utc TEXT")


def record_certificate(db_path: str | Path, run_id: int, xml: bytes, schema_version: str) -> StoredCertificate:
    """Keep ``xml`` as run ``run_id``'s certificate, of the run's ending stored now (replacing an
    earlier one; the same bytes for the same ending again change nothing, so a repeated export is
    not sent twice)."""
    digest = hashlib.sha256(xml).hexdigest()
    conn = _open(db_path)
    try:
        ensure_certificate_table(conn)
        with conn:
            conn.execute("BEGIN IMMEDIATE")
            ending = conn.execute("SELECT t_utc FROM results WHERE run_id = ? AND key = 'summary'",
                                  (run_id,)).fetchone()
            summary_utc = None if ending is None else str(ending[0])
            old = conn.execute("SELECT sha256, summary_utc FROM certificates WHERE run_id = ?", (run_id,)).fetchone()
            if old is None or tuple(old) != (digest, summary_utc):
                conn.execute("INSERT OR REPLACE INTO certificates (run_id, schema_version, sha256, xml, written_utc, "
                             "fleet_sent_utc, summary_utc) VALUES (?, ?, ?, ?, ?, NULL, ?)",
                             (run_id, schema_version, digest, xml, utc_now(), summary_utc))
    finally:
        conn.close()
    found = stored_certificate(db_path, run_id)
    assert found is not None
    return found


def stored_certificate(db_path: str | Path, run_id: int) -> StoredCertificate | None:
    """Run ``run_id``'s certificate as written; None when none was (or the database has no table
    for them: a station that never exported one)."""
    if not Path(db_path).is_file():
        return None
    conn = _open(db_path)
    try:
        has = conn.execute("SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = 'certificates'").fetchone()
        if has is None:
            return None
        row = conn.execute("SELECT run_id, schema_version, sha256, xml, written_utc, fleet_sent_utc FROM certificates "
                           "WHERE run_id = ?", (run_id,)).fetchone()
    finally:
        conn.close()
    if row is None:
        return None
    return StoredCertificate(int(row[0]), str(row[1]), str(row[2]), bytes(row[3]), str(row[4]), row[5] is not None)
