"""Sending a run's Digital Calibration Certificate (as ``station export-dcc`` recorded it in the run
database, :mod:`station.cell.records.certificates`) to the fleet store, after the run itself.

A certificate goes with the publication of the ending it was made from (its UUID in the queue)
once that is in the store; until then, or while the store is unreachable, it stays marked unsent and ``station
sync`` sends it. Never raises for the network or the store.
"""

from __future__ import annotations

import sqlite3
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from station.cell.records.certificates import ensure_certificate_table
from station.cell.records.run_records import utc_now

__all__ = ["CertificateSync", "send_certificates"]


@dataclass(frozen=True)
class CertificateSync:
    sent: int = 0  # new in the store
    waiting: int = 0  # their run is not in the store yet (or is not queued for it)
    failed: int = 0
    error: str = ""

    @property
    def ok(self) -> bool:
        return self.failed == 0


# the publication of the ending the certificate was made from, once that is in the store (NULL
# until then: the certificate waits); a row from before summary_utc: the run's latest ending
_TODO = """SELECT c.run_id, c.sha256, c.schema_version, c.xml,
                  (SELECT CASE WHEN o.sent_utc IS NOT NULL THEN o.run_uuid END FROM fleet_outbox o
                    WHERE o.run_id = c.run_id AND (c.summary_utc IS NULL OR o.summary_utc = c.summary_utc)
                    ORDER BY o.summary_utc DESC LIMIT 1)
             FROM certificates c WHERE c.fleet_sent_utc IS NULL {only} ORDER BY c.run_id"""


def _todo(db_path: str | Path, only_run: int | None) -> list[tuple[Any, ...]]:
    conn = sqlite3.connect(str(db_path), timeout=30.0)
    try:
        tables = {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        if not {"certificates", "fleet_outbox"} <= tables:
            return []
        ensure_certificate_table(conn)  # a database from before summary_utc
        only = "" if only_run is None else "AND c.run_id = ?"
        return list(conn.execute(_TODO.format(only=only), () if only_run is None else (only_run,)))
    finally:
        conn.close()


def send_certificates(db_path: str | Path, url: str, *, only_run: int | None = None,
                      connect: Callable[[str], Any] | None = None) -> CertificateSync:
    """Send the unsent certificates of ``db_path`` whose run is in the store at ``url``."""
    from station.fleet import store  # psycopg: imported when something is sent

    todo = _todo(db_path, only_run)
    ready = [t for t in todo if t[4] is not None]
    waiting = len(todo) - len(ready)
    if not ready:
        return CertificateSync(waiting=waiting)
    try:
        conn = (connect or store.connect)(url)
    except store.FleetStoreError as exc:
        return CertificateSync(waiting=waiting, failed=len(ready), error=str(exc))
    sent = failed = 0
    error = ""
    local = sqlite3.connect(str(db_path), timeout=30.0, isolation_level=None)
    try:
        with conn:
            for i, (run_id, digest, version, xml, run_uuid) in enumerate(ready):
                try:
                    sent += store.insert_certificate(conn, run_uuid, bytes(xml), version)
                except Exception as exc:  # noqa: BLE001 - psycopg's errors: the connection or the store
                    failed += 1
                    error = error or f"certificate of run {run_id}: {type(exc).__name__}: {exc}".splitlines()[0]
                    if conn.closed or conn.broken:
                        failed += len(ready) - i - 1  # the rest: not tried
                        break
                    continue
                local.execute("UPDATE certificates SET fleet_sent_utc = ? WHERE run_id = ? AND sha256 = ?",
                              (utc_now(), run_id, digest))
    finally:
        local.close()
    return CertificateSync(sent=sent, waiting=waiting, failed=failed, error=error)
