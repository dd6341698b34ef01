"""A resume with only what post-processes the measurements changed (issue 18 §2): the correction
grid, the identification's settings, tolerances, names in the report. Every measurement is reused
and the run says so; a change to what is measured is still refused, and so are verification poses
measured with the identification or table that the change replaces."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from types import SimpleNamespace

import pytest

from station.cell.records.fingerprint import POST_PROCESSING, check_same_cell, resume_note
from station.cell.records.reading.stored_config import stored_config
from station.cell.records.rundb import RunDB
from station.errors import ConfigError, Outcome
from station.ui.cli.main import main

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "scara600"
FP = {"[robot]": "a", "[body]": "b", "[correction]": "c", "[identification]": "d", "robot model": "e"}


def test_only_post_processing_changed_is_resumable_and_named():
    now = {**FP, "[correction]": "c2", "[verification]": "v"}
    assert check_same_cell(FP, now, 3) == ("[correction]", "[verification]")
    note = resume_note(check_same_cell(FP, now, 3))
    assert note and "[correction]" in note and "every measurement on disk is reused" in note
    assert resume_note(check_same_cell(FP, dict(FP), 3)) is None
    assert "[body]" not in POST_PROCESSING and "[plan]" not in POST_PROCESSING


@pytest.mark.parametrize("key", ["[body]", "[robot]", "robot model", "[plan]"])
def test_what_changes_measurements_is_refused(key):
    with pytest.raises(ConfigError, match=rf"run 3 was measured on a different cell: .*{key.replace('[', '.')}"):
        check_same_cell(FP, {**FP, key: "other"}, 3)


def test_verification_measured_with_the_old_table_or_identification_is_refused():
    after = [SimpleNamespace(kind="identification"), SimpleNamespace(kind="verification_after")]
    with pytest.raises(ConfigError, match=r"\[correction\] changed since, but its verification_after poses"):
        check_same_cell(FP, {**FP, "[correction]": "c2"}, 3, after)
    before = [SimpleNamespace(kind="verification_before")]
    assert check_same_cell(FP, {**FP, "[correction]": "c2"}, 3, before) == ("[correction]",)  # no table in them
    with pytest.raises(ConfigError, match=r"\[identification\] changed since, but its verification_before poses"):
        check_same_cell(FP, {**FP, "[identification]": "d2"}, 3, before)


def test_a_resume_with_another_grid_reuses_every_measurement(tmp_path, capsys):
    for name in ("robot.toml", "head.toml", "body.csv"):
        shutil.copy(EXAMPLE / name, tmp_path / name)
    text = (EXAMPLE / "cell.toml").read_text()
    text = text[: text.index("[[tool]]")].replace("repeats = 4", "repeats = 1").replace(
        "verification_cycles = 5", "verification_cycles = 1")
    path, db = tmp_path / "cell.toml", str(tmp_path / "runs.sqlite")
    path.write_text(text)
    assert main(["calibrate", "--simulated", str(path), "--db", db, "--no-upload", "--json"]) == int(Outcome.NOT_UPLOADED)
    capsys.readouterr()
    with RunDB(db) as rdb:
        before = [(m.step_index, m.t_utc) for m in rdb.measurements(1)]
    path.write_text(text.replace("max_interpolation_um = 15.0", "max_interpolation_um = 14.0"))
    code = main(["calibrate", "--simulated", str(path), "--db", db, "--no-upload", "--resume", "1", "--json"])
    captured = capsys.readouterr()
    out = json.loads(captured.out)
    assert code == int(Outcome.NOT_UPLOADED) == out["exit_code"], out.get("failure")
    assert "every measurement on disk is reused" in captured.err
    with RunDB(db) as rdb:
        assert [(m.step_index, m.t_utc) for m in rdb.measurements(1)] == before  # nothing measured again
        # the table and the report are made with the configuration the run finished with
        assert stored_config(rdb, 1).correction.max_interpolation_um == 14.0
    path.write_text(text.replace("max_interpolation_um = 15.0", "max_interpolation_um = 14.0").replace(
        "cube_edge_mm = 30.0", "cube_edge_mm = 30.5"))  # another body: refused
    code = main(["calibrate", "--simulated", str(path), "--db", db, "--no-upload", "--resume", "1", "--json"])
    assert code == int(Outcome.CONFIG_ERROR)
    assert "[body] changed since" in json.loads(capsys.readouterr().out)["failure"]["message"]
