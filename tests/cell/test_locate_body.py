"""The body is found, not assumed (issue 37 §1): an integrator's SCARA with a 9-probe head of ±3 mm
stroke on 20 mm cubes, its simulated base 3.2 mm from the guess (beyond the stroke), is located
and calibrated at the first try; a stroke that cannot cover the set-up's uncertainty even with the
search is refused before motion, and the refusal's first suggestion, applied, passes."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from simulators.from_config import simulated_cell_for
from station.cell.config.cell_config import load_config, parse_text
from station.cell.plan.locating import check_locating
from station.cell.records.rundb import RunDB
from station.cell.run.locate import RESULT_KEY
from station.core.identification.setup_locate import setup_from_contacts
from station.core.kinematics.transforms import invert, matrix_to_pose, pose_to_matrix
from station.errors import ConfigError, Outcome
from station.ui.cli.main import main

CELL = Path(__file__).resolve().parent / "data" / "integrator_scara"

#: issue 40, found by the simulated controller's collision check now on by default
def _copy(tmp_path: Path) -> Path:
    shutil.copytree(CELL, tmp_path / "cell")
    return tmp_path / "cell" / "cell.toml"


def test_the_premise_the_simulated_base_stands_beyond_the_stroke():
    cfg = load_config(CELL / "cell.toml")
    truth = simulated_cell_for(cfg, 4).truth
    guess, true = cfg.model.nominal[:6], truth.setup
    assert np.linalg.norm(true[:3] - guess[:3]) == pytest.approx(3.2, abs=0.01)
    a = invert(pose_to_matrix(guess)) @ cfg.body_points
    b = invert(pose_to_matrix(true)) @ cfg.body_points
    along_faces = np.einsum("nji,nj->ni", a[:, :3, :3], b[:, :3, 3] - a[:, :3, 3])  # in each corner's frame
    assert np.abs(along_faces).max() > 3.0 == float(cfg.head.strokes.min()) / 2  # a face beyond the probes' reach


@pytest.mark.slow  # an end-to-end session: the slow tier (README), run by CI
def test_an_integrators_scara_is_located_and_calibrated_at_the_first_try(tmp_path, capsys):
    cfg_path = _copy(tmp_path)
    db = tmp_path / "runs.sqlite"
    code = main(["calibrate", "--simulated", str(cfg_path), "--db", str(db), "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == int(Outcome.SUCCESS) == out["exit_code"], out.get("failure")
    assert out["after"]["rms_um"] < 20.0 and out["before"]["rms_um"] / out["after"]["rms_um"] > 20
    with RunDB(str(db)) as rdb:
        rec = rdb.load_result(1, RESULT_KEY)
        assert rec["search_touches"] >= 1 and rec["replanned"]  # out of stroke at the guess: searched
        located = np.array(rec["setup_located_mm_deg"][:3])
        first = [m for m in rdb.measurements(1) if m.point_id in rec["points"] and m.kind == "identification"]
        assert any("body located after" in m.message for m in first)
    truth = simulated_cell_for(load_config(cfg_path), 4).truth.setup
    # the located set-up is a starting guess: within a mm of the truth (the robot's own errors remain)
    assert np.linalg.norm(located - truth[:3]) < 1.0 < np.linalg.norm(np.array([-430.0, 10.0, -100.0]) - truth[:3])


def test_a_stroke_that_cannot_cover_the_uncertainty_is_refused_before_motion(tmp_path, capsys):
    cfg_path = _copy(tmp_path)
    text = cfg_path.read_text().replace("setup_uncertainty_mm = 5.0", "setup_uncertainty_mm = 10.0").replace(
        "repeats = 1", "repeats = 1\nlocate_steps = 1")
    cfg_path.write_text(text)
    code = main(["plan", str(cfg_path), "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == int(Outcome.CONFIG_ERROR)
    msg = out["failure"]["message"]
    assert "stroke (±3 mm" in msg and "uncertainty ±10 mm" in msg and "1 search step(s) of 4.80 mm" in msg
    first = msg.split("Change one of: ")[1].split(";")[0]
    assert first == "[plan] locate_steps = 2"
    fixed = text.replace("locate_steps = 1", "locate_steps = 2")
    cov = check_locating(parse_text(fixed, str(cfg_path)))  # the suggestion, applied verbatim, passes
    assert cov.reach >= 10.0
    # calibrate refuses the same way, before anything moves (no run is created)
    code = main(["calibrate", "--simulated", str(cfg_path), "--db", str(tmp_path / "r.sqlite"), "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == int(Outcome.CONFIG_ERROR) and out["run_id"] is None and "locate_steps = 2" in out["failure"]["message"]


def test_an_uncertainty_beyond_the_clearance_is_refused():
    text = (CELL / "cell.toml").read_text().replace("setup_uncertainty_mm = 5.0", "setup_uncertainty_mm = 25.0")
    with pytest.raises(ConfigError, match=r"exceeds the clearance \(\[plan\] clearance_mm = 20\)"):
        check_locating(parse_text(text, str(CELL / "cell.toml")))


def test_the_setup_from_located_corners_is_exact_for_an_exact_robot():
    rng = np.random.default_rng(3)
    R_true = np.array([-431.2, 12.3, -97.4, 0.0, 0.0, np.deg2rad(0.4)])
    P = np.stack([pose_to_matrix(np.array([*rng.uniform(-200, 200, 2), rng.uniform(0, 90), 0, 0, rng.uniform(-3, 3)]))
                  for _ in range(3)])
    M = np.stack([pose_to_matrix(np.array([*rng.normal(0, 1, 3), 0.0, 0.0, rng.normal(0, 0.01)])) for _ in range(3)])
    T = invert(pose_to_matrix(R_true)) @ P @ invert(M)  # base←head that puts each measured contact on its corner
    np.testing.assert_allclose(setup_from_contacts(P, T, M), R_true, atol=1e-9)
    np.testing.assert_allclose(setup_from_contacts(P[:1], T[:1], M[:1]), R_true, atol=1e-9)  # one corner alone
    assert matrix_to_pose(pose_to_matrix(R_true)) == pytest.approx(R_true)
