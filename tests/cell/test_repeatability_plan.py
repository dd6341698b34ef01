"""The robot file's repeatability in a cell (issue 38): the measurement σ the plan, its preview and
the fit use gains it in quadrature; a bad value stops `station plan` with exit 2 and its fix."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from station.cell.config.cell_config import load_config
from station.cell.pipeline.preview import preview
from station.cell.session.new_cell import ASSUMED_SIGMA_UM, HEAD_SIGMA_UM
from station.core.measurement.repeatability import RP_PER_SIGMA
from station.ui.cli.main import main

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "scara600"


def _cell(tmp_path: Path, line: str | None) -> Path:
    folder = tmp_path / "cell"
    shutil.copytree(EXAMPLE, folder)
    if line is not None:
        robot = folder / "robot.toml"
        robot.write_text(robot.read_text().replace('length_unit = "mm"\n', f'length_unit = "mm"\n{line}\n', 1))
    return folder / "cell.toml"


def test_the_repeatability_widens_the_noise_and_the_predicted_accuracy(tmp_path):
    plain = load_config(_cell(tmp_path / "a", None))
    keyed = load_config(_cell(tmp_path / "b", "repeatability_mm = 0.03"))
    assert plain.identification.repeatability_mm is None
    assert keyed.identification.repeatability_mm == 0.03
    s = plain.identification.sigma_position_um * 1e-3
    assert keyed.identification.pose_sigma()[:3] == pytest.approx(np.hypot(s, 0.03 / RP_PER_SIGMA))
    assert np.array_equal(keyed.identification.pose_sigma()[3:], plain.identification.pose_sigma()[3:])
    # the same poses (the stopping rule is relative to the noise) and a larger predicted σ
    with_rp, without = preview(keyed), preview(plain)
    assert with_rp.sigma_position_um[1] > 1.2 * without.sigma_position_um[1]


def test_a_negative_repeatability_stops_the_plan_with_its_fix(tmp_path, capsys):
    cfg = _cell(tmp_path, "repeatability_mm = -0.02")
    code = main(["plan", str(cfg)])
    err = capsys.readouterr().err
    assert code == 2
    assert "repeatability_mm = -0.02 is outside (0, 10] mm" in err and "ISO 9283" in err
    assert "Traceback" not in err


def test_init_takes_the_robots_repeatability_from_its_data_sheet(tmp_path, capsys, monkeypatch):
    """`station init`'s expected figure after correction counts the robot file's RP, not the
    simulator's [simulation] repeatability_um, where the file states it."""
    folder = _cell(tmp_path, "repeatability_mm = 0.02").parent
    monkeypatch.chdir(folder)
    assert main(["init", "new.toml", "--robot", "robot.toml", "--head", "head.toml", "--body", "body.csv"]) == 0
    said = capsys.readouterr().out
    assert f"repeatability σ {0.02 / RP_PER_SIGMA * 1e3:.1f} µm per axis from the robot file's RP 20 µm" in said
    written = load_config(folder / "new.toml").identification
    assert written.repeatability_mm == 0.02
    # the position σ it writes is the head's alone: the fit adds the RP, so it is not counted twice
    assert written.sigma_position_um == pytest.approx(HEAD_SIGMA_UM) and HEAD_SIGMA_UM < ASSUMED_SIGMA_UM
    assert written.pose_sigma()[0] * 1e3 == pytest.approx(np.hypot(HEAD_SIGMA_UM, 20 / RP_PER_SIGMA))


def test_init_without_a_repeatability_writes_the_sigma_that_includes_it(tmp_path, monkeypatch):
    folder = _cell(tmp_path, None).parent
    monkeypatch.chdir(folder)
    assert main(["init", "new.toml", "--robot", "robot.toml", "--head", "head.toml", "--body", "body.csv"]) == 0
    written = load_config(folder / "new.toml").identification
    assert written.repeatability_mm is None and written.sigma_position_um == ASSUMED_SIGMA_UM
