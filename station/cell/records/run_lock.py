"""One process per run: the run lock a station process holds in the run database while it works
on a run (docs/run-database.md, "One process per run").

The lock is a row of ``run_locks`` (``run_id`` PRIMARY KEY) naming host, PID, the PID's start
time and when it was taken; it is taken in one ``BEGIN IMMEDIATE`` transaction, so of two
processes exactly one gets it. A lock whose process is provably gone (same host, and the PID no
longer runs or now belongs to a process started later) is taken over: a ``kill -9`` or a power
cut must not make the operator clear locks by hand before the resume. A lock of another host
cannot be proven stale from here; ``station runs --db DB --unlock RUN`` clears it.
"""

from __future__ import annotations

import os
import socket
import sqlite3
import uuid
from dataclasses import dataclass

from station.cell.records.record_checks import DamagedRecordError
from station.cell.records.record_fields import check_lock_row
from station.cell.records.run_records import RunDatabaseError, utc_now

LOCK_TABLE = """CREATE TABLE IF NOT EXISTS run_locks (
    run_id     INTEGER PRIMARY KEY REFERENCES runs(id) ON DELETE CASCADE,
    host       TEXT NOT NULL,
    pid        INTEGER NOT NULL,
    pid_start  TEXT NOT NULL DEFAULT '',   -- the PID's start time (Linux /proc), '' where unknown
    since_utc  TEXT NOT NULL,
    token      TEXT NOT NULL               -- which RunDB of that process holds it
)"""

#: tokens of the locks this process holds (a second session in the same process is refused too)
_HELD: set[str] = set()


class RunLockedError(RunDatabaseError):
    """Another process works on the run."""


@dataclass(frozen=True)
class LockHolder:
    run_id: int
    host: str
    pid: int
    pid_start: str
    since_utc: str
    token: str

    def describe(self) -> str:
        return f"process {self.pid} on host {self.host} (since {self.since_utc})"


def this_host() -> str:
    return socket.gethostname()


def pid_start(pid: int) -> str:
    """The start time of process ``pid`` in clock ticks after boot (Linux); '' where unknown or gone."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii", errors="replace") as f:
            stat = f.read()
    except OSError:
        return ""
    # the command name (field 2) may hold spaces and parentheses: count from the last ')'
    fields = stat[stat.rfind(")") + 2:].split()
    return fields[19] if len(fields) > 19 else ""


def _pid_runs(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # it runs, as another user
        return True
    except OSError:
        return True  # cannot tell: treat as running (the safe side)
    return True


def is_stale(holder: LockHolder) -> bool:
    """Provably left behind: on this host, and its process is gone (or the PID was reused by a
    process started later); in this process, held by no open RunDB."""
    if holder.host != this_host():
        return False
    if holder.pid == os.getpid():
        return holder.token not in _HELD
    if not _pid_runs(holder.pid):
        return True
    now_start = pid_start(holder.pid)
    return bool(holder.pid_start and now_start and now_start != holder.pid_start)


def read_holder(conn: sqlite3.Connection, run_id: int, strict: bool = True) -> LockHolder | None:
    """The holder of the run's lock, its row checked (a damaged row: :class:`DamagedRecordError`
    naming the field; ``strict=False``: what of it reads, for clearing it)."""
    if not _has_table(conn):
        return None
    row = conn.execute("SELECT run_id, host, pid, pid_start, since_utc, token FROM run_locks WHERE run_id = ?",
                       (int(run_id),)).fetchone()
    if row is None:
        return None
    try:
        return LockHolder(*check_lock_row(row))
    except DamagedRecordError:
        if strict:
            raise
        return LockHolder(int(run_id), str(row[1])[:80], 0, "", str(row[4])[:40], str(row[5]))


def _has_table(conn: sqlite3.Connection) -> bool:
    return conn.execute("SELECT 1 FROM sqlite_master WHERE type='table' AND name='run_locks'").fetchone() is not None


def insert_statements(run_id_sql: str, token: str) -> tuple[str, tuple]:
    """The INSERT of this process's lock, for a transaction that also creates the run
    (``run_id_sql``: ``?`` or ``last_insert_rowid()``; the parameters follow it)."""
    me = os.getpid()
    return (f"INSERT INTO run_locks(run_id, host, pid, pid_start, since_utc, token) VALUES ({run_id_sql}, ?, ?, ?, ?, ?)",
            (this_host(), me, pid_start(me), utc_now(), token))


def new_token() -> str:
    return uuid.uuid4().hex


def acquire(conn: sqlite3.Connection, path: object, run_id: int) -> tuple[str, LockHolder | None]:
    """Take the lock of ``run_id`` in one IMMEDIATE transaction. Returns the lock's token and the
    stale holder it replaced (None if the run was free); raises :class:`RunLockedError` when a
    live process holds it."""
    token = new_token()
    conn.execute("BEGIN IMMEDIATE")
    try:
        conn.execute(LOCK_TABLE)
        holder = read_holder(conn, run_id)
        if holder is not None:
            if not is_stale(holder):
                raise RunLockedError(refusal(path, holder))
            conn.execute("DELETE FROM run_locks WHERE run_id = ? AND token = ?", (int(run_id), holder.token))
        sql, params = insert_statements("?", token)
        conn.execute(sql, (int(run_id), *params))
        if holder is not None:
            conn.execute("INSERT INTO events(run_id, t_utc, level, message) VALUES (?, ?, 'warning', ?)",
                         (int(run_id), utc_now(), f"stale run lock of {holder.describe()} taken over: that "
                                                  f"process is gone"))
        conn.execute("COMMIT")
    except BaseException:
        if conn.in_transaction:
            conn.execute("ROLLBACK")
        raise
    _HELD.add(token)
    return token, holder


def held(token: str) -> None:
    """Note a lock taken with :func:`insert_statements` as held by this process."""
    _HELD.add(token)


def release(conn: sqlite3.Connection, token: str) -> None:
    """Drop this process's lock (only its own row: a lock taken over meanwhile stays)."""
    _HELD.discard(token)
    conn.execute("DELETE FROM run_locks WHERE token = ?", (token,))


def refusal(path: object, holder: LockHolder) -> str:
    where = f"{path}: run {holder.run_id} is in use by {holder.describe()}"
    if holder.host != this_host():
        return (f"{where}; wait for it to finish. If that process is gone (its PC was switched off), "
                f"clear the lock with 'station runs --db {path} --unlock {holder.run_id}' and resume again")
    return (f"{where}; wait for it to finish or stop it (a lock whose process is gone is taken over by the "
            f"next resume). If PID {holder.pid} is not a station process, clear the lock with "
            f"'station runs --db {path} --unlock {holder.run_id}'")
