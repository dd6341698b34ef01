"""A new cell right the first time (issue 27): ``station init`` from the cell's files, ``plan`` and
``calibrate --simulated`` succeed at the first try; a table that misses its bound after
identification ends NOT_UPLOADED with its reason, never IDENTIFICATION_FAILED."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import pytest

from station.cell.records.rundb import RunDB
from station.cell.session.calibrate import CellRequest, run_calibration_session
from station.errors import Outcome
from station.ui.cli.main import main
from station.ui.simulated_cell import load_cell
from station.ui.tui.result_panel import summary_markup

ROOT = Path(__file__).resolve().parents[2]


def _new_scara(tmp_path: Path) -> None:
    """A SCARA with 380 + 270 mm arms (used nowhere else in the project), written from files only:
    its robot file, the reference 3-2-1 head and the reference body's CMM report."""
    robot = (ROOT / "examples" / "scara_arc" / "robot.toml").read_text(encoding="utf-8")
    robot = robot.replace("\nx = 300.0\n", "\nx = 380.0\n").replace("\nx = 250.0\n", "\nx = 270.0\n")
    assert "x = 380.0" in robot and "x = 270.0" in robot
    (tmp_path / "robot.toml").write_text(robot.replace('name = "scara550"', 'name = "scara650-test"'), encoding="utf-8")
    shutil.copy(ROOT / "examples" / "heads" / "reference-321.toml", tmp_path / "head.toml")
    shutil.copy(ROOT / "examples" / "bodies" / "reference-body.csv", tmp_path / "body.csv")


@pytest.mark.slow  # an end-to-end session: the slow tier (README), run by CI
def test_init_from_the_files_then_plan_and_calibrate_succeed_at_the_first_try(tmp_path, capsys, monkeypatch):
    _new_scara(tmp_path)
    monkeypatch.chdir(tmp_path)
    assert main(["init", "cell.toml", "--robot", "robot.toml", "--head", "head.toml", "--body", "body.csv"]) == 0
    said = capsys.readouterr().out
    assert "[robot] setup:" in said and "[plan] repeats =" in said and "designed by the station" in said
    text = (tmp_path / "cell.toml").read_text(encoding="utf-8")
    assert 'model = "robot.toml"' in text and 'file = "head.toml"' in text and 'file = "body.csv"' in text
    assert "this head's shortest probe stroke is ±" in text  # the head's own stroke, not the built-in head's
    assert main(["plan", "cell.toml"]) == 0
    assert "correction table (designed by the station)" in capsys.readouterr().out
    code = main(["calibrate", "--simulated", "cell.toml", "--seed", "3", "--db", "runs.sqlite", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and out["outcome"] == "SUCCESS", out.get("failure") or out.get("notes")
    assert out["correction"]["interpolation_bound_um"] <= 15.0 and out["correction"]["predicted_bound_um"] > 0


def test_a_table_over_its_bound_after_identification_is_not_uploaded_with_its_reason(tmp_path, monkeypatch):
    import station.cell.pipeline.calibration as pipeline

    real = pipeline.identified_table

    def over(cfg, params, design):  # the identified robot's table misses the bound, whatever the grid
        table, used, _ = real(cfg, params, design)
        return table, used, 2.0 * cfg.correction.max_interpolation_um

    monkeypatch.setattr(pipeline, "identified_table", over)
    db = tmp_path / "runs.sqlite"
    s = run_calibration_session(CellRequest(simulated=True, seed=2, db=str(db)), lambda e: None, load=load_cell)
    assert s.outcome is Outcome.NOT_UPLOADED and s.exit_code == 11 and s.failure is None
    out = s.to_json()
    assert out["not_uploaded_reason"] == "correction_bound" and out["upload_skipped"]
    note = next(n for n in s.notes if "no correction table" in n)
    assert re.search(r"interpolates with up to 30\.0 µm in the cell x", note), note
    assert f"--resume {s.run_id}" in note and "correction.max_interpolation_um = 32" in note
    with RunDB(str(db)) as rdb:  # every measurement and the identified parameters are kept
        assert rdb.load_result(s.run_id, "identification", default=None) is not None
        assert rdb.measurements(s.run_id, kind="identification")
    panel = summary_markup(s)
    assert "NOT UPLOADED" in panel and "press" not in panel  # no one-key resume that would fail again at once
