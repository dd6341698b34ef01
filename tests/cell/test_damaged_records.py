"""Records with bad contents in a valid run database: each is a typed error with exit 5 that
names the run and the record, through every command that reads it (issue 19)."""

from __future__ import annotations

from tests.cell.damaged_runs import damaged, run_cli


def _refused(capsys, argv: tuple, *expected: str) -> None:
    rc, text = run_cli(capsys, *argv)
    assert rc == 5, text
    for e in expected:
        assert e in text, text
    assert "Traceback" not in text and "internal error" not in text


def test_plan_that_is_not_json(good_db, tmp_path, capsys):
    db = damaged(good_db, tmp_path, "UPDATE runs SET plan_json = '{not json' WHERE id = 1;")
    msg = ("run 1: the stored plan is damaged (not JSON", "start a new run")
    _refused(capsys, ("runs", "--db", db), *msg)
    _refused(capsys, ("report", "1", "--db", db, "-o", tmp_path / "rep"), *msg)
    _refused(capsys, ("export", "--db", db, "--run", "1", tmp_path / "m.csv"), *msg)
    _refused(capsys, ("calibrate", "--simulated", "--seed", "1", "--resume", "1", "--db", db), *msg)
    _refused(capsys, ("recheck", "--simulated", "--seed", "1", "--db", db), *msg)


def test_summary_of_an_open_bracket(good_db, tmp_path, capsys):
    db = damaged(good_db, tmp_path, "UPDATE results SET json = '[' WHERE key = 'summary';")
    msg = ("run 1: the stored result 'summary' is damaged (not JSON", "start a new run")
    _refused(capsys, ("runs", "--db", db, "--json"), *msg)
    _refused(capsys, ("report", "1", "--db", db, "-o", tmp_path / "rep"), *msg)
    _refused(capsys, ("recheck", "--simulated", "--seed", "1", "--db", db), *msg)


def test_summary_of_the_wrong_json_type(good_db, tmp_path, capsys):
    db = damaged(good_db, tmp_path, "UPDATE results SET json = '[1, 2]' WHERE key = 'summary';")
    _refused(capsys, ("runs", "--db", db), "run 1: the stored result 'summary' is damaged (a JSON list where an "
                                           "object belongs)")


def test_measurements_table_without_the_stations_columns(good_db, tmp_path, capsys):
    db = damaged(good_db, tmp_path, "DROP TABLE measurements; "
                                     "CREATE TABLE measurements(run_id INTEGER, step_index INTEGER, kind TEXT);")
    msg = (f"{db}: the measurements table lacks the station's columns point_id", "restore a backup")
    _refused(capsys, ("runs", "--db", db), *msg)
    _refused(capsys, ("export", "--db", db, "--run", "1", tmp_path / "m.csv"), *msg)
    _refused(capsys, ("report", "1", "--db", db, "-o", tmp_path / "rep"), *msg)
    _refused(capsys, ("calibrate", "--simulated", "--seed", "1", "--resume", "1", "--db", db), *msg)


def test_stored_step_with_five_joints_for_a_four_joint_robot(good_db, tmp_path, capsys):
    db = damaged(good_db, tmp_path, "UPDATE runs SET plan_json = json_replace(plan_json, '$[3].joints', "
                                     "json_insert(json_extract(plan_json, '$[3].joints'), '$[#]', 0.0));")
    msg = ("run 1: the stored plan step 3 is damaged (5 joints for a robot with 4)", "start a new run")
    _refused(capsys, ("calibrate", "--simulated", "--seed", "1", "--resume", "1", "--db", db), *msg)
    _refused(capsys, ("report", "1", "--db", db, "-o", tmp_path / "rep"), *msg)


def test_stored_step_of_an_unknown_kind(good_db, tmp_path, capsys):
    db = damaged(good_db, tmp_path, "UPDATE runs SET plan_json = json_replace(plan_json, '$[0].kind', 'dance');")
    _refused(capsys, ("report", "1", "--db", db, "-o", tmp_path / "rep"), "run 1: the stored plan step 0 is damaged")


def test_measurement_with_unreadable_joints(good_db, tmp_path, capsys):
    db = damaged(good_db, tmp_path, "UPDATE measurements SET joints_commanded = '[1, 2' WHERE step_index = 0;")
    msg = ("run 1: the stored measurement of step 0 (joints commanded) is damaged",)
    _refused(capsys, ("export", "--db", db, "--run", "1", tmp_path / "m.csv"), *msg)
    _refused(capsys, ("calibrate", "--simulated", "--seed", "1", "--resume", "1", "--db", db), *msg)


def test_measurement_pose_of_the_wrong_shape(good_db, tmp_path, capsys):
    db = damaged(good_db, tmp_path, "UPDATE measurements SET pose = '[[1, 2], [3, 4]]' WHERE step_index = 0;")
    _refused(capsys, ("export", "--db", db, "--run", "1", tmp_path / "m.csv"),
             "run 1: the stored measurement of step 0 (pose) is damaged (an array of shape (2, 2))")


def test_a_plan_emptied_under_its_measurements(good_db, tmp_path, capsys):
    """Found by benchmarks/fuzz_campaign.py: an IndexError deep in the verification figures."""
    db = damaged(good_db, tmp_path, "UPDATE runs SET plan_json = '[]' WHERE id = 1;")
    msg = ("run 1: the stored measurement of step 0 is damaged", "the stored plan has 0 steps")
    _refused(capsys, ("report", "1", "--db", db, "-o", tmp_path / "rep"), *msg)
    _refused(capsys, ("calibrate", "--simulated", "--seed", "1", "--resume", "1", "--db", db), *msg)


def test_joints_read_of_another_robot(good_db, tmp_path, capsys):
    """Found by benchmarks/fuzz_campaign.py: numpy's 'inhomogeneous shape' in the identification."""
    db = damaged(good_db, tmp_path, "UPDATE measurements SET joints_read = '[1]' WHERE run_id = 1 AND step_index = 0;")
    msg = ("run 1: the stored measurement of step 0 (joints read) is damaged", "1 values for a step of 4 joints")
    _refused(capsys, ("report", "1", "--db", db, "-o", tmp_path / "rep"), *msg)
    _refused(capsys, ("calibrate", "--simulated", "--seed", "1", "--resume", "1", "--db", db), *msg)
