"""The run database: one SQLite file that holds every run of the station (docs/run-database.md).

A *run* is one calibration campaign: the configuration snapshot it was started with, the
measurement plan (one dict per step), and then, step by step, the measurements, the results of
identification / correction / verification, and an audit trail of events.

Guarantees
----------
* ``record_measurement`` commits (WAL journal, ``synchronous=FULL``) before it returns, so a
  measurement survives a ``kill -9`` or a power cut right after the call. The measuring loop must
  call it before it commands the next robot motion.
* Each step of a run is stored at most once (``UNIQUE(run_id, step_index)``); a second write of the
  same step raises :class:`DuplicateMeasurementError` unless ``replace=True`` is passed, and a
  replacement is logged as an event.
* A crashed run resumes at :meth:`RunDB.next_missing`: the lowest step index of the plan that has
  no stored measurement.

Units: joints in rad (revolute) / mm (prismatic), readings and positions in mm, angles in rad,
pose residuals in µm; times are UTC ISO-8601 strings ending in ``Z``.

One :class:`RunDB` may be created in one thread and used from another (a worker), one thread at a
time; every public method holds an internal lock.
"""

from __future__ import annotations

import json
import math
import sqlite3
import threading
import time
import tomllib
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterable, Iterator, Sequence

import numpy as np

from station.cell.plan.steps import MEASUREMENT_KINDS
from station.cell.records import record_checks as rc
from station.cell.records import record_fields as rf
from station.cell.records import run_lock
from station.cell.records.measurement_cache import MeasurementCache
from station.cell.records.record_checks import check_against_plan
from station.cell.records.run_lock import LockHolder
from station.cell.records.run_records import (
    _SCHEMA,
    _TABLES,
    EVENT_LEVELS,
    RUN_STATUSES,
    SCHEMA_VERSION,
    DuplicateMeasurementError,
    EventRecord,
    MeasurementRecord,
    RunDatabaseError,
    RunNotFoundError,
    RunRecord,
    SchemaVersionError,
    _dumps,
    _float_list,
    _station_version,
    utc_now,
)

__all__ = [
    "RunDB",
]

_MISSING = object()


# --------------------------------------------------------------------------------------- the DB

class RunDB:
    """The station's run database (one SQLite file). Use as a context manager or call close()."""

    def __init__(self, path: str | Path, *, timeout_s: float = 10.0, lock_new_runs: bool = False):
        """``lock_new_runs``: a run this RunDB creates is locked to this process from its creation
        until :meth:`close` (a session's database; :meth:`lock_run` locks a resumed run)."""
        self.path = Path(path)
        self._lock = threading.RLock()
        self._lock_new_runs = lock_new_runs
        self._run_locks: dict[int, str] = {}  # run id -> token of the run lock this RunDB holds
        self._conn: sqlite3.Connection | None = None
        self._contexts: dict[int, rf.RunContext | None] = {}  # per run: what the checks of its records know
        self._checked: set[str] = set()  # the whole-file checks done once
        self._parsed = MeasurementCache()  # records already checked, while their rows are unchanged
        self._runs_read: dict[int, tuple[tuple, RunRecord]] = {}  # run id -> its row and record, as last read
        if self.path.is_dir():
            raise RunDatabaseError(f"{self.path}: is a directory; give the path of a run database "
                                   f"file (it is created if it does not exist)")
        if not self.path.parent.exists():
            raise RunDatabaseError(f"{self.path}: folder {self.path.parent} does not exist; "
                                   f"create it first")
        try:
            conn = sqlite3.connect(str(self.path), timeout=timeout_s, isolation_level=None,
                                   check_same_thread=False)
        except sqlite3.Error as e:
            raise RunDatabaseError(f"{self.path}: cannot open the run database ({e}); check the "
                                   f"path and its permissions") from e
        self._conn = conn
        try:
            self._setup_waiting(timeout_s)
        except sqlite3.DatabaseError as e:
            conn.close()
            self._conn = None
            if isinstance(e, sqlite3.OperationalError) and ("disk" in str(e) or "full" in str(e)):
                raise RunDatabaseError(f"{self.path}: cannot open the run database ({e}); check free disk space "
                                       f"and that its folder is writable") from e
            raise RunDatabaseError(
                f"{self.path}: not a usable run database ({e}). If it is a damaged run database, "
                f"keep it for inspection and restore the last backup; otherwise move it away or "
                f"choose another path, the station then creates a new one") from e
        except BaseException:
            conn.close()
            self._conn = None
            raise

    # -- opening -------------------------------------------------------------------------------

    def _setup_waiting(self, timeout_s: float) -> None:
        """:meth:`_setup`, tried again for up to ``timeout_s`` while SQLite answers 'database is
        locked'. SQLite's busy timeout does not cover every statement: ``PRAGMA journal_mode``
        fails at once while another process holds the write lock, e.g. a watcher or a second
        station creating the same new file (a script reading committed_steps() made a starting
        calibration fail with DATABASE_ERROR). Every step of the setup may run again: the schema
        is created under BEGIN IMMEDIATE after a second look."""
        deadline = time.monotonic() + timeout_s
        while True:
            try:
                self._setup(timeout_s)
                return
            except sqlite3.OperationalError as e:
                if "locked" not in str(e) or time.monotonic() >= deadline:
                    raise
            time.sleep(0.05)

    def _setup(self, timeout_s: float) -> None:
        c = self._conn
        assert c is not None
        c.execute(f"PRAGMA busy_timeout = {int(timeout_s * 1000)}")
        # Reading the schema fails right here with 'file is not a database' for foreign files.
        names = {r[0] for r in c.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        mode = c.execute("PRAGMA journal_mode = WAL").fetchone()[0]
        if str(mode).lower() != "wal":
            raise RunDatabaseError(
                f"{self.path}: SQLite refused the WAL journal (mode is {mode!r}); put the run "
                f"database on a local disk (network file systems do not support WAL)")
        c.execute("PRAGMA synchronous = FULL")
        c.execute("PRAGMA foreign_keys = ON")
        if c.execute("PRAGMA foreign_keys").fetchone()[0] != 1:
            raise RunDatabaseError("this SQLite build does not enforce foreign keys; use a "
                                   "Python built with a standard SQLite")
        check = c.execute("PRAGMA quick_check").fetchone()[0]
        if check != "ok":
            raise RunDatabaseError(
                f"{self.path}: the run database is damaged (SQLite quick_check: {check}); keep "
                f"the file for inspection, restore the last backup or start a new database")
        if "schema_version" not in names:
            if names - {"sqlite_sequence"}:
                raise RunDatabaseError(
                    f"{self.path}: an SQLite file, but not a station run database (tables: "
                    f"{', '.join(sorted(names))}); choose another path for the run database")
            self._create_schema()
            return
        rows = c.execute("SELECT version FROM schema_version").fetchall()
        if len(rows) != 1:
            raise RunDatabaseError(f"{self.path}: schema_version table holds {len(rows)} rows "
                                   f"instead of 1; the file is damaged, restore a backup")
        version = rows[0][0]
        if not isinstance(version, int):
            raise RunDatabaseError(f"{self.path}: schema version {version!r} is not an integer; "
                                   f"the file is damaged, restore a backup")
        if version > SCHEMA_VERSION:
            raise SchemaVersionError(
                f"{self.path}: written by a newer station (run-database schema {version}; this "
                f"station reads up to {SCHEMA_VERSION}). Update the station software, or use a "
                f"new database file with this one")
        if version < SCHEMA_VERSION:  # no older schemas exist yet; migrations go here
            raise SchemaVersionError(
                f"{self.path}: run-database schema {version} is older than any this station "
                f"supports ({SCHEMA_VERSION}); open it with the station version that wrote it")
        missing = _TABLES - names
        if missing:
            raise RunDatabaseError(f"{self.path}: tables {', '.join(sorted(missing))} are "
                                   f"missing; the file is damaged, restore a backup")
        for table in rc.TABLE_COLUMNS:  # a table re-made by a foreign tool fails here, not mid-run
            rc.check_columns(self.path, table, [r[1] for r in c.execute(f"PRAGMA table_info({table})")])

    def _create_schema(self) -> None:
        c = self._conn
        assert c is not None
        c.execute("BEGIN IMMEDIATE")
        try:
            # Another process may have created it between our check and the write lock.
            exists = c.execute("SELECT 1 FROM sqlite_master WHERE type='table' AND "
                               "name='schema_version'").fetchone()
            if not exists:
                for stmt in _SCHEMA.split(";"):
                    if stmt.strip():
                        c.execute(stmt)
                c.execute("INSERT INTO schema_version(version) VALUES (?)", (SCHEMA_VERSION,))
                c.execute(run_lock.LOCK_TABLE)
            c.execute("COMMIT")
        except BaseException:
            c.execute("ROLLBACK")
            raise

    # -- plumbing ------------------------------------------------------------------------------

    def __enter__(self) -> "RunDB":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Close the file, releasing the run locks it holds. Everything recorded is already
        committed; closing loses nothing."""
        with self._lock:
            for run_id in list(self._run_locks):
                self._release(run_id)
            if self._conn is not None:
                self._conn.close()
                self._conn = None

    @property
    def closed(self) -> bool:
        return self._conn is None

    def _c(self) -> sqlite3.Connection:
        if self._conn is None:
            raise RunDatabaseError(f"{self.path}: the run database is closed; open a new RunDB")
        return self._conn

    def _write(self, statements: Iterable[tuple[str, tuple]]) -> list[sqlite3.Cursor]:
        """Run statements in one IMMEDIATE transaction and commit (durable on return)."""
        c = self._c()
        try:
            c.execute("BEGIN IMMEDIATE")
            try:
                curs = [c.execute(sql, params) for sql, params in statements]
                c.execute("COMMIT")
            except BaseException:
                if c.in_transaction:
                    c.execute("ROLLBACK")
                raise
        except sqlite3.IntegrityError:
            raise  # the caller turns it into a specific error
        except sqlite3.OperationalError as e:
            raise RunDatabaseError(
                f"{self.path}: write failed, nothing of it was stored ({e}); check free disk "
                f"space and permissions, and that no other station process holds the database "
                f"locked") from e
        except sqlite3.DatabaseError as e:
            raise RunDatabaseError(f"{self.path}: write failed, nothing of it was stored ({e}); "
                                   f"the file may be damaged, keep it and restore a backup") from e
        return curs

    def _require_run(self, run_id: int) -> tuple[Any, ...]:
        row = self._c().execute(
            "SELECT id, created_utc, station_version, status, config_toml, plan_json, seed, note "
            "FROM runs WHERE id = ?", (rf.run_id_param(run_id),)).fetchone()
        if row is None:
            latest = self._c().execute("SELECT MAX(id) FROM runs").fetchone()[0]
            have = f"its runs are 1..{latest}" if latest else "it holds no runs yet"
            raise RunNotFoundError(f"{self.path}: no run {run_id} ({have}); check the run number "
                                   f"and the --db file")
        return tuple(row)

    _run_from_row = staticmethod(rc.run_record)

    def _run_checked(self, row: tuple[Any, ...]) -> RunRecord:
        """The run's row as a record, for this class's own reading: an unchanged row is not parsed
        and checked again (record_measurement reads the run at every step; its plan is ~2 ms)."""
        hit = self._runs_read.get(row[0])
        if hit is None or hit[0] != row:
            hit = (row, self._run_from_row(row))
            self._runs_read[row[0]] = hit
        return hit[1]

    # -- run locks (station.cell.records.run_lock) ---------------------------------------------------

    @contextmanager
    def lock_run(self, run_id: int) -> Iterator[LockHolder | None]:
        """Hold the run's lock until the block ends (or :meth:`close`); yields the stale holder it
        took over, if any. Raises :class:`RunLockedError` when a live process holds it."""
        with self._lock:
            self._require_run(run_id)
            if int(run_id) not in self._run_locks:
                try:
                    token, stale = run_lock.acquire(self._c(), self.path, int(run_id))
                except sqlite3.OperationalError as e:
                    raise RunDatabaseError(f"{self.path}: the run lock of run {run_id} could not be "
                                           f"taken ({e}); check that the file is writable") from e
                self._run_locks[int(run_id)] = token
            else:
                stale = None
        try:
            yield stale
        finally:
            with self._lock:
                self._release(int(run_id))

    def _release(self, run_id: int) -> None:
        token = self._run_locks.pop(run_id, None)
        if token is None or self._conn is None:
            return
        try:
            run_lock.release(self._conn, token)
        except sqlite3.Error:  # a lock left behind is taken over as stale: this process ends
            pass

    def run_lock(self, run_id: int, strict: bool = True) -> LockHolder | None:
        """Who holds the run's lock, or None (``strict=False``: a damaged lock row as far as it reads)."""
        with self._lock:
            self._require_run(run_id)
            return run_lock.read_holder(self._c(), run_id, strict)

    def unlock_run(self, run_id: int) -> LockHolder | None:
        """Clear the run's lock whoever holds it (``station runs --unlock``); returns the holder it
        removed, or None if the run was not locked."""
        with self._lock:
            holder = self.run_lock(run_id, strict=False)  # a damaged lock row is cleared too
            if holder is not None:
                self._write([("DELETE FROM run_locks WHERE run_id = ?", (int(run_id),)),
                             ("INSERT INTO events(run_id, t_utc, level, message) VALUES (?, ?, 'warning', ?)",
                              (int(run_id), utc_now(), f"run lock of {holder.describe()} cleared by hand"))])
            return holder

    # -- runs ----------------------------------------------------------------------------------

    def create_run(self, config_toml: str, plan: Sequence[dict], seed: int | None = None,
                   note: str = "", *, station_version: str | None = None) -> int:
        """Store a new run (status 'created') with its configuration snapshot and plan."""
        if not isinstance(config_toml, str):
            raise RunDatabaseError("config_toml must be the text of the configuration (str), "
                                   f"not {type(config_toml).__name__}; read the file first")
        try:
            tomllib.loads(config_toml)
        except tomllib.TOMLDecodeError as e:
            raise RunDatabaseError(f"config_toml is not valid TOML ({e}); pass the full text "
                                   f"of the configuration file, not its path") from e
        if isinstance(plan, (str, bytes)) or not all(isinstance(s, dict) for s in plan):
            raise RunDatabaseError("plan must be a list of step dicts (one per measurement)")
        plan_json = _dumps(list(plan), "plan")
        seed_text = None
        if seed is not None:
            if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
                raise RunDatabaseError(f"seed must be an integer or None, not {seed!r}")
            seed_text = str(int(seed))  # as text: SQLite integers stop at 2**63
        version = _station_version() if station_version is None else str(station_version)
        now = utc_now()
        token = run_lock.new_token()
        with self._lock:
            lock = [(run_lock.LOCK_TABLE, ()), run_lock.insert_statements(
                "(SELECT MAX(id) FROM runs)", token)] if self._lock_new_runs else []
            cur, *_ = self._write([
                ("INSERT INTO runs(created_utc, station_version, status, config_toml, plan_json, "
                 "seed, note) VALUES (?, ?, 'created', ?, ?, ?, ?)",
                 (now, version, config_toml, plan_json, seed_text, str(note))),
                ("INSERT INTO events(run_id, t_utc, level, message) VALUES "
                 "(last_insert_rowid(), ?, 'info', ?)",
                 (now, f"run created: {len(plan)} planned steps, station {version}")),
                *lock,
            ])
            rowid = cur.lastrowid
            assert rowid is not None  # an INSERT always sets it
            if self._lock_new_runs:  # taken in the run's own transaction: no moment unlocked
                run_lock.held(token)
                self._run_locks[int(rowid)] = token
            return int(rowid)

    def run(self, run_id: int) -> RunRecord:
        with self._lock:
            return self._run_from_row(self._require_run(run_id))

    def runs(self) -> list[RunRecord]:
        """All runs, newest first."""
        with self._lock:
            rows = self._c().execute(
                "SELECT id, created_utc, station_version, status, config_toml, plan_json, seed, "
                "note FROM runs ORDER BY id DESC").fetchall()
        return [self._run_from_row(r) for r in rows]

    def latest_run(self) -> RunRecord | None:
        with self._lock:
            row = self._c().execute(
                "SELECT id, created_utc, station_version, status, config_toml, plan_json, seed, "
                "note FROM runs ORDER BY id DESC LIMIT 1").fetchone()
        return None if row is None else self._run_from_row(row)

    def set_status(self, run_id: int, status: str) -> None:
        """Set the run's status (one of RUN_STATUSES); the change is logged as an event."""
        if status not in RUN_STATUSES:
            raise RunDatabaseError(f"unknown run status {status!r}; use one of "
                                   f"{', '.join(RUN_STATUSES)}")
        with self._lock:
            old = self._require_run(run_id)[3]
            self._write([
                ("UPDATE runs SET status = ? WHERE id = ?", (status, int(run_id))),
                ("INSERT INTO events(run_id, t_utc, level, message) VALUES (?, ?, 'info', ?)",
                 (int(run_id), utc_now(), f"status {old} -> {status}")),
            ])

    # -- measurements --------------------------------------------------------------------------

    def record_measurement(self, run_id: int, step_index: int, *, kind: str,
                           joints_commanded: Any, joints_read: Any = None,
                           raw_frames: bytes = b"", readings_mm: Any = None,
                           channel_status: Sequence | None = None, pose: Any = None,
                           pose_residual_um: float | None = None, ok: bool = True,
                           message: str = "", point_id: str = "", label: str = "",
                           t_utc: str | None = None, replace: bool = False) -> MeasurementRecord:
        """Store one measurement and commit it durably before returning.

        Call this before commanding the next robot motion. ``step_index`` must lie in the run's
        plan (0 <= step_index < len(plan)). A step that is already stored raises
        :class:`DuplicateMeasurementError`; pass ``replace=True`` to overwrite it on purpose (the
        replacement is logged). Returns the record as it will be read back.
        """
        if not isinstance(kind, str) or not kind:
            raise RunDatabaseError(f"kind must be a non-empty string such as "
                                   f"{', '.join(MEASUREMENT_KINDS)}; got {kind!r}")
        if isinstance(step_index, bool) or not isinstance(step_index, (int, np.integer)):
            raise RunDatabaseError(f"step_index must be an integer, not {step_index!r}")
        step_index = int(step_index)
        if not isinstance(raw_frames, (bytes, bytearray, memoryview)):
            raise RunDatabaseError(f"raw_frames must be the bytes received from the probe head, "
                                   f"not {type(raw_frames).__name__}; concatenate the frames")
        raw = bytes(raw_frames)
        jc = _float_list(joints_commanded, "joints_commanded")
        jr = _float_list(joints_read, "joints_read")
        rd = _float_list(readings_mm, "readings_mm")
        ps = _float_list(pose, "pose", ndim=2)
        if ps is not None and (len(ps), len(ps[0]) if ps else 0) != (4, 4):
            raise RunDatabaseError(f"pose must be a 4x4 homogeneous matrix or None, got shape "
                                   f"{np.shape(pose)}")
        cs = None if channel_status is None else list(channel_status)
        cs_json = None if cs is None else _dumps(cs, "channel_status")
        res = None if pose_residual_um is None else float(pose_residual_um)
        if res is not None and math.isnan(res):
            res = None
        t = utc_now() if t_utc is None else str(t_utc)
        row = (int(run_id), step_index, kind, str(point_id), str(label),
               json.dumps(jc, allow_nan=False),
               None if jr is None else json.dumps(jr, allow_nan=False), raw,
               None if rd is None else json.dumps(rd, allow_nan=False), cs_json,
               None if ps is None else json.dumps(ps, allow_nan=False),
               res, 1 if ok else 0, str(message), t)
        with self._lock:
            run = self._run_checked(self._require_run(run_id))
            if not 0 <= step_index < run.n_steps:
                raise RunDatabaseError(
                    f"run {run_id}: step {step_index} is outside its plan of {run.n_steps} steps "
                    f"(0..{run.n_steps - 1}); record only planned steps, or start a new run with "
                    f"a longer plan")
            planned_kind = run.plan[step_index].get("kind")
            if planned_kind is not None and planned_kind != kind:
                raise RunDatabaseError(
                    f"run {run_id}: step {step_index} is planned as {planned_kind!r} but was "
                    f"recorded as {kind!r}; the measuring loop and the stored plan disagree")
            insert = ("INSERT INTO measurements(run_id, step_index, kind, point_id, label, "
                      "joints_commanded, joints_read, raw_frames, readings_mm, channel_status, "
                      "pose, pose_residual_um, ok, message, t_utc) "
                      "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)", row)
            stmts: list[tuple[str, tuple[Any, ...]]] = [insert]
            if replace:  # delete, log only if something was deleted, insert: one transaction
                stmts = [("DELETE FROM measurements WHERE run_id = ? AND step_index = ?",
                          (int(run_id), step_index)),
                         ("INSERT INTO events(run_id, t_utc, level, message) SELECT ?, ?, "
                          "'warning', ? WHERE changes() > 0",
                          (int(run_id), t, f"step {step_index} replaced by a new measurement")),
                         insert]
            try:
                self._write(stmts)
            except sqlite3.IntegrityError as e:
                if "UNIQUE" in str(e):
                    raise DuplicateMeasurementError(
                        f"run {run_id}: step {step_index} is already recorded; resume at "
                        f"next_missing() = {self._next_missing(run)} instead, or pass "
                        f"replace=True to overwrite it on purpose") from e
                raise RunDatabaseError(f"run {run_id}: measurement {step_index} rejected by the "
                                       f"database ({e})") from e
        return self._measurement_from_row(row)

    _measurement_from_row = staticmethod(rc.measurement_record)

    def measurements(self, run_id: int, kind: str | None = None) -> list[MeasurementRecord]:
        """The run's measurements ordered by step index, optionally only those of one kind. Every
        row of the run is checked, also when only one kind is asked for: a row whose kind was
        damaged must not drop out of the selection unnoticed."""
        sql = ("SELECT run_id, step_index, kind, point_id, label, joints_commanded, joints_read, "
               "raw_frames, readings_mm, channel_status, pose, pose_residual_um, ok, message, "
               "t_utc FROM measurements WHERE run_id = ? ORDER BY step_index")
        with self._lock:
            run_row = self._require_run(run_id)
            rows = self._c().execute(sql, (int(run_id),)).fetchall()
            self._check_orphans()
            plan = self._run_checked(run_row).plan
        plan_text = run_row[5]  # plan_json: the checks read the plan, so a changed plan checks anew
        records, fresh = self._parsed.records(int(run_id), plan_text, rows, self._measurement_from_row)
        check_against_plan(records, plan, run_id)
        rf.check_measurements(fresh, plan, self._context(int(run_id)))  # every new field (record_fields.py)
        rf.check_channel_count(records)
        self._parsed.keep(int(run_id), plan_text, rows, records)
        if kind is not None:
            records = [r for r in records if r.kind == kind]
        return records

    def _check_orphans(self) -> None:
        """A measurement of no run (written with the foreign keys off) is damage, named (once per RunDB)."""
        if "orphans" in self._checked:
            return
        bad = self._c().execute("PRAGMA foreign_key_check(measurements)").fetchall()
        if bad:
            row = self._c().execute("SELECT run_id, step_index FROM measurements WHERE rowid = ?",
                                    (bad[0][1],)).fetchone()
            raise rc.damaged_field(None, "measurements", f"rowid {bad[0][1]} (step {row[1]})", "run_id",
                                   f"run {row[0]} does not exist ({len(bad)} rows of no run); it belonged to another "
                                   f"run or was edited")
        self._checked.add("orphans")

    def _context(self, run_id: int) -> rf.RunContext | None:
        """The run's robot, body and head as its stored configuration says (read once per RunDB)."""
        if run_id not in self._contexts:
            from station.cell.records.reading.stored_config import run_context  # it reads the database: imported here
            self._contexts[run_id] = run_context(self, run_id)
        return self._contexts[run_id]

    def completed_steps(self, run_id: int, ok_only: bool = False) -> set[int]:
        """Step indices that have a stored measurement (also failed ones unless ``ok_only``)."""
        sql = "SELECT step_index FROM measurements WHERE run_id = ?"
        if ok_only:
            sql += " AND ok = 1"
        with self._lock:
            self._require_run(run_id)
            return {r[0] for r in self._c().execute(sql, (int(run_id),))}

    def _next_missing(self, run: RunRecord) -> int | None:
        done = {r[0] for r in self._c().execute(
            "SELECT step_index FROM measurements WHERE run_id = ?", (run.id,))}
        return next((i for i in range(run.n_steps) if i not in done), None)

    def next_missing(self, run_id: int) -> int | None:
        """Lowest planned step without a stored measurement; None when every step is stored.

        Failed measurements (ok=False) count as stored: re-measure them with ``replace=True``.
        """
        with self._lock:
            return self._next_missing(self._run_from_row(self._require_run(run_id)))

    # -- results and events --------------------------------------------------------------------

    def save_result(self, run_id: int, key: str, obj: Any) -> None:
        """Store ``obj`` as JSON under ``key`` (overwrites). numpy arrays become lists; NaN and
        ±inf are stored as ``{"__float__": "nan" | "inf" | "-inf"}`` and come back as floats."""
        if not isinstance(key, str) or not key:
            raise RunDatabaseError(f"result key must be a non-empty string, not {key!r}")
        text = _dumps(obj, f"result {key!r}")
        with self._lock:
            self._require_run(run_id)
            self._write([("INSERT INTO results(run_id, key, json, t_utc) VALUES (?, ?, ?, ?) "
                          "ON CONFLICT(run_id, key) DO UPDATE SET json = excluded.json, "
                          "t_utc = excluded.t_utc", (int(run_id), key, text, utc_now()))])

    def load_result(self, run_id: int, key: str, default: Any = _MISSING) -> Any:
        """The stored result (lists for arrays, floats restored); ``default`` when absent, else
        :class:`RunDatabaseError`."""
        with self._lock:
            self._require_run(run_id)
            row = self._c().execute("SELECT json FROM results WHERE run_id = ? AND key = ?",
                                    (int(run_id), key)).fetchone()
        if row is None:
            if default is _MISSING:
                raise RunDatabaseError(f"run {run_id}: no result {key!r}; run the step that "
                                       f"produces it first, or pass default=")
            return default
        value = rc.check_result(rc.parse_json(row[0], int(run_id), f"result {key!r}"), int(run_id), key)
        rf.check_result_fields(value, int(run_id), key, self.run(run_id).n_steps if key == "recentring" else 0)
        return value

    def result_keys(self, run_id: int) -> list[str]:
        with self._lock:
            self._require_run(run_id)
            return [r[0] for r in self._c().execute(
                "SELECT key FROM results WHERE run_id = ? ORDER BY key", (int(run_id),))]

    def log(self, run_id: int, level: str, message: str) -> None:
        """Append an event to the run's audit trail (committed on return)."""
        if level not in EVENT_LEVELS:
            raise RunDatabaseError(f"unknown event level {level!r}; use one of "
                                   f"{', '.join(EVENT_LEVELS)}")
        with self._lock:
            self._require_run(run_id)
            self._write([("INSERT INTO events(run_id, t_utc, level, message) VALUES (?, ?, ?, ?)",
                          (int(run_id), utc_now(), level, str(message)))])

    def events(self, run_id: int) -> list[EventRecord]:
        with self._lock:
            self._require_run(run_id)
            rows = self._c().execute("SELECT run_id, t_utc, level, message FROM events WHERE "
                                     "run_id = ? ORDER BY id", (int(run_id),)).fetchall()
        return [EventRecord(*r) for r in rows]
