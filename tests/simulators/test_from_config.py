"""The simulated cell of a user's configuration (``simulators/from_config.py``): it is the cell the
files describe, its true errors have the ``[simulation]`` magnitudes, its defaults are the built-in
cell's exactly, and ``python -m simulators --config`` serves it over real transports."""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import signal
import subprocess
import sys
import tomllib
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest

from drivers.controller_map import WordOrder
from simulators import start_simulated_cell
from simulators.cell import CalibrationBody, CellTruth
from simulators.from_config import (
    SimulationPhysics,
    effective_seed,
    simulate_config,
    simulated_cell_for,
    toml_text,
)
from simulators.reference_cell import cell_config_text
from station.cell.config import schema as cfgschema
from station.cell.config.cell_config import parse_text
from station.core.kinematics.transforms import matrix_to_pose
from station.core.units import ARCSEC, DEG
from station.io.robot.files import load_robot
from station.ui.cli.main import main

ROOT = Path(__file__).resolve().parents[2]

# twelve corners of three 40 mm cubes, none of them the built-in cell's
POINTS = [("K1.a", [20.0, -250.0, 40.0, 0.0, 0.0, 20.0]), ("K1.b", [57.6, -236.3, 40.0, 0.0, 0.0, 110.0]),
          ("K1.c", [43.9, -198.7, 40.0, 0.0, 0.0, 200.0]), ("K1.d", [6.3, -212.4, 40.0, 0.0, 0.0, 290.0]),
          ("K2.a", [100.0, -20.0, 100.0, 0.0, 0.0, -15.0]), ("K2.b", [138.6, -30.4, 100.0, 0.0, 0.0, 75.0]),
          ("K2.c", [149.0, 8.3, 100.0, 0.0, 0.0, 165.0]), ("K2.d", [110.4, 18.6, 100.0, 0.0, 0.0, 255.0]),
          ("K3.a", [0.0, 220.0, 60.0, 0.0, 0.0, 35.0]), ("K3.b", [32.8, 242.9, 60.0, 0.0, 0.0, 125.0]),
          ("K3.c", [9.8, 275.7, 60.0, 0.0, 0.0, 215.0]), ("K3.d", [-22.9, 252.8, 60.0, 0.0, 0.0, 305.0])]
SETUP = [-430.0, 25.0, -160.0, 0.5, -0.3, 4.0]


def user_config(simulation: str = "", robot: str = "sr800") -> str:
    pts = "\n".join(f'  {{ id = "{i}", pose = {p} }},' for i, p in POINTS)
    return f"""[cell]
name = "a user's cell"
[robot]
model = "{robot}"
setup = {SETUP}
[limits]
joints = [[-120.0, 120.0], [-135.0, 135.0], [-190.0, -10.0], [-350.0, 350.0]]
[body]
cube_edge_mm = 40.0
points = [
{pts}
]
[devices]
probe_head = "/dev/ttyUSB7"
controller = "192.168.0.10:502"
word_order = "little"
probe_timeout_s = 0.5
[simulation]
{simulation}
"""


# ----------------------------------------------------------------- the defaults are the built-in cell
def test_schema_defaults_are_the_simulators_defaults():
    schema = cfgschema._Simulation.model_fields
    for f in fields(SimulationPhysics):
        assert schema[f.name].default == f.default, f.name


@pytest.mark.parametrize("seed", [1, 7])
def test_default_physics_reproduce_the_builtin_cell_bit_for_bit(seed):
    phys = SimulationPhysics()
    a, b = CellTruth.generate(seed=seed), CellTruth.generate(seed=seed, **phys.truth_kwargs())
    for name in ("params", "repeatability", "backlash", "encoder_resolution"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    pos, ang = phys.body_sigma()
    assert np.array_equal(CalibrationBody.generate(seed=seed).true,
                          CalibrationBody.generate(seed=seed, position_sigma_mm=pos, angle_sigma_rad=ang).true)
    # the [simulation] table at its defaults (what a file holding only a seed passes) starts the same cell
    defaults = {f.name: f.default for f in fields(SimulationPhysics)}
    with start_simulated_cell(seed=seed) as plain, start_simulated_cell(seed=seed, **defaults) as keyed:
        assert np.array_equal(plain.cell.truth.params, keyed.cell.truth.params)
        assert np.array_equal(plain.cell.body.true, keyed.cell.body.true)
        assert plain.cell.probe.noise_mm == keyed.cell.probe.noise_mm
        assert keyed.physics == {}
        text = cell_config_text(keyed, seed)
        assert text == cell_config_text(plain, seed).replace(f":{plain.controller_port}", f":{keyed.controller_port}") \
            .replace(plain.probe_port, keyed.probe_port)


def test_builtin_cell_with_other_physics_records_them():
    with start_simulated_cell(seed=2, probe_noise_um=2.0, repeatability_um=8.0) as servers:
        assert servers.cell.probe.noise_mm == pytest.approx(0.002)
        assert servers.cell.truth.repeatability[0] == pytest.approx(0.008 / 450.0)
        sim = tomllib.loads(cell_config_text(servers, 2))["simulation"]
        assert sim == {"seed": 2, "probe_noise_um": 2.0, "repeatability_um": 8.0}


def test_the_builtin_scara_with_joint_errors_takes_the_model_from_the_same_file(tmp_path):
    """Issue 30: ``[simulation] joint_errors = "scara"`` gives the built-in SCARA gears that err once
    per turn, recorded with the run as its physics; ``[identification]`` keys of the same file are
    merged into the built-in configuration (a key it has replaced, its comments kept); the
    six-axis kind is refused for it, and the SCARA kind for a six-axis arm."""
    from contextlib import ExitStack

    from station.cell.session.calibrate import CellRequest
    from station.errors import ConfigError
    from station.ui.simulated_cell import load_cell

    config = tmp_path / "cell.toml"
    config.write_text('[simulation]\njoint_errors = "scara"\njoint_errors_scale = 2.0\n\n'
                      '[identification]\nmodel = "cyclic"\nsigma_position_um = 7.5\n', encoding="utf-8")
    with ExitStack() as stack:
        loaded = load_cell(CellRequest(config=str(config), simulated=True, seed=3), stack)
        cfg, truth = loaded.cfg, loaded.judge.robot
        assert cfg.identification.terms == ("cyclic",) and cfg.identification.sigma_position_um == 7.5
        text = cfg.source_text
        assert text.count("sigma_position_um") == 1 and "# The simulated head" in text
        sim = tomllib.loads(text)["simulation"]
        assert sim["joint_errors"] == "scara" and sim["joint_errors_scale"] == 2.0
        amp = np.hypot(*np.array(truth.joint_errors.cyclic).T) / (np.pi / 180 / 3600)
        assert amp == pytest.approx([50.0, 40.0, 0.0, 30.0])  # 25″, 20″, 0, 15″ × 2
        q = np.zeros((1, 4))
        assert np.abs(truth.joint_delta(q)).max() > 0  # the commanded joints err
    config.write_text('[simulation]\njoint_errors = "six-axis"\n', encoding="utf-8")
    with ExitStack() as stack, pytest.raises(ConfigError, match='write "scara"'):
        load_cell(CellRequest(config=str(config), simulated=True), stack)
    from simulators.from_config import _joint_errors

    with pytest.raises(ConfigError, match="is for a SCARA"):
        _joint_errors({"joint_errors": "scara"}, load_robot("irb2600"), 1)


# ----------------------------------------------------------------- the cell the files describe
def test_the_simulated_cell_is_the_one_the_files_describe(tmp_path):
    shutil.copy(ROOT / "station/io/robots/sr800.toml", tmp_path / "my_robot.toml")
    path = tmp_path / "cell.toml"
    path.write_text(user_config("seed = 4", robot="my_robot.toml"))
    cfg = parse_text(path.read_text(), str(path))
    with simulate_config(cfg, source=path) as r:
        truth, body = r.servers.cell.truth, r.servers.cell.body
        assert r.seed == 4 == r.endpoints()["seed"]
        # the robot file with the configured set-up is the nominal of the true robot
        assert np.array_equal(truth.model.nominal, cfg.model.nominal)
        assert np.allclose(cfg.model.nominal[cfg.model.setup_slice()],
                           [*SETUP[:3], *np.deg2rad(SETUP[3:])])
        # the user's points, not the built-in body
        assert np.array_equal(body.nominal, cfg.body_points) and body.n_points == len(POINTS)
        # the configured word order and soft limits at the controller
        ctrl = r.servers.controller_server
        assert ctrl.word_order is WordOrder.LITTLE
        assert np.array_equal(ctrl.soft_limits, cfg.soft_limits)
        # the station's configuration: the user's, with only [devices] pointing at the simulators
        st = r.cfg
        assert (st.devices.probe_head, st.devices.controller_port) == (r.servers.probe_port, r.servers.controller_port)
        assert st.devices.word_order == "little" and st.devices.probe_timeout_s == 2.0
        assert st.point_ids == cfg.point_ids and st.model is cfg.model and st.simulated_seed == 4
        # its text reads back as the same cell from anywhere (the robot file's path made absolute)
        data = tomllib.loads(r.text)
        assert data["robot"]["model"] == str((tmp_path / "my_robot.toml").resolve())
        assert data["simulation"] == {"seed": 4}
        again = parse_text(r.text, "<elsewhere>")
        assert again.point_ids == cfg.point_ids
        assert np.array_equal(again.body_points, cfg.body_points)
        assert np.array_equal(again.model.nominal, cfg.model.nominal)
        assert again.devices == st.devices
        user = tomllib.loads(path.read_text())
        assert all(data[key] == user[key] for key in ("cell", "limits", "body"))


def _seven_probe_head_file(path: Path) -> None:
    from station.core.probe.geometry import ProbeHeadGeometry, default_probe_head
    from station.io.head_file import head_to_toml

    g = default_probe_head(cube_edge_mm=40.0)
    extra = np.array([[8.0, 25.0, 1.0]]) @ g.nominal_pose[:3, :3].T + g.nominal_pose[:3, 3]  # a 4th on top
    g7 = ProbeHeadGeometry(np.vstack([g.mount_points, extra]), np.vstack([g.directions, [[0.0, 0.0, -1.0]]]),
                           np.append(g.faces, 0), tip_radius_mm=1.0, stroke_mm=10.0, cube_edge_mm=40.0,
                           nominal_pose=g.nominal_pose, name="seven", reading_sigma_mm=0.0007)
    path.write_text(head_to_toml(g7, np.array([-4.6, -4.1, -128.5, 0.0, 0.0, 0.0])))


def test_the_configured_head_is_the_simulated_head(tmp_path, capsys):
    _seven_probe_head_file(tmp_path / "head7.toml")
    path = tmp_path / "cell.toml"
    path.write_text(user_config() + '[head]\nfile = "head7.toml"\n')
    cfg = parse_text(path.read_text(), str(path))
    assert cfg.head.n_probes == 7
    with simulate_config(cfg, source=path) as r:
        physics = r.servers.cell.probe
        assert physics.geometry is cfg.head and physics.noise_mm == pytest.approx(0.0007)
        assert tomllib.loads(r.text)["head"]["file"] == str((tmp_path / "head7.toml").resolve())
        out = tmp_path / "elsewhere"
        out.mkdir()
        (out / "sim.toml").write_text(r.text)
        assert main(["check", str(out / "sim.toml")]) == 0
        assert "7 probes wired" in capsys.readouterr().out


def test_seed_order_command_line_then_file_then_default():
    with_seed = parse_text(user_config("seed = 9"))
    without = parse_text(user_config())
    assert effective_seed(with_seed) == 9 and effective_seed(with_seed, 3) == 3
    assert effective_seed(without) == 1 and effective_seed(without, 0) == 0


def _errors(cfg, seeds):
    m = cfg.model
    n_t = m.n_params // 6
    e = np.array([simulated_cell_for(cfg, s).truth.errors.reshape(n_t, 6) for s in seeds])
    return e


def test_true_errors_have_the_configured_magnitudes():
    """Over 60 seeds the sample σ of each error class is the configured one (±15 %)."""
    sim = ("length_sigma_um = 100.0\nangle_sigma_arcsec = 40.0\nsetup_sigma_mm = 3.0\nsetup_yaw_sigma_deg = 0.5\n"
           "setup_tilt_sigma_deg = 0.1\nrepeatability_um = 9.0\nbacklash_um = 60.0\nprismatic_backlash_um = 30.0\n"
           "lever_mm = 300.0\nprobe_noise_um = 1.5\nbody_position_sigma_um = 10.0\nbody_angle_sigma_arcsec = 20.0\n"
           "capture_mm = 5.0\ncapture_angle_deg = 4.0")
    cfg = parse_text(user_config(sim))
    seeds = range(60)
    e = _errors(cfg, seeds)
    lengths, angles = e[:, 1:, :3].ravel(), e[:, 1:, 3:].ravel()
    assert np.std(lengths) == pytest.approx(0.100, rel=0.15) and abs(np.mean(lengths)) < 0.02
    assert np.std(angles) / ARCSEC == pytest.approx(40.0, rel=0.15)
    assert np.std(e[:, 0, :3]) == pytest.approx(3.0, rel=0.15)
    assert np.std(e[:, 0, 3:5]) / DEG == pytest.approx(0.1, rel=0.15)
    assert np.std(e[:, 0, 5]) / DEG == pytest.approx(0.5, rel=0.25)  # one sample per seed
    cell = simulated_cell_for(cfg, 0)
    rev = np.array([t == "revolute" for t in cfg.model.joint_types])
    assert np.allclose(cell.truth.repeatability, np.where(rev, 0.009 / 300.0, 0.009))
    assert np.allclose(cell.truth.backlash, np.where(rev, 0.060 / 300.0, 0.030))
    assert cell.probe.noise_mm == pytest.approx(0.0015)
    assert (cell.capture_mm, cell.capture_angle_rad) == pytest.approx((5.0, 4.0 * DEG))
    dev = np.array([_deviations(simulated_cell_for(cfg, s).body) for s in range(20)])
    assert np.std(dev[..., :3]) == pytest.approx(0.010, rel=0.15)
    assert np.std(dev[..., 3:]) / ARCSEC == pytest.approx(20.0, rel=0.15)
    # the seed decides: one seed, one cell; another seed, another
    assert np.array_equal(simulated_cell_for(cfg, 5).truth.params, simulated_cell_for(cfg, 5).truth.params)
    assert not np.array_equal(simulated_cell_for(cfg, 5).truth.params, simulated_cell_for(cfg, 6).truth.params)


def _deviations(body):
    return np.array([matrix_to_pose(np.linalg.inv(n) @ t) for n, t in zip(body.nominal, body.true)])


def test_a_point_s_stated_sigma_takes_precedence():
    """A σ the CMM report states for a point is its true deviation's; where none is stated (0),
    the [simulation] default (here 0: exact) applies."""
    pid, pose = POINTS[3]
    text = user_config("body_position_sigma_um = 0.0\nbody_angle_sigma_arcsec = 0.0").replace(
        f'{{ id = "{pid}", pose = {pose} }}', f'{{ id = "{pid}", pose = {pose}, sigma_position_um = 4.0 }}')
    cfg = parse_text(text)
    assert cfg.body_sigma[3, 0] == pytest.approx(0.004) and np.count_nonzero(cfg.body_sigma) == 1
    dev = _deviations(simulated_cell_for(cfg, 2).body)
    assert np.allclose(np.delete(dev, 3, axis=0), 0.0, atol=1e-12)
    assert 0 < np.linalg.norm(dev[3, :3]) < 0.05 and np.allclose(dev[3, 3:], 0.0, atol=1e-12)
    # where none is stated, every point gets the [simulation] σ (default 2 µm, 3″)
    dev = _deviations(simulated_cell_for(parse_text(user_config()), 2).body)
    assert np.all(np.linalg.norm(dev[:, :3], axis=1) > 1e-4) and np.all(np.linalg.norm(dev[:, 3:], axis=1) > 0)


def test_probe_noise_is_the_head_s_stated_sigma_unless_simulation_sets_it():
    cfg = parse_text(user_config())
    head = dataclasses.replace(cfg.head, reading_sigma_mm=0.0012)
    assert simulated_cell_for(dataclasses.replace(cfg, head=head), 1).probe.noise_mm == pytest.approx(0.0012)
    cfg = parse_text(user_config("probe_noise_um = 0.8"))
    assert simulated_cell_for(dataclasses.replace(cfg, head=head), 1).probe.noise_mm == pytest.approx(0.0008)


def test_from_frames_refuses_bad_input():
    with pytest.raises(ValueError, match="sigma"):
        CalibrationBody.from_frames(np.tile(np.eye(4), (2, 1, 1)), 40.0, [[0.001, -1.0]], seed=0)
    with pytest.raises(ValueError, match="nominal"):
        CalibrationBody.from_frames(np.eye(4), 40.0, [0.001, 0.0], seed=0)


def test_another_robot_file_is_simulated_as_given(tmp_path):
    """A robot file of other dimensions: the simulated robot's nominal is that file's."""
    text = (ROOT / "station/io/robots/sr800.toml").read_text().replace("x = 445.0", "x = 425.0", 1)
    assert text != (ROOT / "station/io/robots/sr800.toml").read_text()
    (tmp_path / "other.toml").write_text(text)
    path = tmp_path / "cell.toml"
    path.write_text(user_config(robot="other.toml"))
    cfg = parse_text(path.read_text(), str(path))
    cell = simulated_cell_for(cfg, 1)
    assert not np.allclose(cell.truth.model.nominal, load_robot("sr800").with_setup(
        cfg.model.nominal[cfg.model.setup_slice()]).nominal)
    assert np.array_equal(cell.truth.model.nominal, cfg.model.nominal)


def test_toml_text_reads_back_as_the_same_data():
    for p in (ROOT / "station/io/robots/sr800.toml",):
        data = tomllib.loads(p.read_text())
        assert tomllib.loads(toml_text(data)) == data
    data = {"a b": 1, "t": {"s": 'q"\\\nµ', "inner": {"x": [1, 2.5]}, "pts": [{"id": "A", "v": [1.0]}]},
            "tool": [{"name": "g", "tcp": [0.0, 0.0, 200.0]}, {"name": "h", "on": True}], "empty": []}
    assert tomllib.loads(toml_text(data)) == data


# ----------------------------------------------------------------- python -m simulators --config
def test_python_m_simulators_serves_the_user_cell_and_station_check_passes(tmp_path, capsys):
    path, out = tmp_path / "cell.toml", tmp_path / "simulated.toml"
    path.write_text(user_config("seed = 6"))
    p = subprocess.Popen([sys.executable, "-m", "simulators", "--config", str(path), "--write-config", str(out)],
                         cwd=ROOT, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                         env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        line = p.stdout.readline()  # readiness: printed once both endpoints accept traffic
        assert line, "simulator did not start"
        ready = json.loads(line)
        assert ready["seed"] == 6 and ready["config"] == str(out)
        written = tomllib.loads(out.read_text())
        assert written["devices"]["controller"] == ready["controller"]
        assert written["devices"]["probe_head"] == ready["probe_head"]
        assert written["devices"]["word_order"] == "little"
        assert [q["id"] for q in written["body"]["points"]] == [i for i, _ in POINTS]
        assert main(["check", str(out)]) == 0
        report = capsys.readouterr().out
        assert "12 measuring points" in report and "FAILED" not in report and "warning" not in report
    finally:
        p.send_signal(signal.SIGTERM)
        assert p.wait(timeout=20) == 0


def test_python_m_simulators_refuses_a_bad_config_with_exit_2(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(user_config("length_sigma_um = -3.0"))
    r = subprocess.run([sys.executable, "-m", "simulators", "--config", str(bad)], cwd=ROOT,
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "simulation.length_sigma_um" in r.stderr and "Traceback" not in r.stderr
    r = subprocess.run([sys.executable, "-m", "simulators", "--config", str(bad), "--word-order", "big"], cwd=ROOT,
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "[devices]" in r.stderr
