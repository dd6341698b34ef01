"""Rehearse your cell (issue 8, point 4): ``station calibrate --simulated CONFIG`` simulates the cell
the user's own files describe (robot, set-up, body, limits, word order; the true errors from its
``[simulation]``); a file holding only ``[simulation]`` (and ``[recheck]``, ``[warmup]``) keeps
the built-in cell, and no file at all is exactly today's built-in cell."""

from __future__ import annotations

import json
import tomllib
from contextlib import ExitStack

import numpy as np
import pytest

from simulators.cell import CalibrationBody, CellTruth, CubeSpec
from station.cell.records.rundb import RunDB
from station.cell.session.calibrate import CellRequest, run_calibration_session
from station.core.kinematics.transforms import matrix_to_pose
from station.errors import ConfigError, Outcome
from station.ui.cli.main import main
from station.ui.simulated_cell import load_cell

# five 40 mm cubes in a layout of their own (not the built-in body), 20 corners
CUBES = (CubeSpec(20.0, -280.0, 0.0, np.deg2rad(25.0)), CubeSpec(160.0, -120.0, 50.0, np.deg2rad(-10.0)),
         CubeSpec(-20.0, 20.0, 100.0, np.deg2rad(40.0)), CubeSpec(140.0, 170.0, 20.0, np.deg2rad(0.0)),
         CubeSpec(-10.0, 290.0, 70.0, np.deg2rad(-30.0)))


def _points() -> str:
    lines = []
    for i, cube in enumerate(CUBES):
        for k, T in enumerate(CalibrationBody.corner_frames(cube, 40.0)):
            p = matrix_to_pose(T)
            pose = ", ".join(f"{v:.4f}" for v in (*p[:3], *np.degrees(p[3:])))
            lines.append(f'  {{ id = "B{i + 1}{"abcd"[k]}", pose = [{pose}] }},')
    return "\n".join(lines)


def user_cell(simulation: str = "seed = 3") -> str:
    """The SR 800 on another set-up, another body, a little-endian controller."""
    return f"""[cell]
name = "rehearsal cell"
[robot]
model = "sr800"
setup = [-430.0, 25.0, -160.0, 0.0, 0.0, 4.0]
[limits]
joints = [[-125.0, 125.0], [-140.0, 140.0], [-195.0, -5.0], [-355.0, 355.0]]
[body]
cube_edge_mm = 40.0
points = [
{_points()}
]
[devices]
probe_head = "/dev/ttyUSB0"
controller = "192.168.0.10:502"
word_order = "little"
[plan]
settle_s = 0.0
repeats = 4
verification_cycles = 5
[identification]
sigma_position_um = 6.0
sigma_angle_arcsec = 6.0
[simulation]
{simulation}
"""


@pytest.mark.slow  # an end-to-end session: the slow tier (README), run by CI
def test_a_user_cell_is_rehearsed_end_to_end(tmp_path, capsys):
    """Calibrated in simulation: ≥ 20× better, within 1.2× of the oracle; then a recheck of the
    same rehearsal (through the same loading) finds the same cell and no drift."""
    path, db = tmp_path / "cell.toml", str(tmp_path / "runs.sqlite")
    path.write_text(user_cell())
    events: list = []
    summary = run_calibration_session(CellRequest(config=str(path), simulated=True, db=db), events.append,
                                      load=load_cell)
    assert summary.outcome is Outcome.SUCCESS, summary.failure
    assert summary.cell == "rehearsal cell"
    assert summary.gain is not None and summary.gain >= 20.0
    assert summary.after_vs_oracle is not None and 0.7 <= summary.after_vs_oracle <= 1.2, summary.after_vs_oracle
    assert summary.after is not None and summary.after.rms_um < 30.0, summary.after  # µm
    with RunDB(db) as rdb:
        run = rdb.run(summary.run_id)
    stored = tomllib.loads(run.config_toml)  # the run's record is the user's cell, simulated
    assert [p["id"] for p in stored["body"]["points"]][:2] == ["B1a", "B1b"] and len(stored["body"]["points"]) == 20
    assert stored["robot"]["setup"] == [-430.0, 25.0, -160.0, 0.0, 0.0, 4.0]
    assert stored["devices"]["word_order"] == "little" and stored["simulation"] == {"seed": 3}
    assert stored["devices"]["controller"].startswith("127.0.0.1:")
    capsys.readouterr()
    assert main(["recheck", str(path), "--simulated", "--db", db, "--json", "--poses", "5"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["outcome"] == "SUCCESS" and out["baseline"]["run_id"] == summary.run_id


def _loaded(request: CellRequest):
    stack = ExitStack()
    return stack, load_cell(request, stack)


def test_the_rehearsed_truth_is_the_user_cell_and_the_seed_flag_overrides(tmp_path):
    path = tmp_path / "cell.toml"
    path.write_text(user_cell("seed = 3\nlength_sigma_um = 10.0"))
    stack, loaded = _loaded(CellRequest(config=str(path), simulated=True))
    with stack:
        assert loaded.endpoints["seed"] == 3 and loaded.cfg.simulated_seed == 3
        setup = loaded.judge.robot.model.nominal[loaded.judge.robot.model.setup_slice()]
        assert np.allclose(setup, [-430.0, 25.0, -160.0, 0.0, 0.0, np.deg2rad(4.0)])
        assert loaded.cfg.point_ids[0] == "B1a" and loaded.cfg.devices.word_order == "little"
        assert loaded.cfg.devices.controller_host == "127.0.0.1"
        n_t = loaded.judge.robot.model.n_params // 6
        lengths = loaded.judge.robot.errors.reshape(n_t, 6)[1:, :3]
        assert np.max(np.abs(lengths)) < 0.06  # σ 10 µm, not the default 40 µm
    stack, loaded = _loaded(CellRequest(config=str(path), simulated=True, seed=8))
    with stack:
        assert loaded.endpoints["seed"] == 8 and tomllib.loads(loaded.cfg.source_text)["simulation"]["seed"] == 8


def test_no_file_is_todays_builtin_cell():
    stack, loaded = _loaded(CellRequest(simulated=True, seed=2))
    with stack:
        assert np.array_equal(loaded.judge.robot.params, CellTruth.generate(seed=2).params)
        assert loaded.cfg.name == "simulated reference cell" and len(loaded.cfg.point_ids) == 24
        assert tomllib.loads(loaded.cfg.source_text)["simulation"] == {"seed": 2}


def test_a_file_with_only_simulation_keeps_the_builtin_cell(tmp_path):
    path = tmp_path / "sim.toml"
    path.write_text("[simulation]\nseed = 4\nprobe_noise_um = 1.0\n[recheck]\nposes = 5\n")
    stack, loaded = _loaded(CellRequest(config=str(path), simulated=True))
    with stack:
        assert loaded.cfg.name == "simulated reference cell" and len(loaded.cfg.point_ids) == 24
        assert np.array_equal(loaded.judge.robot.params, CellTruth.generate(seed=4).params)
        assert loaded.cfg.recheck.poses == 5
        assert tomllib.loads(loaded.cfg.source_text)["simulation"] == {"seed": 4, "probe_noise_um": 1.0}
    stack, loaded = _loaded(CellRequest(config=str(path), simulated=True, seed=6))
    with stack:
        assert loaded.endpoints["seed"] == 6
        assert np.array_equal(loaded.judge.robot.params, CellTruth.generate(seed=6).params)


@pytest.mark.parametrize("text,key", [
    (user_cell("probe_noise_um = 500.0"), r"simulation\.probe_noise_um = 500\.0.*0 … 100"),
    (user_cell("capture_angle_deg = 0.0"), r"simulation\.capture_angle_deg.*> 0 … 45"),
    (user_cell("lenght_sigma_um = 3.0"), r"unknown key 'lenght_sigma_um'"),
    (user_cell("step_joint = 3\nstep_offset_deg = 0.1"), r"simulation\].*prismatic"),
    ("[simulation]\nbacklash_um = -1.0\n", r"simulation\.backlash_um.*0 … 5000"),
    ("[simulation]\nsetup_yaw_sigma_deg = true\n", r"simulation\.setup_yaw_sigma_deg"),
    ("[robot]\nmodel = \"sr800\"\n[simulation]\nseed = 1\n", r"body is missing"),
])
def test_a_bad_simulation_is_a_config_error_naming_the_key(tmp_path, capsys, text, key):
    path = tmp_path / "cell.toml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=key):
        _loaded(CellRequest(config=str(path), simulated=True))
    assert main(["calibrate", str(path), "--simulated", "--db", str(tmp_path / "r.sqlite")]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err

