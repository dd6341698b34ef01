"""Every field of every record read is checked (issue 33): a damaged measurement, result or lock
row is exit 5 naming the run, the table, the row and the field, through the run database's reading
side; integers from the command line are range-checked before they reach SQLite; the eight
internal errors of the reliability campaign are each a typed error now."""

from __future__ import annotations

import sqlite3

import pytest

from station.cell.records.record_checks import DamagedRecordError
from station.cell.records.run_records import RunNotFoundError
from station.cell.records.rundb import RunDB
from tests.cell.damaged_runs import damaged, run_cli


def _no_internal(text: str) -> None:
    assert "Traceback" not in text and "internal error" not in text and "NoneType" not in text, text


_M = "UPDATE measurements SET {} WHERE step_index = 3;"

#: (the damage, the field the message must name): each was exit 0 before (issue 33, "silent acceptances")
FIELD_DAMAGES = [
    (_M.format("kind = 'bogus'"), "field kind: 'bogus' is not a measurement kind"),
    (_M.format("kind = 'reversal'"), "field kind: 'reversal', but the plan's step 3 is 'identification'"),
    (_M.format("point_id = 'ZZ'"), "field point_id: 'ZZ', but the plan's step 3 measures"),
    (_M.format("t_utc = 'x'"), "field t_utc: 'x' is not a UTC time stamp"),
    (_M.format("t_utc = '2026-13-45T99:00:00Z'"), "field t_utc"),
    (_M.format("channel_status = '[\"ok\",\"ok\",\"ok\",\"ok\",\"ok\",\"garbage\"]'"),
     "field channel_status: 'garbage' is not a channel status"),
    (_M.format("channel_status = '[\"ok\"]'"), "field channel_status: 1 statuses for 6 readings"),
    (_M.format("readings_mm = '[1]', channel_status = '[\"ok\"]'"), "field readings_mm: 1 readings for a head of 6"),
    (_M.format("readings_mm = '[1e308,1,1,1,1,1]'"), "field readings_mm: a reading beyond ±1000 mm"),
    (_M.format("joints_commanded = '[1e300, 0, 0, 0]'"), "field joints_commanded: a joint beyond"),
    (_M.format("joints_read = '[0, 9, 0, 0]'"), "field joints_read: joint 2 = 9 outside the robot's range"),
    (_M.format("pose = '[[2,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]'"), "field pose: not a rigid transformation"),
    (_M.format("pose = '[[1,0,0,1e300],[0,1,0,0],[0,0,1,0],[0,0,0,1]]'"), "field pose: a position beyond"),
    (_M.format("pose_residual_um = -5"), "field pose_residual_um: -5.0 is not a finite residual"),
    ("UPDATE runs SET plan_json = json_set(plan_json, '$[3].joints[0]', 1e300);",
     "table runs, row run 1, field plan_json step 3 joints: joint 1 = 1e+300 outside the robot's range"),
    ("UPDATE runs SET plan_json = json_set(plan_json, '$[3].point_id', 'ZZ');",
     "field plan_json step 3 point_id: 'ZZ' is no point of the run's body"),
    # a row of no run is named by its SQLite rowid, the order rows were written in: not step + 1,
    # since the body's locating touches are recorded first and out of the plan's order (issue 37);
    # {rowid} is step 3's rowid in the good database (_ROWID)
    ("PRAGMA foreign_keys = OFF; UPDATE measurements SET run_id = 99 WHERE step_index = 3;",
     "table measurements, row rowid {rowid} (step 3), field run_id: run 99 does not exist"),
]
_ROWID = "{rowid}"


def _step3_rowid(db) -> int:
    conn = sqlite3.connect(db)
    try:
        (rowid,), = conn.execute("SELECT rowid FROM measurements WHERE run_id = 1 AND step_index = 3").fetchall()
    finally:
        conn.close()
    return int(rowid)


@pytest.mark.parametrize("sql, field", FIELD_DAMAGES, ids=[f[1].replace(_ROWID, "N")[:40] for f in FIELD_DAMAGES])
def test_a_damaged_measurement_field_is_exit_5_naming_table_row_and_field(good_db, tmp_path, capsys, sql, field):
    if _ROWID in field:
        field = field.replace(_ROWID, str(_step3_rowid(good_db)))  # the row as SQLite numbers it
    db = damaged(good_db, tmp_path, sql)
    rc, text = run_cli(capsys, "export", "--db", db, "--run", "1", tmp_path / "m.csv")
    assert rc == 5 and field in text and "the stored record is damaged" in text, text
    assert "keep the database file" in text
    _no_internal(text)


def test_a_row_of_a_damaged_kind_does_not_drop_out_of_a_selection_by_kind(good_db, tmp_path):
    db = damaged(good_db, tmp_path, _M.format("kind = 'bogus'"))
    with RunDB(db) as rdb, pytest.raises(DamagedRecordError, match="row step 3, field kind"):
        rdb.measurements(1, kind="identification")


def test_an_unknown_point_id_is_exit_5_in_the_report(good_db, tmp_path, capsys):
    """Was ``KeyError`` (internal error) in ``report``."""
    db = damaged(good_db, tmp_path, _M.format("point_id = 'ZZ'"))
    rc, text = run_cli(capsys, "report", "1", "--db", db, "-o", tmp_path / "rep")
    assert rc == 5 and "field point_id" in text, text
    _no_internal(text)


@pytest.mark.parametrize("value, field", [
    ("[1]", "field json: a JSON list where an object of displacements by step belongs"),
    ('{"3": 5}', "field json['3']: not a displacement of six finite numbers"),
    ('{"x": [0,0,0,0,0,0]}', "field json['x']: not a step of the run's plan"),
])
def test_a_malformed_recentring_result_is_exit_5_in_the_report(good_db, tmp_path, capsys, value, field):
    """Was ``AttributeError`` (internal error) in ``report``."""
    db = damaged(good_db, tmp_path, f"UPDATE results SET json = '{value}' WHERE key = 'recentring';")
    rc, text = run_cli(capsys, "report", "1", "--db", db, "-o", tmp_path / "rep")
    assert rc == 5 and "table results, row key 'recentring', " + field in text, text
    _no_internal(text)


@pytest.mark.parametrize("value, field", [
    ('[1]', "field json: a JSON list where an object belongs"),
    ('{"name": "t1", "summary": [1]}', "field json.tool_params_identified"),
    ('{"name": "t1", "tool_params_identified": [1], "tool_params_nominal": [1], "summary": 3}', "field json.summary"),
    ('{"name": "t1", "error": 5}', "field json.error"),
])
def test_a_malformed_tool_result_is_exit_5_in_export(good_db, tmp_path, capsys, value, field):
    """Was ``AttributeError`` (internal error) in ``export --tool``."""
    db = damaged(good_db, tmp_path, "INSERT INTO results(run_id, key, json, t_utc) VALUES "
                                     f"(1, 'tool:t1', '{value}', '2026-01-01T00:00:00Z');")
    rc, text = run_cli(capsys, "export", "--db", db, "--run", "1", "--tool", "t1", tmp_path / "t.json")
    assert rc == 5 and "table results, row key 'tool:t1', " + field in text, text
    _no_internal(text)


def test_a_lock_row_with_a_non_numeric_pid_is_exit_5_and_can_be_cleared(good_db, tmp_path, capsys):
    """Was ``ValueError`` (internal error) in ``calibrate --resume``."""
    db = damaged(good_db, tmp_path, "CREATE TABLE IF NOT EXISTS run_locks (run_id INTEGER PRIMARY KEY, host TEXT "
                                     "NOT NULL, pid INTEGER NOT NULL, pid_start TEXT NOT NULL DEFAULT '', since_utc "
                                     "TEXT NOT NULL, token TEXT NOT NULL); INSERT INTO run_locks VALUES "
                                     "(1, 'pc', 'abc', '', '2026-01-01T00:00:00Z', 't');")
    rc, text = run_cli(capsys, "calibrate", "--simulated", "--seed", "1", "--resume", "1", "--db", db)
    assert rc == 5 and "table run_locks, row run 1, field pid: 'abc' is not a process id" in text, text
    assert "station runs --unlock 1" in text
    _no_internal(text)
    rc, text = run_cli(capsys, "runs", "--db", db, "--unlock", "1")
    assert rc == 0 and "cleared" in text, text
    with RunDB(db) as rdb:
        assert rdb.run_lock(1) is None


BIG = "99999999999999999999"  # above 2^63


@pytest.mark.parametrize("argv", [
    ("report", BIG), ("export", "--run", BIG, "m.csv"), ("runs", "--unlock", BIG),
    ("calibrate", "--simulated", "--resume", BIG), ("recheck", "--simulated", "--resume", BIG),
    ("report", "0"), ("report", "-1"), ("export", "--run", "1e3", "m.csv"),
], ids=lambda a: " ".join(a)[:40])
def test_a_run_number_out_of_range_is_a_usage_error(tmp_path, capsys, argv):
    """Was ``OverflowError`` (internal error) in all five commands."""
    rc, text = run_cli(capsys, *argv, "--db", tmp_path / "runs.sqlite")
    assert rc == 2 and "a run number" in text and "9223372036854775807" in text, text
    _no_internal(text)


@pytest.mark.parametrize("seed", ["-1", "4294967296", BIG, "x"])
def test_a_seed_out_of_range_is_a_usage_error(tmp_path, capsys, seed):
    """``--seed -1`` was ``ValueError`` (internal error)."""
    rc, text = run_cli(capsys, "calibrate", "--simulated", "--seed", seed, "--db", tmp_path / "r.sqlite")
    assert rc == 2 and "seed" in text and "0 … 4294967295" in text, text
    _no_internal(text)


def test_a_run_id_beyond_sqlite_never_reaches_it(good_db):
    with RunDB(good_db) as rdb:
        for bad in (2**63, 2**70, -1, 0, True, "1"):
            with pytest.raises(RunNotFoundError, match="is not a run number"):
                rdb.run(bad)  # type: ignore[arg-type]


def test_the_records_of_a_good_run_all_pass(good_db):
    with RunDB(good_db) as rdb:
        assert len(rdb.measurements(1)) == rdb.run(1).n_steps
        assert len(rdb.measurements(1, kind="oracle")) == 55
        assert isinstance(rdb.load_result(1, "recentring"), dict)
