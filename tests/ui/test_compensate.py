"""``station compensate``: the round trip through the controller's nominal IK lands the identified
robot on the wanted poses; failed rows are reported by row and the others still written."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

from station.core.kinematics.forward import forward
from station.core.kinematics.ik import ArmConfig, configuration, solve_ik
from station.core.kinematics.model import robot_to_toml
from station.core.kinematics.poses import spread_joints
from station.core.kinematics.transforms import matrix_to_pose, pose_error, pose_to_matrix
from station.core.units import ARCSEC
from station.io.robot.files import load_robot
from station.ui.cli.main import main

HEADER = "x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg"


def _identified(model, seed):
    """Nominal + errors of several 0.1 mm and several 0.01° in every parameter."""
    rng = np.random.default_rng(seed)
    p = model.nominal + rng.standard_normal(model.n_params) * np.where(model.is_angle(), math.radians(0.03), 0.3)
    p[:6] = [800.0, -200.0, 30.0, 0.01, -0.02, 0.4]  # a set-up R (measurement frame)
    return p


def _write_targets(path: Path, poses, extra_header="", extra=None, tail=()):
    lines = ["# wanted poses, robot base frame", HEADER + extra_header]
    for i, p in enumerate(poses):
        vals = [f"{v:.9f}" for v in p[:3]] + [f"{math.degrees(v):.12f}" for v in p[3:]]
        if extra is not None:
            vals += extra[i]
        lines.append(",".join(vals))
    lines += list(tail)
    path.write_text("\n".join(lines) + "\n")


def _read_out(path: Path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def _joints(model, n, seed):
    q = spread_joints(model, n, np.random.default_rng(seed))
    if model.n_joints == 6:
        q[:, 4] = np.sign(q[:, 4]) * np.maximum(np.abs(q[:, 4]), 0.3)  # away from the wrist singularity
    return q


@pytest.mark.parametrize("robot", ["irb2600", "sr800"])
def test_round_trip_lands_the_identified_robot_on_the_wanted_poses(tmp_path, robot, capsys):
    model = load_robot(robot)
    ident = _identified(model, 1)
    (tmp_path / "model.toml").write_text(robot_to_toml(model, ident, angle_unit="rad"))
    q = _joints(model, 25, 2)
    P = forward(model, q, ident, setup=False)  # the poses the user wants
    _write_targets(tmp_path / "t.csv", matrix_to_pose(P))
    rc = main(["compensate", str(tmp_path / "model.toml"), str(tmp_path / "t.csv"), "-o", str(tmp_path / "o.csv")])
    assert rc == 0, capsys.readouterr().err
    rows = _read_out(tmp_path / "o.csv")
    assert [r["row"] for r in rows] == [str(i + 1) for i in range(25)] and all(r["status"] == "ok" for r in rows)
    C = pose_to_matrix(np.array([[float(r["x_mm"]), float(r["y_mm"]), float(r["z_mm"]),
                                  math.radians(float(r["roll_deg"])), math.radians(float(r["pitch_deg"])),
                                  math.radians(float(r["yaw_deg"]))] for r in rows]))
    cfg = [ArmConfig(*(int(r[k] or 0) for k in ("shoulder", "elbow", "wrist"))) for r in rows]
    # the controller: nominal IK of the command in the given configuration; the robot: identified FK
    ctl = solve_ik(model, C, model.nominal, configuration=cfg)
    assert np.all(ctl.has_joints)
    e = pose_error(forward(model, ctl.joints, ident, setup=False), P)
    assert np.linalg.norm(e[:, :3], axis=1).max() < 1e-3  # ≤ 1 µm
    # a SCARA is commanded in x, y, z, yaw; its roll and pitch follow from the elbow it takes
    ang = np.abs(e[:, 5]) if model.is_scara else np.linalg.norm(e[:, 3:], axis=1)
    assert ang.max() < 0.1 * ARCSEC
    # and the commands are real corrections: uncompensated, the robot would miss by ~mm
    assert np.linalg.norm(C[:, :3, 3] - P[:, :3, 3], axis=1).max() > 0.1


def test_unreachable_rows_are_reported_and_the_others_written(tmp_path, capsys):
    model = load_robot("irb2600")
    ident = _identified(model, 3)
    (tmp_path / "model.toml").write_text(robot_to_toml(model, ident, angle_unit="rad"))
    P = matrix_to_pose(forward(model, _joints(model, 4, 4), ident, setup=False))
    P = np.insert(P, 2, [4000.0, 0.0, 500.0, 0.0, 0.0, 0.0], axis=0)  # row 3: beyond the reach
    _write_targets(tmp_path / "t.csv", P)
    rc = main(["compensate", str(tmp_path / "model.toml"), str(tmp_path / "t.csv"), "-o", str(tmp_path / "o.csv"),
               "--json"])
    out = capsys.readouterr()
    assert rc == 4
    assert "row 3 (line 5)" in out.err and "out of reach" in out.err
    summary = json.loads(out.out)
    assert summary["compensated"] == 4 and [f["row"] for f in summary["failed"]] == [3]
    assert summary["failed"][0]["status"] == "unreachable"
    rows = _read_out(tmp_path / "o.csv")
    assert [r["status"] for r in rows] == ["ok", "ok", "unreachable", "ok", "ok"]
    assert rows[2]["x_mm"] == "" and "out of reach" in rows[2]["reason"]
    assert all(rows[i]["x_mm"] for i in (0, 1, 3, 4))


def test_configuration_columns_and_setup_frame(tmp_path, capsys):
    model = load_robot("irb2600")
    ident = _identified(model, 5)
    (tmp_path / "model.toml").write_text(robot_to_toml(model, ident, angle_unit="rad"))
    q = _joints(model, 6, 6)
    P_world = forward(model, q, ident, setup=True)  # given in the measurement frame
    want = [ArmConfig.from_array(c) for c in solve_ik(model, forward(model, q, ident, setup=False), ident).config]
    extra = [[str(c.shoulder), str(c.elbow), ""] for c in want]
    _write_targets(tmp_path / "t.csv", matrix_to_pose(P_world), ",shoulder,elbow,wrist", extra)
    rc = main(["compensate", str(tmp_path / "model.toml"), str(tmp_path / "t.csv"), "-o", str(tmp_path / "o.csv"),
               "--setup"])
    assert rc == 0, capsys.readouterr().err
    rows = _read_out(tmp_path / "o.csv")
    for r, c in zip(rows, want):
        assert (int(r["shoulder"]), int(r["elbow"])) == (c.shoulder, c.elbow)
        assert float(r["residual_um"]) < 1e-3
    qo = np.radians([[float(r[f"q{j}_deg"]) for j in range(1, 7)] for r in rows])
    e = pose_error(forward(model, qo, ident, setup=True), P_world)
    assert np.abs(e[:, :3]).max() < 1e-5


def test_joint_offsets_reported_beside_the_full_model(tmp_path, capsys):
    model = load_robot("irb2600")
    ident = _identified(model, 7)
    (tmp_path / "model.toml").write_text(robot_to_toml(model, ident, angle_unit="rad"))
    _write_targets(tmp_path / "t.csv", matrix_to_pose(forward(model, _joints(model, 10, 8), ident, setup=False)))
    rc = main(["compensate", str(tmp_path / "model.toml"), str(tmp_path / "t.csv"), "-o", str(tmp_path / "o.csv"),
               "--joint-offsets", "--json"])
    assert rc == 0
    jo = json.loads(capsys.readouterr().out)["joint_offsets"]
    assert [o["joint"] for o in jo["offsets"]] == ["A1", "A2", "A3", "A4", "A5", "A6"]
    acc = jo["accuracy_on_targets"]
    assert acc["targets"] == 10
    assert acc["full_model"]["rms_position_um"] < 1e-3 < acc["joint_offsets"]["rms_position_um"]


@pytest.mark.parametrize("content, where", [
    (HEADER + "\n1,2,abc,0,0,0\n", "line 2, column 3 (z_mm)"),
    (HEADER + ",colour\n1,2,3,0,0,0,red\n", "line 1, column 7: unknown column 'colour'"),
    ("x_mm,y_mm,z_mm,roll_deg,pitch_deg\n1,2,3,0,0\n", "missing columns yaw_deg"),
    (HEADER + "\n1,2,3,0,0,0\n1,2,3,0,0\n", "line 3: 5 fields"),
    (HEADER + ",elbow\n1,2,3,0,0,0,2\n", "line 2, column 7 (elbow)"),
    (HEADER + "\n1,2,nan,0,0,0\n", "not a finite number"),
    ("# only a comment\n" + HEADER + "\n", "no targets"),
])
def test_bad_target_files_are_config_errors_with_line_and_column(tmp_path, capsys, content, where):
    (tmp_path / "t.csv").write_text(content)
    rc = main(["compensate", "irb2600", str(tmp_path / "t.csv"), "-o", str(tmp_path / "o.csv")])
    assert rc == 2
    assert where in capsys.readouterr().err
    assert not (tmp_path / "o.csv").exists()


def test_a_model_without_a_builtin_nominal_needs_robot(tmp_path, capsys):
    model = load_robot("sr800")
    text = robot_to_toml(model, _identified(model, 9), angle_unit="rad").replace('name = "sr800"', 'name = "cell7"')
    (tmp_path / "m.toml").write_text(text)
    _write_targets(tmp_path / "t.csv", [[600.0, 100.0, 400.0, 0.0, 0.0, 0.3]])
    args = ["compensate", str(tmp_path / "m.toml"), str(tmp_path / "t.csv"), "-o", str(tmp_path / "o.csv")]
    assert main(args) == 2 and "--robot" in capsys.readouterr().err
    assert main(args + ["--robot", "sr800"]) == 0
    assert main(["compensate", str(tmp_path / "m.toml"), str(tmp_path / "t.csv"), "-o", str(tmp_path / "o.csv"),
                 "--robot", "irb2600"]) == 2


def test_near_singular_rows_fail_unless_allowed(tmp_path, capsys):
    model = load_robot("irb2600")
    ident = _identified(model, 11)
    (tmp_path / "model.toml").write_text(robot_to_toml(model, ident, angle_unit="rad"))
    q = np.array([[0.2, 0.3, -0.4, 0.3, math.radians(0.2), 0.1], [0.1, 0.2, -0.3, 0.5, 0.8, 0.2]])
    P = forward(model, q, ident, setup=False)
    conf = configuration(model, q, ident)  # row 1's wrist is nearly straight in this configuration
    extra = [[str(c) for c in row] for row in conf]
    _write_targets(tmp_path / "t.csv", matrix_to_pose(P), ",shoulder,elbow,wrist", extra)
    args = ["compensate", str(tmp_path / "model.toml"), str(tmp_path / "t.csv"), "-o", str(tmp_path / "o.csv")]
    assert main(args) == 4
    assert "row 1 (line 3): near a singularity" in capsys.readouterr().err
    assert [r["status"] for r in _read_out(tmp_path / "o.csv")] == ["near_singularity", "ok"]
    assert main(args + ["--allow-singular"]) == 0
    rows = _read_out(tmp_path / "o.csv")
    assert [r["status"] for r in rows] == ["ok", "ok"] and float(rows[0]["residual_um"]) < 1e-3
