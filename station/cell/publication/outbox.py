"""Store and forward: the station's queue of publications, a table ``fleet_outbox`` in its own
run database, and sending it to the fleet store.

A finished run is queued first (its publication and a new UUID, committed), then sent; what
cannot be sent stays queued and ``station sync`` sends it later. The store inserts by UUID with
``ON CONFLICT DO NOTHING``: a retry, a sync that died between the store's commit and ours, or two
syncs of one queue at once never make a second row, and nothing leaves the queue unsent. A run
never waits on the network longer than the connection timeout and never fails because of it.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import os
import sqlite3
import stat
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from station.cell.config.cell_config import CellConfig
from station.cell.publication.payload import build_publication
from station.cell.records.run_records import utc_now
from station.cell.records.rundb import RunDB
from station.fleet.settings import fleet_url

log = logging.getLogger(__name__)

__all__ = ["OUTBOX_TABLE", "QueueEntry", "SyncResult", "enqueue_run", "enqueue_finished", "attach_report", "pending", "sync",
           "publish_or_queue", "queue_state"]

OUTBOX_TABLE = """CREATE TABLE IF NOT EXISTS fleet_outbox (
    run_uuid        TEXT PRIMARY KEY,       -- the publication's identity in the fleet store
    run_id          INTEGER NOT NULL REFERENCES runs(id) ON DELETE CASCADE,
    summary_utc     TEXT NOT NULL,          -- the ending it publishes (a resumed run ends again)
    publication     TEXT NOT NULL,          -- JSON: what the store receives (station/cell/publication/payload.py)
    queued_utc      TEXT NOT NULL,
    sent_utc        TEXT,                   -- NULL: not yet in the store
    attempts        INTEGER NOT NULL DEFAULT 0,
    last_error      TEXT NOT NULL DEFAULT '',
    report_path     TEXT,                   -- the report.html written for the run, once there is one
    report_sent_utc TEXT,
    UNIQUE (run_id, summary_utc)
)"""


@dataclass(frozen=True)
class QueueEntry:
    run_id: int
    run_uuid: str
    publication: dict[str, Any]
    sent: bool
    report_path: str | None
    report_sent: bool
    attempts: int
    last_error: str


@dataclass(frozen=True)
class SyncResult:
    sent: int = 0  # new in the store
    already: int = 0  # the store held them already (a retry, another sync)
    reports: int = 0
    failed: int = 0  # still queued
    error: str = ""  # why (the first failure)

    @property
    def ok(self) -> bool:
        return self.failed == 0


def _open(db_path: str | Path, create: bool = True) -> sqlite3.Connection:
    """The run database with its queue table (created when ``create``; otherwise a database
    without one is opened as it is and the queries find nothing)."""
    conn = sqlite3.connect(str(db_path), timeout=30.0, isolation_level=None)
    conn.execute("PRAGMA busy_timeout = 30000")
    conn.execute("PRAGMA foreign_keys = ON")
    if create:
        conn.execute(OUTBOX_TABLE)
    return conn


def _has_queue(conn: sqlite3.Connection) -> bool:
    return conn.execute("SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = 'fleet_outbox'").fetchone() is not None


def enqueue_run(db_path: str | Path, run_id: int, cfg: CellConfig, db: RunDB | None = None) -> str:
    """Queue the ending of run ``run_id`` (its stored summary) once: queued again, the same
    ending keeps its UUID and publication; a resumed run that ends again is a new publication.
    Returns its UUID. ``db``: the session's open run database (else it is opened here)."""
    conn = _open(db_path)
    try:
        now = utc_now()
        stored = conn.execute("SELECT t_utc FROM results WHERE run_id = ? AND key = 'summary'", (run_id,)).fetchone()
        finished = str(stored[0]) if stored else now  # when its summary was stored: the run's end
        row = conn.execute("SELECT run_uuid FROM fleet_outbox WHERE run_id = ? AND summary_utc = ?",
                           (run_id, finished)).fetchone()
        if row:
            return str(row[0])
        run_uuid = str(uuid.uuid4())
        if db is None:
            with RunDB(db_path) as own:
                pub = build_publication(own, run_id, cfg, run_uuid, finished)
        else:
            pub = build_publication(db, run_id, cfg, run_uuid, finished)
        conn.execute("INSERT INTO fleet_outbox (run_uuid, run_id, summary_utc, publication, queued_utc) "
                     "VALUES (?, ?, ?, ?, ?) ON CONFLICT (run_id, summary_utc) DO NOTHING",
                     (run_uuid, run_id, finished, json.dumps(pub), now))
        return str(conn.execute("SELECT run_uuid FROM fleet_outbox WHERE run_id = ? AND summary_utc = ?",
                                (run_id, finished)).fetchone()[0])
    finally:
        conn.close()


def enqueue_finished(db_path: str | Path, station: str | None = None,
                     report_dir: Callable[[int], Path] | None = None) -> tuple[int, list[str]]:
    """Queue every run of ``db_path`` that has a stored summary and is not queued yet (a station
    joining the fleet with its history), each with the configuration it was made with, under
    ``station`` (the current ``[fleet] station``: the runs were made before it was set, and published
    under the host name two stations' histories merged into one robot, issue 39), with the report
    the run wrote where there is one (its summary names it, else ``report_dir(run_id)`` holds it:
    the default folder of ``station report``). Returns how many were queued and, for each run that could
    not be, why."""
    from station.cell.records.reading.stored_config import stored_config

    conn = _open(db_path)
    try:
        todo = [int(r[0]) for r in conn.execute(
            "SELECT r.run_id FROM results r WHERE r.key = 'summary' AND NOT EXISTS "
            "(SELECT 1 FROM fleet_outbox o WHERE o.run_id = r.run_id AND o.summary_utc = r.t_utc) ORDER BY r.run_id")]
    finally:
        conn.close()
    queued, problems = 0, []
    with RunDB(db_path) as db:
        for run_id in todo:
            try:
                cfg = stored_config(db, run_id)
                if station:
                    cfg = dataclasses.replace(cfg, fleet=dataclasses.replace(cfg.fleet, station=station))
                enqueue_run(db_path, run_id, cfg, db)
                queued += 1
            except Exception as exc:  # noqa: BLE001 - one unreadable run does not stop the others
                problems.append(f"run {run_id}: {exc}")
    for run_id in todo:  # the report each run wrote (its summary names it), checked when it is read
        report = _written_report(db_path, run_id, report_dir)
        if report is not None:
            attach_report(db_path, run_id, report)
    return queued, problems


def _written_report(db_path: str | Path, run_id: int, report_dir: Callable[[int], Path] | None) -> str | None:
    """The report.html a run's stored summary names (``calibrate --report``), else the one in its
    default report folder, if it is there."""
    with RunDB(db_path) as db:
        summary = db.load_result(run_id, "summary", default=None)
    named = summary.get("report") if isinstance(summary, dict) else None
    folders = ([Path(named)] if isinstance(named, str) and named else []) + ([report_dir(run_id)] if report_dir else [])
    for folder in folders:
        candidate = folder if folder.suffix == ".html" else folder / "report.html"
        if candidate.is_file():
            return str(candidate)
    return None


def attach_report(db_path: str | Path, run_id: int, report_path: str | Path) -> bool:
    """Remember the report written for a queued run (its latest ending; sent with it, or after
    it); False when the run is not queued for the fleet."""
    conn = _open(db_path, create=False)
    try:
        if not _has_queue(conn):
            return False
        cur = conn.execute("UPDATE fleet_outbox SET report_path = ?, report_sent_utc = NULL WHERE run_uuid = "
                           "(SELECT run_uuid FROM fleet_outbox WHERE run_id = ? ORDER BY summary_utc DESC LIMIT 1)",
                           (os.path.abspath(report_path), run_id))  # as named: a link is refused when read
        return cur.rowcount == 1
    finally:
        conn.close()


def _entries(conn: sqlite3.Connection, where: str, params: tuple = ()) -> list[QueueEntry]:
    rows = conn.execute("SELECT run_id, run_uuid, publication, sent_utc, report_path, report_sent_utc, attempts, "
                        f"last_error FROM fleet_outbox {where} ORDER BY run_id, summary_utc", params).fetchall()
    return [QueueEntry(int(r[0]), str(r[1]), json.loads(r[2]), r[3] is not None, r[4], r[5] is not None,
                       int(r[6]), str(r[7])) for r in rows]


def pending(db_path: str | Path) -> list[QueueEntry]:
    """What is still to send: runs not in the store, or reports not yet attached there."""
    conn = _open(db_path, create=False)
    try:
        if not _has_queue(conn):
            return []
        return _entries(conn, "WHERE sent_utc IS NULL OR (report_path IS NOT NULL AND report_sent_utc IS NULL)")
    finally:
        conn.close()


def queue_state(db_path: str | Path) -> list[QueueEntry]:
    conn = _open(db_path, create=False)
    try:
        if not _has_queue(conn):
            return []
        return _entries(conn, "")
    finally:
        conn.close()


#: the largest report sent (a self-contained report.html with its plots is a few MB)
MAX_REPORT_BYTES = 32 * 1024 * 1024


def _read_report(path: str) -> str:
    """The report a run wrote, read as the station wrote it and nothing else (issue 39: a queued
    path that was a symlink to /etc/passwd was served to QA as the run's report): a regular file
    named report.html, reached through no symbolic link, opened without following one, at most
    :data:`MAX_REPORT_BYTES`. Anything else is an OSError naming why (the run stays published)."""
    p = Path(path)
    if p.name != "report.html":
        raise OSError(f"not a station's report (its file is report.html): {p.name!r}")
    if os.path.realpath(p) != os.path.abspath(p):
        raise OSError("the path passes through a symbolic link; a report is read only where the station wrote it")
    fd = os.open(p, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0))
    with os.fdopen(fd, "rb") as f:
        st = os.fstat(f.fileno())
        if not stat.S_ISREG(st.st_mode):
            raise OSError("not a regular file")
        if st.st_size > MAX_REPORT_BYTES:
            raise OSError(f"{st.st_size} bytes, more than the {MAX_REPORT_BYTES} a report may have")
        data = f.read(MAX_REPORT_BYTES + 1)
    if len(data) > MAX_REPORT_BYTES:
        raise OSError(f"more than the {MAX_REPORT_BYTES} bytes a report may have")
    return data.decode("utf-8")


def sync(db_path: str | Path, url: str, *, only_run: int | None = None,
         connect: Callable[[str], Any] | None = None) -> SyncResult:
    """Send everything queued in ``db_path`` to the store at ``url``. Never raises for the
    network or the store: what could not be sent stays queued, with the error, and is counted."""
    from station.fleet import store  # psycopg: imported when something is sent

    todo = [e for e in pending(db_path) if only_run is None or e.run_id == only_run]
    if not todo:
        return SyncResult()
    sent = already = reports = failed = 0
    error = ""
    local = _open(db_path)
    try:
        try:
            conn = (connect or store.connect)(url)
        except store.FleetStoreError as exc:
            _failed(local, [x.run_uuid for x in todo], str(exc))
            return SyncResult(failed=len(todo), error=str(exc))
        with conn:
            for e in todo:
                try:
                    if not e.sent:
                        new = store.insert_publication(conn, e.publication)
                        sent, already = sent + new, already + (not new)
                        local.execute("UPDATE fleet_outbox SET sent_utc = ?, attempts = attempts + 1, last_error = '' "
                                      "WHERE run_uuid = ?", (utc_now(), e.run_uuid))
                    if e.report_path is not None and not e.report_sent:
                        reports += store.insert_report(conn, e.run_uuid, e.report_path, _read_report(e.report_path))
                        local.execute("UPDATE fleet_outbox SET report_sent_utc = ? WHERE run_uuid = ?",
                                      (utc_now(), e.run_uuid))
                except OSError as exc:  # the report file is gone: the run stays published, say why
                    failed += 1
                    error = error or f"run {e.run_id}: report {e.report_path}: {exc}"
                    _failed(local, [e.run_uuid], error)
                except Exception as exc:  # noqa: BLE001 - psycopg's errors: the connection or the store
                    failed += 1
                    msg = f"run {e.run_id}: {type(exc).__name__}: {str(exc).strip().splitlines()[0] if str(exc).strip() else ''}"
                    error = error or msg
                    _failed(local, [e.run_uuid], msg)
                    if conn.closed or conn.broken:
                        rest = [x.run_uuid for x in todo[todo.index(e) + 1:]]
                        _failed(local, rest, msg)
                        failed += len(rest)
                        break
    finally:
        local.close()
    return SyncResult(sent=sent, already=already, reports=reports, failed=failed, error=error)


def _failed(local: sqlite3.Connection, run_uuids: list[str], error: str) -> None:
    local.executemany("UPDATE fleet_outbox SET attempts = attempts + 1, last_error = ? WHERE run_uuid = ?",
                      [(error[:500], u) for u in run_uuids])


def publish_or_queue(db_path: str | Path, run_id: int | None, cfg: CellConfig, db: RunDB | None = None,
                     url: str | None = None) -> str | None:
    """The end of a run: queue its publication and try to send it now, to ``url`` (default
    ``STATION_FLEET_URL``, else ``[fleet] url``). Returns a line for the operator (None when no
    fleet store is configured). Never raises: the run's outcome stands whatever the network does."""
    url = url or fleet_url(cfg.fleet.url)
    if url is None or run_id is None:
        return None
    try:
        run_uuid = enqueue_run(db_path, run_id, cfg, db)
    except Exception as exc:  # noqa: BLE001 - a run never fails on its publication
        log.warning("run %s: not queued for the fleet store: %s", run_id, exc)
        return f"fleet: run {run_id} could not be queued for the fleet store ({exc}); 'station sync' retries"
    try:
        result = sync(db_path, url, only_run=run_id)
    except Exception as exc:  # noqa: BLE001
        log.warning("run %s: fleet publication failed: %s", run_id, exc)
        result = SyncResult(failed=1, error=str(exc))
    if result.ok:
        return f"fleet: run {run_id} published to the fleet store ({run_uuid})"
    return (f"fleet: run {run_id} queued, not yet published ({result.error}); 'station sync --db {db_path}' "
            f"sends it when the fleet store is reachable")
