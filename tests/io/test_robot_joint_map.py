"""Robot files that map the controller's joints onto the model's: sign, zero offset, coupling
(``q_model = sign·q_controller + offset + k·q_other``), in TOML and in DH tables; data read
through the map identify back the robot that made them, and compensated joints go back out
through its inverse."""

from __future__ import annotations

import csv
import json
import math
from importlib import resources
from pathlib import Path

import numpy as np
import pytest

from station.core.kinematics.forward import forward
from station.core.kinematics.joint_map import JointMap
from station.core.kinematics.poses import spread_joints
from station.core.kinematics.transforms import matrix_to_pose
from station.core.measurement.measurements import synthetic_set
from station.errors import ConfigError
from station.io.datafile import write_csv
from station.io.robot.files import load_mapped_robot, load_robot
from station.ui.cli.main import main

JOINTS = ["q1 [deg]", "q2 [deg]", "q3 [mm]", "q4 [deg]"]
POSE = ["x [mm]", "y [mm]", "z [mm]", "roll [deg]", "pitch [deg]", "yaw [deg]"]

# A2 turns the other way, A1's zero is 30° off, A4 is counted against A2 (J3-against-J2 style)
# and the quill A3 moves with A4 by 0.05 mm/deg (a SCARA's ball-screw spline): every form at once.
MAP_TOML = """
[joint_map.A1]
offset = 30.0
[joint_map.A2]
sign = -1
[joint_map.A3]
coupled_to = "A4"
k = 0.05
[joint_map.A4]
offset = -12.5
coupled_to = "A2"
k = -1.0
"""


def _mapped_file(tmp_path: Path, extra: str = MAP_TOML) -> Path:
    text = resources.files("station.io.robots").joinpath("sr800.toml").read_text()
    p = tmp_path / "mapped.toml"
    p.write_text(text.replace('name = "sr800"', 'name = "mapped_scara"', 1) + extra, encoding="utf-8")
    return p


def run(capsys, *argv):
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def _controller_columns(q: np.ndarray) -> np.ndarray:
    out = np.array(q, dtype=float)
    out[:, [0, 1, 3]] = np.degrees(out[:, [0, 1, 3]])
    return out


# --- the map itself ------------------------------------------------------------------------------

def test_the_map_and_its_inverse_round_trip():
    m = JointMap((1.0, -1.0, 1.0), (0.3, 0.0, -0.1), (None, None, 1), (0.0, 0.0, -1.0), ("A1", "A2", "A3"))
    q = np.random.default_rng(0).uniform(-2, 2, (50, 3))
    qm = m.to_model(q)
    np.testing.assert_allclose(qm[:, 0], q[:, 0] + 0.3)
    np.testing.assert_allclose(qm[:, 1], -q[:, 1])
    np.testing.assert_allclose(qm[:, 2], q[:, 2] - 0.1 - q[:, 1])
    np.testing.assert_allclose(m.to_controller(qm), q, atol=1e-13)
    np.testing.assert_allclose(m.to_controller(qm[0]), q[0], atol=1e-13)
    # a joint-zero change of the model is the controller's through the linear part only
    np.testing.assert_allclose(m.delta_to_controller(np.array([0.1, 0.2, 0.0])), [0.1, -0.2, -0.2], atol=1e-15)
    assert JointMap.identity(("A1", "A2")).is_identity and not m.is_identity
    assert m.describe() == ["A1 = +q1 + 0.3", "A2 = -q2", "A3 = +q3 - 0.1 - 1·q2"]


@pytest.mark.parametrize("args, pattern", [
    (((2.0, 1.0), (0.0, 0.0), (None, None), (0.0, 0.0)), "A1: sign must be 1 or -1"),
    (((1.0, 1.0), (0.0, 0.0), (1, 0), (1.0, 1.0)), r"loop \(A1 -> A2 -> A1\)"),
    (((1.0, 1.0), (0.0, 0.0), (0, None), (1.0, 0.0)), "A1: it can be coupled only to another"),
    (((1.0, 1.0), (math.nan, 0.0), (None, None), (0.0, 0.0)), "A1: offset must be a finite number"),
])
def test_a_bad_map_is_refused(args, pattern):
    with pytest.raises(ConfigError, match=pattern):
        JointMap(*args, names=("A1", "A2"))


# --- TOML robot files ------------------------------------------------------------------------------

def test_a_toml_joint_map_is_read_in_the_files_units(tmp_path):
    model, m = load_mapped_robot(_mapped_file(tmp_path))
    assert model.name == "mapped_scara" and m.names == ("A1", "A2", "A3", "A4")
    assert m.sign == (1.0, -1.0, 1.0, 1.0)
    np.testing.assert_allclose(m.offset, [math.radians(30), 0, 0, math.radians(-12.5)])
    assert m.other == (None, None, 3, 1)
    np.testing.assert_allclose(m.k, [0, 0, 0.05 * 180 / math.pi, -1.0])  # mm/deg → mm/rad


def test_the_cell_refuses_a_mapped_robot_file(tmp_path):
    """The cell commands and reads joints as the model counts them: load_robot (what the cell
    configuration reads) refuses a map rather than apply none."""
    with pytest.raises(ConfigError, match=r"maps the controller's joints onto the model's \(A1 = \+q1 \+ 0\.5"):
        load_robot(_mapped_file(tmp_path))
    assert load_robot("sr800").n_joints == 4


def test_a_cell_configuration_with_a_mapped_robot_exits_2_at_config_check(capsys, tmp_path):
    from station.cell.config.cell_config import load_config
    from station.cell.config.template import TEMPLATE

    _mapped_file(tmp_path)
    cell = tmp_path / "cell.toml"
    assert 'model = "sr800"' in TEMPLATE
    cell.write_text(TEMPLATE.replace('model = "sr800"', 'model = "mapped.toml"', 1))
    with pytest.raises(ConfigError, match="for a cell, give a robot file without \\[joint_map\\]"):
        load_config(cell)
    rc, _, err = run(capsys, "plan", cell)
    assert rc == 2 and "maps the controller's joints onto the model's" in err, err


@pytest.mark.parametrize("extra, pattern", [
    ("[joint_map.A9]\nsign = -1\n", r"\[joint_map.A9\]: no joint transform 'A9'; the joints are A1, A2, A3, A4"),
    ("[joint_map.A2]\nsign = 2\n", r"\[joint_map.A2\].sign must be 1 or -1"),
    ("[joint_map.A2]\nsing = -1\n", r"\[joint_map.A2\]: unknown key 'sing' \(did you mean 'sign'\?\); allowed: sign, offset, coupled_to, k"),
    ("[joint_map.A2]\ncoupled_to = \"A2\"\nk = 1\n", r"coupled_to = 'A2': give another joint transform"),
    ("[joint_map.A2]\nk = 1\n", r"A2: k is given without the joint it couples to"),
    ("[joint_map.A3]\ncoupled_to = \"A2\"\n", r"A3: coupled to A2, but no factor k"),
    ("[joint_map.A2]\ncoupled_to = \"A3\"\nk = 1\n[joint_map.A3]\ncoupled_to = \"A2\"\nk = 1\n", "loop"),
    ("[joint_map.A2]\noffset = \"ten\"\n", r"\[joint_map.A2\].offset must be a finite number"),
])
def test_a_bad_toml_map_exits_2_saying_what_to_change(capsys, tmp_path, extra, pattern):
    import re

    rc, _, err = run(capsys, "analyze", "--robot", _mapped_file(tmp_path, extra), "--poses", "5")
    assert rc == 2, err
    assert re.search(pattern, err), err
    assert "internal error" not in err


@pytest.fixture(scope="module")
def mapped_run(tmp_path_factory):
    """Poses of a perturbed robot at controller joints: calibration and held-out files, and the
    model ``station identify`` writes from the first."""
    d = tmp_path_factory.mktemp("mapped")
    robot = _mapped_file(d)
    model, m = load_mapped_robot(robot)
    rng = np.random.default_rng(7)
    truth = model.nominal + rng.standard_normal(model.n_params) * np.where(model.is_angle(), 5e-4, 0.1)
    truth[:6] = [150.0, -80.0, 12.0, 0.0, 0.0, 0.3]
    sig = np.array([0.005] * 3 + [math.radians(5 / 3600)] * 3)
    files = {}
    for name, n in (("cal", 40), ("held", 20)):
        q_model = spread_joints(model, n, rng)
        data = synthetic_set(model, "pose", q_model, truth, sigma=sig, rng=rng)
        pose = matrix_to_pose(data.measured)
        pose[:, 3:] = np.degrees(pose[:, 3:])
        f = d / f"{name}.csv"
        write_csv(f, JOINTS + POSE, np.column_stack([_controller_columns(m.to_controller(q_model)), pose]))
        files[name] = (f, q_model)
    out = d / "identified.toml"
    rc = main(["identify", str(files["cal"][0]), "--robot", str(robot), "-o", str(out),
               "--sigma-position", "5", "--sigma-angle", "5", "--json"])
    assert rc == 0
    return robot, model, m, truth, files, out


def test_mapped_controller_joints_identify_back_the_robot(capsys, mapped_run):
    robot, model, m, truth, files, out = mapped_run
    identified, m_out = load_mapped_robot(out)
    assert m_out.close_to(m)  # the written model carries the map (in rad) for validate, predict, compensate
    q_held = files["held"][1]
    err = forward(identified, q_held)[:, :3, 3] - forward(model, q_held, truth)[:, :3, 3]
    assert np.sqrt(np.mean(np.sum(err**2, axis=1))) < 0.015  # mm: within the 5 µm noise's reach
    rc, text, err_text = run(capsys, "validate", out, files["held"][0], "--json")
    assert rc == 0, err_text
    assert json.loads(text)["model_errors"]["rms_position_um"] < 20.0


def test_without_the_map_the_same_data_do_not_fit(capsys, mapped_run):
    _, _, _, _, files, _ = mapped_run
    rc, text, err = run(capsys, "identify", files["cal"][0], "--robot", "sr800", "--json")
    assert rc != 1, err
    assert rc != 0 or json.loads(text)["rms_position_residual_um"] > 1000.0


def test_predict_reads_controller_joints_through_the_map(capsys, mapped_run, tmp_path):
    _, model, m, truth, files, out = mapped_run
    q_model = files["held"][1]
    j = tmp_path / "joints.csv"
    write_csv(j, JOINTS, _controller_columns(m.to_controller(q_model)))
    rc, text, err = run(capsys, "predict", out, j, "--json")
    assert rc == 0, err
    got = np.array(json.loads(text)["poses_mm_rad"])
    np.testing.assert_allclose(got[:, :3], forward(model, q_model, truth)[:, :3, 3], atol=0.03)


def test_compensated_joints_go_back_out_as_the_controller_counts_them(capsys, mapped_run, tmp_path):
    robot, model, m, _, files, out = mapped_run
    identified, _ = load_mapped_robot(out)
    targets = matrix_to_pose(forward(model, files["held"][1][:8], setup=False))
    t = tmp_path / "targets.csv"
    write_csv(t, ["x_mm", "y_mm", "z_mm", "roll_deg", "pitch_deg", "yaw_deg"],
              np.column_stack([targets[:, :3], np.degrees(targets[:, 3:])]))
    o = tmp_path / "compensated.csv"
    rc, _, err = run(capsys, "compensate", out, t, "--robot", robot, "-o", o)
    assert rc == 0, err
    with open(o, newline="") as f:
        rows = list(csv.DictReader(f))
    q_c = np.array([[float(r["q1_deg"]), float(r["q2_deg"]), float(r["q3_mm"]), float(r["q4_deg"])] for r in rows])
    q_c[:, [0, 1, 3]] = np.radians(q_c[:, [0, 1, 3]])
    reached = forward(identified, m.to_model(q_c), setup=False)[:, :3, 3]
    np.testing.assert_allclose(reached, targets[:, :3], atol=1e-3)  # the identified robot lands on the target
    # and the same joints read without the map would not
    assert np.max(np.abs(forward(identified, q_c, setup=False)[:, :3, 3] - targets[:, :3])) > 10.0


def test_a_nominal_with_another_map_is_refused_by_compensate(capsys, mapped_run, tmp_path):
    _, _, _, _, files, out = mapped_run
    t = tmp_path / "targets.csv"
    t.write_text("x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg\n500,100,400,0,0,0\n")
    other = _mapped_file(tmp_path, "[joint_map.A2]\nsign = -1\n")
    rc, _, err = run(capsys, "compensate", out, t, "--robot", other, "-o", tmp_path / "c.csv")
    assert rc == 2 and "is not the model's" in err, err


# --- DH tables ----------------------------------------------------------------------------------------

DH = """# a three-axis arm; J3 counted against J2, J2 the other way round, J1's zero 90° off
type,theta [deg],d [mm],a [mm],alpha [deg],lower [deg|mm],upper [deg|mm],sign,offset [deg|mm],coupled_to,k
fixed,0,100,0,0,,,,,,
revolute,0,300,50,90,-170,170,,90,,
revolute,0,0,400,0,-90,150,-1,,,
revolute,0,0,350,0,-150,150,,,J2,-1
"""


def test_a_dh_table_maps_joints_by_its_columns(capsys, tmp_path):
    p = tmp_path / "arm.dh.csv"
    p.write_text(DH)
    model, m = load_mapped_robot(p)
    assert model.n_joints == 3
    assert m.sign == (1.0, -1.0, 1.0) and m.other == (None, None, 1)
    np.testing.assert_allclose(m.offset, [math.pi / 2, 0, 0])
    np.testing.assert_allclose(m.k, [0, 0, -1.0])
    q_c = np.radians([[10.0, 20.0, 30.0], [-40.0, 5.0, 60.0]])
    j = tmp_path / "joints.csv"
    write_csv(j, ["q1 [rad]", "q2 [rad]", "q3 [rad]"], q_c)
    rc, text, err = run(capsys, "predict", p, j, "--json")
    assert rc == 0, err
    want = matrix_to_pose(forward(model, m.to_model(q_c)))
    np.testing.assert_allclose(np.array(json.loads(text)["poses_mm_rad"]), want, atol=1e-9)
    assert np.max(np.abs(want[:, :3] - forward(model, q_c)[:, :3, 3])) > 100.0  # the map moved the pose


@pytest.mark.parametrize("row, pattern", [
    ("fixed,0,10,0,0,,,-1,,,", r"line 3: a fixed row has no joint; leave sign empty"),
    ("revolute,0,0,350,0,-150,150,,,J7,-1", r"coupled_to = 'J7': give the number of another joint row, 1 … 2"),
    ("revolute,0,0,350,0,-150,150,,,2,-1", r"coupled_to = '2': give the number of another joint row"),
    ("revolute,0,0,350,0,-150,150,2,,,", r"A2: sign must be 1 or -1"),
    ("revolute,0,0,350,0,-150,150,,,,0.5", r"A2: k is given without the joint it couples to"),
    ("revolute,0,0,350,0,-150,150,,x,,", r"line 3: offset must be a number, got 'x'"),
])
def test_a_bad_dh_map_column_exits_2(capsys, tmp_path, row, pattern):
    import re

    head = DH.splitlines()[1]
    p = tmp_path / "bad.dh.csv"
    p.write_text(f"{head}\nrevolute,0,300,50,90,-170,170,,,,\n{row}\n")
    rc, _, err = run(capsys, "analyze", "--robot", p, "--poses", "5")
    assert rc == 2, err
    assert re.search(pattern, err), err


def test_export_model_keeps_the_map_in_toml_and_says_so_for_dh(capsys, mapped_run, tmp_path):
    _, _, m, _, _, out = mapped_run
    t = tmp_path / "again.toml"
    rc, _, err = run(capsys, "export-model", out, "--format", "toml", "-o", t)
    assert rc == 0, err
    assert load_mapped_robot(t)[1].close_to(m)
    rc, text, err = run(capsys, "export-model", out, "--format", "mdh", "-o", tmp_path / "again.mdh.csv")
    assert rc == 0, err
    assert "the joint map (A1 = +q1 + 0.523598776" in text and "is not written in MDH" in text
