"""Run database: round trips, duplicates, resume, durability under SIGKILL, export, bad files."""

from __future__ import annotations

import csv
import dataclasses
import math
import os
import random
import signal
import sqlite3
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from station.cell.records.reading.run_export import export_csv
from station.cell.records.run_records import (
    SCHEMA_VERSION,
    DuplicateMeasurementError,
    MeasurementRecord,
    RunDatabaseError,
    RunNotFoundError,
    RunRecord,
    SchemaVersionError,
)
from station.cell.records.rundb import RunDB
from station.core.kinematics.transforms import matrix_to_pose, pose_to_matrix
from station.errors import StationError

REPO = Path(__file__).resolve().parents[2]

CONFIG = """\
[robot]
name = "sr800"

[[transform]]
name = "A1"
joint = "revolute"

[[transform]]
name = "A2"
joint = "revolute"

[[transform]]
name = "A3"
joint = "prismatic"

[[transform]]
name = "A4"
joint = "revolute"

[probe]
channels = 6
"""

# Deterministic content of step i, shared by this module and the writer subprocess, so that a
# row read back after a kill can be checked field by field (a partial row would not match).
FIELDS_SRC = r'''
import math
import numpy as np

def fields(i):
    q = [0.001 * i, -0.5 + 1e-4 * i, -10.0 - 0.01 * i, 0.1 / (i + 1)]
    readings = [1.0 + i / 3.0, 2.0, float("nan") if i % 7 == 0 else -0.125, 0.0, 1e-7 * i, 3.3]
    pose = np.eye(4)
    pose[:3, 3] = [i / 7.0, -i / 11.0, 0.5]
    return dict(kind="identification", point_id=f"P{i % 5}", label=f"step {i}",
                joints_commanded=q, joints_read=[v + 1e-9 for v in q],
                raw_frames=(f"M0,+{i:08.4f}".encode() + b"\r\n\x00\xff") * (1 + i % 4),
                readings_mm=readings, channel_status=["ok"] * 5 + ["over_range" if i % 7 == 0 else "ok"],
                pose=pose, pose_residual_um=0.5 + i, ok=i % 7 != 0, message="" if i % 7 else "out of range")
'''
_ns: dict = {}
exec(FIELDS_SRC, _ns)
fields = _ns["fields"]

WRITER_SRC = FIELDS_SRC + r'''
import sys, time
from station.cell.records.rundb import RunDB

db_path, run_id, pause_s, max_new = sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), int(sys.argv[4])
with RunDB(db_path) as db:
    print("ready", flush=True)
    while max_new > 0 and (i := db.next_missing(run_id)) is not None:
        max_new -= 1
        db.record_measurement(run_id, i, **fields(i))
        print(i, flush=True)          # reported only after the commit returned
        time.sleep(pause_s)           # "the next robot motion"
print("done", flush=True)
'''


def plan(n: int, kind: str = "identification") -> list[dict]:
    return [{"kind": kind, "point": f"P{i % 5}", "q": [0.0, 0.1 * i, -10.0, 0.0]} for i in range(n)]


@pytest.fixture
def db(tmp_path):
    with RunDB(tmp_path / "runs.db") as d:
        yield d


def assert_matches(m: MeasurementRecord, run_id: int, i: int) -> None:
    f = fields(i)
    assert (m.run_id, m.step_index, m.kind) == (run_id, i, f["kind"])
    assert (m.point_id, m.label, m.message, m.ok) == (f["point_id"], f["label"], f["message"], f["ok"])
    assert m.raw_frames == f["raw_frames"]
    np.testing.assert_array_equal(m.joints_commanded, f["joints_commanded"])
    np.testing.assert_array_equal(m.joints_read, f["joints_read"])
    np.testing.assert_array_equal(m.readings_mm, f["readings_mm"])  # NaN == NaN here
    np.testing.assert_array_equal(m.pose, f["pose"])
    assert m.channel_status == tuple(f["channel_status"])
    assert m.pose_residual_um == f["pose_residual_um"]


# ----------------------------------------------------------------------------------- round trips

def test_run_round_trip_and_order(db):
    assert db.latest_run() is None and db.runs() == []
    p = plan(3)
    a = db.create_run(CONFIG, p, seed=2**100 + 7, note="first")
    b = db.create_run(CONFIG, plan(2), station_version="9.9.9")
    r = db.run(a)
    assert isinstance(r, RunRecord)
    assert (r.id, r.status, r.config_toml, r.plan, r.seed, r.note) == (a, "created", CONFIG, tuple(p), 2**100 + 7, "first")
    assert r.n_steps == 3 and r.created_utc.endswith("Z")
    assert db.run(b).station_version == "9.9.9" and db.run(b).seed is None
    assert [x.id for x in db.runs()] == [b, a]
    assert db.latest_run().id == b
    with pytest.raises(dataclasses.FrozenInstanceError):
        r.status = "failed"  # type: ignore[misc]


def test_measurement_round_trip_every_field(db):
    rid = db.create_run(CONFIG, plan(8))
    for i in (0, 7, 3):
        ret = db.record_measurement(rid, i, **fields(i), t_utc=f"2026-01-01T00:00:0{i}Z")
        assert_matches(ret, rid, i)
    ms = db.measurements(rid)
    assert [m.step_index for m in ms] == [0, 3, 7]
    for m in ms:
        assert_matches(m, rid, m.step_index)
        assert m.t_utc == f"2026-01-01T00:00:0{m.step_index}Z"
        assert not m.readings_mm.flags.writeable
    nan_step = ms[0]
    assert math.isnan(nan_step.readings_mm[2]) and nan_step.ok is False
    with pytest.raises(dataclasses.FrozenInstanceError):
        ms[0].ok = True  # type: ignore[misc]


def test_optional_fields_and_kind_filter(db):
    rid = db.create_run(CONFIG, plan(2, "verification_before") + plan(1, "verification_after"))
    db.record_measurement(rid, 0, kind="verification_before", joints_commanded=[1, 2, 3, 4])
    db.record_measurement(rid, 2, kind="verification_after", joints_commanded=np.zeros(4),
                          pose_residual_um=float("nan"), raw_frames=bytearray(b"\x00\x01"))
    m = db.measurements(rid, kind="verification_before")
    assert len(m) == 1 and m[0].joints_read is None and m[0].readings_mm is None
    assert m[0].pose is None and m[0].channel_status is None and m[0].raw_frames == b""
    after = db.measurements(rid, kind="verification_after")[0]
    assert after.pose_residual_um is None and after.raw_frames == b"\x00\x01"
    assert db.measurements(rid, kind="reversal") == []


def test_record_can_be_written_again_from_its_fields(db):
    rid = db.create_run(CONFIG, plan(2))
    rec = db.record_measurement(rid, 1, **fields(1))
    other = db.create_run(CONFIG, plan(2))
    db.record_measurement(**{**dataclasses.asdict(rec), "run_id": other})
    assert_matches(db.measurements(other)[0], other, 1)


def test_bad_measurement_arguments_are_typed(db):
    rid = db.create_run(CONFIG, plan(2))
    ok = fields(0)
    cases = [
        dict(ok, pose=np.eye(3)),
        dict(ok, joints_commanded="abc"),
        dict(ok, raw_frames="M0,+1.0"),
        dict(ok, kind="verification_after"),  # plan says identification
    ]
    for kw in cases:
        with pytest.raises(RunDatabaseError):
            db.record_measurement(rid, 0, **kw)
    with pytest.raises(RunDatabaseError, match="outside its plan"):
        db.record_measurement(rid, 2, **ok)
    with pytest.raises(RunNotFoundError, match="no run 99"):
        db.record_measurement(99, 0, **ok)
    assert db.completed_steps(rid) == set()


# ------------------------------------------------------------------------ duplicates and resume

def test_duplicate_rejected_unless_replace(db):
    rid = db.create_run(CONFIG, plan(3))
    db.record_measurement(rid, 0, **fields(0))
    with pytest.raises(DuplicateMeasurementError, match="replace=True") as e:
        db.record_measurement(rid, 0, **fields(1))
    assert isinstance(e.value, StationError) and e.value.exit_code == 5
    assert_matches(db.measurements(rid)[0], rid, 0)  # the original is untouched
    db.record_measurement(rid, 0, **{**fields(0), "message": "re-measured"}, replace=True)
    ms = db.measurements(rid)
    assert len(ms) == 1 and ms[0].message == "re-measured"
    assert any("step 0 replaced" in e.message and e.level == "warning" for e in db.events(rid))


def test_resume_semantics(db):
    rid = db.create_run(CONFIG, plan(5))
    assert db.next_missing(rid) == 0 and db.completed_steps(rid) == set()
    for i in (0, 1, 3):
        db.record_measurement(rid, i, **fields(i))
    assert db.completed_steps(rid) == {0, 1, 3}
    assert db.next_missing(rid) == 2
    db.record_measurement(rid, 2, **fields(2))
    assert db.next_missing(rid) == 4
    db.record_measurement(rid, 4, **fields(4))
    assert db.next_missing(rid) is None
    # a failed measurement counts as done; ok_only tells them apart
    rid2 = db.create_run(CONFIG, plan(8))
    for i in range(8):
        db.record_measurement(rid2, i, **fields(i))
    assert db.next_missing(rid2) is None
    assert db.completed_steps(rid2, ok_only=True) == set(range(1, 7))


def test_persistence_across_close_and_reopen(tmp_path):
    path = tmp_path / "runs.db"
    with RunDB(path) as db:
        rid = db.create_run(CONFIG, plan(4), seed=3)
        db.record_measurement(rid, 0, **fields(0))
        db.record_measurement(rid, 1, **fields(1))
        db.set_status(rid, "measuring")
        db.save_result(rid, "params", {"p": np.array([1.5, np.nan, np.inf, -np.inf]), "n": np.int64(20)})
        db.log(rid, "warning", "probe 3 near end of range")
    assert db.closed
    with pytest.raises(RunDatabaseError, match="closed"):
        db.runs()
    with RunDB(path) as db2:
        r = db2.run(rid)
        assert (r.status, r.seed) == ("measuring", 3)
        assert [m.step_index for m in db2.measurements(rid)] == [0, 1]
        assert_matches(db2.measurements(rid)[1], rid, 1)
        assert db2.next_missing(rid) == 2
        res = db2.load_result(rid, "params")
        assert res["n"] == 20 and res["p"][0] == 1.5 and math.isnan(res["p"][1])
        assert res["p"][2:] == [math.inf, -math.inf]
        msgs = [(e.level, e.message) for e in db2.events(rid)]
        assert ("info", "status created -> measuring") in msgs
        assert ("warning", "probe 3 near end of range") in msgs


def test_results(db):
    rid = db.create_run(CONFIG, plan(1))
    assert db.load_result(rid, "x", default=None) is None
    with pytest.raises(RunDatabaseError, match="no result 'x'"):
        db.load_result(rid, "x")
    db.save_result(rid, "x", [1, 2])
    db.save_result(rid, "x", {"a": (1, 2.5), "b": None, "c": "NaN", "d": True})
    assert db.load_result(rid, "x") == {"a": [1, 2.5], "b": None, "c": "NaN", "d": True}
    assert db.result_keys(rid) == ["x"]
    for bad in ({1: 2}, {"v": object()}, {"__float__": "nan"}):
        with pytest.raises(RunDatabaseError):
            db.save_result(rid, "y", bad)


def test_status_and_log_validation(db):
    rid = db.create_run(CONFIG, plan(1))
    with pytest.raises(RunDatabaseError, match="unknown run status"):
        db.set_status(rid, "done")
    with pytest.raises(RunDatabaseError, match="level"):
        db.log(rid, "fatal", "x")
    with pytest.raises(RunNotFoundError):
        db.set_status(rid + 1, "failed")
    with pytest.raises(RunDatabaseError, match="TOML"):
        db.create_run("not = toml = at all", plan(1))
    with pytest.raises(RunDatabaseError, match="plan"):
        db.create_run(CONFIG, ["step"])  # type: ignore[list-item]


def test_pragmas(db):
    c = db._conn
    assert c.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    assert c.execute("PRAGMA synchronous").fetchone()[0] == 2  # FULL
    assert c.execute("PRAGMA foreign_keys").fetchone()[0] == 1


def test_created_in_one_thread_used_in_another(tmp_path):
    db = RunDB(tmp_path / "runs.db")
    rid = db.create_run(CONFIG, plan(20))
    errors: list[BaseException] = []

    def worker(start: int) -> None:
        try:
            for i in range(start, 20, 2):
                db.record_measurement(rid, i, **fields(i))
        except BaseException as e:  # reported to the main thread below
            errors.append(e)

    ts = [threading.Thread(target=worker, args=(k,)) for k in (0, 1)]
    for t in ts:
        t.start()
    for t in ts:
        t.join()
    assert errors == []
    assert db.completed_steps(rid) == set(range(20))
    db.close()


# ------------------------------------------------------------------------------ kill -9 durability

def _check_after_kill(path: Path, rid: int, committed: list[int], n_plan: int) -> int:
    """Reopen; assert a contiguous prefix, no duplicates, every reported commit present."""
    raw = sqlite3.connect(path)
    try:
        assert raw.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
        n, distinct = raw.execute("SELECT count(*), count(DISTINCT step_index) FROM measurements "
                                  "WHERE run_id = ?", (rid,)).fetchone()
    finally:
        raw.close()
    assert n == distinct
    with RunDB(path) as db:
        steps = db.completed_steps(rid)
        assert steps == set(range(len(steps))), f"not a contiguous prefix: {sorted(steps)}"
        assert set(committed) <= steps, "a measurement reported as committed was lost"
        for m in db.measurements(rid):
            assert_matches(m, rid, m.step_index)  # no partially written row
        nxt = db.next_missing(rid)
        assert nxt == (len(steps) if len(steps) < n_plan else None)
    return len(steps)


def test_sigkill_at_random_moments_loses_and_duplicates_nothing(tmp_path):
    path = tmp_path / "runs.db"
    n_plan = 400
    with RunDB(path) as db:
        rid = db.create_run(CONFIG, plan(n_plan))
    script = tmp_path / "writer.py"
    script.write_text(WRITER_SRC)
    env = {**os.environ, "PYTHONPATH": f"{REPO}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    rng = random.Random(20261121)
    t0 = time.monotonic()
    done_before = 0
    progressed = 0
    for k in range(10):
        proc = subprocess.Popen([sys.executable, str(script), str(path), str(rid), "0.002", "100000"],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                env=env, cwd=tmp_path)
        if k % 3 == 0:  # anywhere, the start-up and opening included
            time.sleep(rng.uniform(0.0, 0.4))
        else:           # while it is writing
            assert proc.stdout.readline().strip() in ("ready", "")
            time.sleep(rng.uniform(0.0, 0.2))
        proc.send_signal(signal.SIGKILL)
        out, err = proc.communicate(timeout=10)
        assert proc.returncode == -signal.SIGKILL or "done" in out, err
        committed = [int(x) for x in out.split() if x.isdigit()]
        if committed:  # the writer resumed exactly where the last one stopped
            assert committed[0] == done_before
            assert committed == list(range(done_before, done_before + len(committed)))
        done = _check_after_kill(path, rid, committed, n_plan)
        assert done >= done_before
        progressed += done > done_before
        done_before = done
    assert progressed >= 3, "the kills never landed while measurements were being written"
    # a last writer, not interrupted, continues the same prefix and exits cleanly
    proc = subprocess.run([sys.executable, str(script), str(path), str(rid), "0", "25"],
                          capture_output=True, text=True, env=env, cwd=tmp_path, timeout=60)
    assert proc.returncode == 0 and proc.stdout.split()[-1] == "done", proc.stderr
    assert _check_after_kill(path, rid, [], n_plan) == min(done_before + 25, n_plan)
    assert time.monotonic() - t0 < 30  # about 5 s on an idle machine


# -------------------------------------------------------------------------------------- export

def test_export_csv_parses_back(db, tmp_path):
    rid = db.create_run(CONFIG, plan(8))
    for i in (0, 1, 2):
        db.record_measurement(rid, i, **fields(i))
    db.record_measurement(rid, 3, kind="identification", joints_commanded=[0.1, 0.2, -5.0, 0.3],
                          message='comma, "quoted"', ok=False)
    out = export_csv(db, rid, tmp_path / "run.csv")
    with open(out, newline="", encoding="utf-8") as f:
        rows = list(csv.reader(f))
    header = rows[0]
    assert header == (["step", "kind", "point_id", "label", "t_utc",
                       "q1 [deg]", "q2 [deg]", "q3 [mm]", "q4 [deg]",
                       "q1_cmd [deg]", "q2_cmd [deg]", "q3_cmd [mm]", "q4_cmd [deg]",
                       "x [mm]", "y [mm]", "z [mm]", "roll [deg]", "pitch [deg]", "yaw [deg]",
                       "residual [um]"]
                      + [f"p{i} [mm]" for i in range(1, 7)] + ["status", "ok", "message"])
    recs = [dict(zip(header, r)) for r in rows[1:]]
    assert [r["step"] for r in recs] == ["0", "1", "2", "3"]
    for i in (0, 1, 2):
        r, f = recs[i], fields(i)
        units = ["deg", "deg", "mm", "deg"]  # joints and orientations in degrees, as everywhere (issue 29)
        deg = np.array([True, True, False, True])
        for col, key in (("", "joints_read"), ("_cmd", "joints_commanded")):
            got = np.array([float(r[f"q{j + 1}{col} [{u}]"]) for j, u in enumerate(units)])
            np.testing.assert_allclose(got, np.where(deg, np.degrees(f[key]), f[key]), rtol=1e-15)
        pose = np.array([float(r[h]) for h in header[13:19]])
        want = matrix_to_pose(f["pose"])
        np.testing.assert_allclose(pose, np.r_[want[:3], np.degrees(want[3:])], rtol=1e-15)
        np.testing.assert_array_equal([float(r[f"p{j} [mm]"]) for j in range(1, 7)], f["readings_mm"])
        assert r["status"] == ";".join(f["channel_status"]) and r["ok"] == str(int(f["ok"]))
        assert float(r["residual [um]"]) == f["pose_residual_um"]
    assert recs[0]["p3 [mm]"] == "nan"
    assert recs[3]["x [mm]"] == "" and recs[3]["p1 [mm]"] == ""
    assert recs[3]["message"] == 'comma, "quoted"' and recs[3]["ok"] == "0"


def test_export_joint_units_given_or_unknown(db, tmp_path):
    rid = db.create_run("[cell]\nname = 'x'\n", plan(1))
    T = pose_to_matrix(np.array([1.0, 2.0, 3.0, 0.1, -0.2, 0.3]))
    db.record_measurement(rid, 0, kind="identification", joints_commanded=[0.0, 1.0], pose=T)
    with open(export_csv(db, rid, tmp_path / "a.csv"), newline="") as f:
        assert next(csv.reader(f))[5:7] == ["q1 [rad|mm]", "q2 [rad|mm]"]
    with open(export_csv(db, rid, tmp_path / "b.csv", joint_units=["rad", "mm"]), newline="") as f:
        rows = list(csv.reader(f))
    assert rows[0][5:7] == ["q1 [deg]", "q2 [mm]"]
    np.testing.assert_allclose([float(v) for v in rows[1][9:15]], [1, 2, 3, *np.degrees([0.1, -0.2, 0.3])], atol=1e-12)


# -------------------------------------------------------------------------------- bad files

def test_not_a_database_is_a_typed_error(tmp_path):
    p = tmp_path / "notes.db"
    p.write_bytes(b"this is a measurement log, not SQLite\n" * 200)
    with pytest.raises(RunDatabaseError, match="not a usable run database") as e:
        RunDB(p)
    assert e.value.exit_code == 5 and "move it away" in str(e.value)


def test_damaged_header_is_a_typed_error(tmp_path):
    p = tmp_path / "runs.db"
    with RunDB(p) as db:
        rid = db.create_run(CONFIG, plan(2))
        db.record_measurement(rid, 0, **fields(0))
    data = bytearray(p.read_bytes())
    data[:16] = b"garbage-garbage!"
    p.write_bytes(bytes(data))
    with pytest.raises(RunDatabaseError):
        RunDB(p)


def test_foreign_sqlite_file_is_refused(tmp_path):
    p = tmp_path / "other.db"
    c = sqlite3.connect(p)
    c.execute("CREATE TABLE customers (name TEXT)")
    c.commit()
    c.close()
    with pytest.raises(RunDatabaseError, match="not a station run database"):
        RunDB(p)


def test_newer_schema_version_is_refused(tmp_path):
    p = tmp_path / "runs.db"
    RunDB(p).close()
    c = sqlite3.connect(p)
    c.execute("UPDATE schema_version SET version = ?", (SCHEMA_VERSION + 1,))
    c.commit()
    c.close()
    with pytest.raises(SchemaVersionError, match="newer station") as e:
        RunDB(p)
    assert isinstance(e.value, RunDatabaseError) and e.value.exit_code == 5
    assert "Update the station" in str(e.value)


def test_bad_paths(tmp_path):
    with pytest.raises(RunDatabaseError, match="is a directory"):
        RunDB(tmp_path)
    with pytest.raises(RunDatabaseError, match="does not exist"):
        RunDB(tmp_path / "missing" / "runs.db")


def _write_locked_for(path: Path, seconds: float) -> threading.Thread:
    """Another connection takes the write lock of ``path`` (a new file: rollback journal, as a
    process that is creating it has) and gives it back after ``seconds``."""
    other = sqlite3.connect(str(path), isolation_level=None, check_same_thread=False)
    other.execute("BEGIN IMMEDIATE")

    def release() -> None:
        time.sleep(seconds)  # the other process's work: wall time is what SQLite's lock waits on
        other.execute("COMMIT")
        other.close()

    t = threading.Thread(target=release, daemon=True)
    t.start()
    return t


def test_a_database_another_process_is_creating_is_waited_for_not_refused(tmp_path):
    """A watcher (committed_steps) opening the file while the station creates it took the write
    lock; SQLite's busy timeout does not cover PRAGMA journal_mode, which failed at once: the
    starting calibration ended DATABASE_ERROR (seen under load in the suite). Now the setup is
    tried again until the lock is free."""
    path = tmp_path / "runs.sqlite"
    holder = _write_locked_for(path, 0.3)
    with RunDB(path) as db:
        assert db.latest_run() is None
    holder.join()


def test_a_lock_held_beyond_the_timeout_is_still_a_clear_error(tmp_path):
    path = tmp_path / "runs.sqlite"
    holder = _write_locked_for(path, 2.0)
    with pytest.raises(RunDatabaseError, match="database is locked"):
        RunDB(path, timeout_s=0.2)
    holder.join()
