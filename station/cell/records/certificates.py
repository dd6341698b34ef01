"""The Digital Calibration Certificate written for a run, kept in the run database as written
(issue 41): ``station export-dcc`` records its bytes here, so that the OPC UA server and the
fleet store (and through it the QA dashboard) offer the same bytes as the file.

A certificate is not rebuilt where it is offered: it is made from the issuer file (laboratory,
customer, approver), which no cell file holds, and from the run's whole record, which the fleet
store does not keep. One certificate per run: exporting again (another issuer or operator)
replaces it, and the new one is sent to the fleet again.
"""

from __future__ import annotations

import hashlib
import sqlite3
from dataclasses import dataclass
from pathlib import Path

from station.cell.records.run_records import utc_now

__all__ = ["CERTIFICATE_TABLE", "StoredCertificate", "record_certificate", "stored_certificate"]

CERTIFICATE_TABLE = """CREATE TABLE IF NOT EXISTS certificates (
    run_id          INTEGER PRIMARY KEY REFERENCES runs(id) ON DELETE CASCADE,
    schema_version  TEXT NOT NULL,          -- the DCC schema it was validated against
    sha256          TEXT NOT NULL,          -- of xml, hex
    xml             BLOB NOT NULL,          -- the certificate as written, byte for byte
    written_utc     TEXT NOT NULL,
    fleet_sent_utc  TEXT                    -- NULL: not yet in the fleet store
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


def record_certificate(db_path: str | Path, run_id: int, xml: bytes, schema_version: str) -> StoredCertificate:
    """Keep ``xml`` as run ``run_id``'s certificate (replacing an earlier one; the same bytes
    again change nothing, so a repeated export is not sent twice)."""
    digest = hashlib.sha256(xml).hexdigest()
    conn = _open(db_path)
    try:
        conn.execute(CERTIFICATE_TABLE)
        with conn:
            conn.execute("BEGIN IMMEDIATE")
            old = conn.execute("SELECT sha256 FROM certificates WHERE run_id = ?", (run_id,)).fetchone()
            if old is None or old[0] != digest:
                conn.execute("INSERT OR REPLACE INTO certificates (run_id, schema_version, sha256, xml, written_utc, "
                             "fleet_sent_utc) VALUES (?, ?, ?, ?, ?, NULL)",
                             (run_id, schema_version, digest, xml, utc_now()))
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
