"""Run database: a run's measurements read again are the ones on disk now (the RunDB keeps the
records it parsed and checked, measurement_cache.py): unchanged rows are not parsed again, and a
row replaced in this process, in another process or by another tool, a step deleted, or the plan
edited, is seen at the next read."""

from __future__ import annotations

import os
import sqlite3
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from station.cell.records.record_checks import DamagedRecordError
from station.cell.records.rundb import RunDB
from tests.cell.test_rundb import CONFIG, FIELDS_SRC, assert_matches, fields

REPO = Path(__file__).resolve().parents[2]


def plan(n: int) -> list[dict]:
    """Steps naming their kind and point, so that the records' checks read the plan."""
    return [{"kind": "identification", "point_id": f"P{i % 5}", "q": [0.0, 0.1 * i, -10.0, 0.0]} for i in range(n)]


@pytest.fixture
def run(tmp_path):
    with RunDB(tmp_path / "runs.db") as db:
        rid = db.create_run(CONFIG, plan(6))
        for i in range(5):
            db.record_measurement(rid, i, **fields(i))
        yield db, rid


def _count_parses(monkeypatch) -> list[int]:
    parsed: list[int] = []
    parse = RunDB._measurement_from_row

    def counting(row):
        parsed.append(row[1])
        return parse(row)
    monkeypatch.setattr(RunDB, "_measurement_from_row", staticmethod(counting))
    return parsed


def test_unchanged_rows_are_parsed_once_and_read_the_same(run, monkeypatch):
    db, rid = run
    parsed = _count_parses(monkeypatch)
    first = db.measurements(rid)
    assert sorted(parsed) == [0, 1, 2, 3, 4]
    again = db.measurements(rid)
    ident = db.measurements(rid, kind="identification")
    assert sorted(parsed) == [0, 1, 2, 3, 4]  # nothing parsed again
    assert [m.step_index for m in again] == [m.step_index for m in ident] == [0, 1, 2, 3, 4]
    for m in again:
        assert_matches(m, rid, m.step_index)
    assert all(a is b for a, b in zip(first, again))  # frozen records with read-only arrays: shared
    assert not again[0].joints_commanded.flags.writeable
    db.record_measurement(rid, 5, **fields(5))
    parsed.clear()  # (record_measurement parses the record it returns)
    assert [m.step_index for m in db.measurements(rid)] == [0, 1, 2, 3, 4, 5]
    assert parsed == [5]  # a new step: only it is parsed


def test_a_step_replaced_in_this_process_is_read_anew(run):
    db, rid = run
    db.measurements(rid)
    db.record_measurement(rid, 2, **{**fields(2), "message": "re-measured", "pose_residual_um": 9.25}, replace=True)
    m = db.measurements(rid)[2]
    assert (m.message, m.pose_residual_um) == ("re-measured", 9.25)


def test_a_step_replaced_by_another_process_is_read_anew(run):
    db, rid = run
    before = db.measurements(rid)[3]
    # the same t_utc as the stored row, other joints: no column but the values tells them apart
    src = FIELDS_SRC + f"""
from station.cell.records.rundb import RunDB
f = fields(3)
f["joints_commanded"] = [v + 0.25 for v in f["joints_commanded"]]
with RunDB({str(db.path)!r}) as other:
    other.record_measurement({rid}, 3, **f, t_utc={before.t_utc!r}, replace=True)
"""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    subprocess.run([sys.executable, "-c", src], check=True, env=env, cwd=REPO, timeout=120)
    after = db.measurements(rid)[3]
    assert after.t_utc == before.t_utc
    np.testing.assert_allclose(after.joints_commanded, np.asarray(fields(3)["joints_commanded"]) + 0.25)


def test_a_step_deleted_by_another_tool_drops_out(run):
    db, rid = run
    db.measurements(rid)
    with sqlite3.connect(db.path) as c:
        c.execute("DELETE FROM measurements WHERE run_id = ? AND step_index = 1", (rid,))
    assert [m.step_index for m in db.measurements(rid)] == [0, 2, 3, 4]


def test_a_row_damaged_after_a_good_read_is_named(run):
    db, rid = run
    db.measurements(rid)
    with sqlite3.connect(db.path) as c:  # not a rigid transformation
        c.execute("UPDATE measurements SET pose = ? WHERE run_id = ? AND step_index = 4",
                  (str(np.diag([2.0, 1.0, 1.0, 1.0]).tolist()), rid))
    with pytest.raises(DamagedRecordError, match="step 4") as e:
        db.measurements(rid)
    assert e.value.exit_code == 5 and "pose" in str(e.value)
    with pytest.raises(DamagedRecordError):  # and again: a damaged row is never kept
        db.measurements(rid)


def test_a_plan_edited_after_a_good_read_checks_the_records_again(run):
    db, rid = run
    db.measurements(rid)
    edited = plan(6)
    edited[0]["point_id"] = "P9"
    with sqlite3.connect(db.path) as c:
        c.execute("UPDATE runs SET plan_json = ? WHERE id = ?", (__import__("json").dumps(edited), rid))
    with pytest.raises(DamagedRecordError, match="point_id"):
        db.measurements(rid)


def test_only_the_runs_read_last_are_kept(tmp_path, monkeypatch):
    from station.cell.records.measurement_cache import MAX_RUNS

    with RunDB(tmp_path / "runs.db") as db:
        rids = [db.create_run(CONFIG, plan(2)) for _ in range(MAX_RUNS + 1)]
        for rid in rids:
            db.record_measurement(rid, 0, **fields(0))
        parsed = _count_parses(monkeypatch)
        for rid in rids:  # the first run drops out when the last is read
            db.measurements(rid)
        parsed.clear()
        db.measurements(rids[-1])
        assert parsed == []
        db.measurements(rids[0])
        assert parsed == [0]
