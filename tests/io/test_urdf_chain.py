"""A branched URDF: ``--base LINK`` / ``--tip LINK`` choose the chain; without them it is refused,
naming the tips it could use; it is never flattened into one chain."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from station.core.kinematics.forward import forward
from station.core.kinematics.transforms import matrix_to_pose
from station.io.datafile import write_csv
from station.io.robot.files import load_mapped_robot
from station.ui.cli.main import main

# name, type, parent, child, xyz [m], rpy [rad], axis, limits [rad | m]
JOINTS = [
    ("j1", "revolute", "base", "l1", (0, 0, 0.4), (0, 0, 0), (0, 0, 1), (-2.5, 2.5)),
    ("j2", "revolute", "l1", "l2", (0.05, 0, 0.1), (0.1, 0, 0), (0, 1, 0), (-1.5, 1.6)),
    ("j3", "revolute", "l2", "l3", (0.3, 0, 0), (0, 0, 0.2), (0, 1, 0), (-2.0, 2.1)),
    ("j4", "fixed", "l3", "flange", (0.25, 0, 0), (0, math.pi / 2, 0), None, None),
    ("j5", "prismatic", "l2", "camera_slide", (0.1, 0.05, 0), (0, 0, 0), (1, 0, 0), (0.0, 0.08)),
    ("j6", "fixed", "camera_slide", "camera", (0, 0, 0.02), (0, 0, 0), None, None),
]
LINKS = ("base", "l1", "l2", "l3", "flange", "camera_slide", "camera")


def _urdf(tmp_path: Path) -> Path:
    body = "".join(f'<link name="{n}"/>' for n in LINKS)
    for name, kind, parent, child, xyz, rpy, axis, lim in JOINTS:
        body += (f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
                 f'<origin xyz="{" ".join(map(str, xyz))}" rpy="{" ".join(map(str, rpy))}"/>')
        if axis is not None:
            body += f'<axis xyz="{" ".join(map(str, axis))}"/><limit lower="{lim[0]}" upper="{lim[1]}"/>'
        body += "</joint>"
    p = tmp_path / "branched.urdf"
    p.write_text(f'<?xml version="1.0"?><robot name="branched">{body}</robot>', encoding="utf-8")
    return p


def _rot(axis, angle: float) -> np.ndarray:
    a = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def _reference(names: list[str], q: np.ndarray) -> np.ndarray:
    """URDF semantics, written out: each joint's origin (mm), then its motion; ``q`` [rad | mm]."""
    T = np.eye(4)
    qi = iter(q)
    by_name = {j[0]: j for j in JOINTS}
    for n in names:
        _, kind, _, _, xyz, rpy, axis, _ = by_name[n]
        origin = np.eye(4)
        origin[:3, :3] = _rot((0, 0, 1), rpy[2]) @ _rot((0, 1, 0), rpy[1]) @ _rot((1, 0, 0), rpy[0])
        origin[:3, 3] = np.array(xyz) * 1000.0
        M = np.eye(4)
        if kind == "revolute":
            M[:3, :3] = _rot(axis, next(qi))
        elif kind == "prismatic":
            M[:3, 3] = np.asarray(axis, dtype=float) * next(qi)
        T = T @ origin @ M
    return T


def run(capsys, *argv):
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def test_a_branched_urdf_without_a_tip_is_refused_naming_the_tips(capsys, tmp_path):
    rc, _, err = run(capsys, "analyze", "--robot", _urdf(tmp_path), "--poses", "5")
    assert rc == 2, err
    assert "branches at link 'l2' into joints 'j3', 'j5'" in err
    assert "choose it with --tip LINK, one of 'flange', 'camera'" in err
    assert "internal error" not in err


@pytest.mark.parametrize("tip, chain", [
    ("flange", ["j1", "j2", "j3", "j4"]),
    ("camera", ["j1", "j2", "j5", "j6"]),
    ("l3", ["j1", "j2", "j3"]),  # a tip above a fixed joint: the chain ends at that link
])
def test_the_tip_chooses_the_chain_exactly(tmp_path, tip, chain):
    model, jmap = load_mapped_robot(_urdf(tmp_path), tip=tip)
    moving = [n for n in chain if next(j for j in JOINTS if j[0] == n)[1] != "fixed"]
    assert model.n_joints == len(moving) and jmap.is_identity  # the other branch's joint is not in it
    want_limits = [next(j for j in JOINTS if j[0] == n)[7] for n in moving]
    scale = [1000.0 if next(j for j in JOINTS if j[0] == n)[1] == "prismatic" else 1.0 for n in moving]
    np.testing.assert_allclose(model.joint_limits, np.array(want_limits) * np.array(scale)[:, None])
    rng = np.random.default_rng(1)
    for _ in range(5):
        q = np.array([rng.uniform(lo, hi) for lo, hi in model.joint_limits])
        np.testing.assert_allclose(forward(model, q[None])[0], _reference(chain, q), atol=1e-9)


def test_base_and_tip_together_take_the_chain_between_them(capsys, tmp_path):
    p = _urdf(tmp_path)
    model, _ = load_mapped_robot(p, base="l1", tip="flange")
    assert model.n_joints == 2
    q = np.array([[0.3, -0.7], [1.0, 0.2]])
    for qi, Ti in zip(q, forward(model, q)):
        np.testing.assert_allclose(Ti, _reference(["j2", "j3", "j4"], qi), atol=1e-9)
    # the same through the command line: predict (its --base is the frame, so --base-link here)
    j = tmp_path / "joints.csv"
    write_csv(j, ["q1 [rad]", "q2 [rad]"], q)
    rc, out, err = run(capsys, "predict", p, j, "--base-link", "l1", "--tip-link", "flange", "--json")
    assert rc == 0, err
    np.testing.assert_allclose(json.loads(out)["poses_mm_rad"], matrix_to_pose(forward(model, q)), atol=1e-9)
    rc, out, err = run(capsys, "analyze", "--robot", p, "--tip", "camera", "--poses", "20", "--json")
    assert rc == 0, err
    assert json.loads(out)["robot"] == "branched"


@pytest.mark.parametrize("flags, pattern", [
    (["--tip", "nose"], r"--tip 'nose': no such link; the links are 'base', 'l1'"),
    (["--base", "l3", "--tip", "camera"], r"--tip 'camera' is not below --base 'l3'.*tips below 'l3': 'flange'"),
    (["--base", "l3"], r"no moving joints found between links 'l3' and 'flange'"),
    (["--base", "hand", "--tip", "flange"], r"--base 'hand': no such link"),
])
def test_a_bad_chain_choice_exits_2_saying_what_to_change(capsys, tmp_path, flags, pattern):
    rc, _, err = run(capsys, "analyze", "--robot", _urdf(tmp_path), *flags, "--poses", "5")
    assert rc == 2, err
    assert re.search(pattern, err), err


def test_base_and_tip_are_refused_for_a_robot_that_is_no_urdf(capsys):
    rc, _, err = run(capsys, "analyze", "--robot", "sr800", "--tip", "flange")
    assert rc == 2 and "choose the chain of a URDF; robot 'sr800' is not a .urdf file" in err, err


def test_compensate_takes_the_chain_of_the_urdf_it_is_given(capsys, tmp_path):
    """An identified TOML model of the flange chain, compensated against its nominal URDF: the
    links choose the URDF's chain; without them the branched URDF is refused, naming the tips."""
    import csv

    from station.core.kinematics.model import robot_to_toml

    p = _urdf(tmp_path)
    nominal, _ = load_mapped_robot(p, tip="flange")
    rng = np.random.default_rng(4)
    ident = nominal.nominal + rng.standard_normal(nominal.n_params) * np.where(nominal.is_angle(), 1e-3, 0.3)
    ident[:6] = 0.0  # targets in the robot base frame: the set-up plays no part
    model = tmp_path / "identified.toml"
    model.write_text(robot_to_toml(nominal, ident, angle_unit="rad"))
    q = np.array([[0.4, -0.6, 0.9], [-1.2, 0.3, -0.5], [2.0, 0.8, 1.1]])
    wanted = matrix_to_pose(forward(nominal, q, ident, setup=False))
    targets = tmp_path / "targets.csv"
    rows = [[f"{v:.9f}" for v in w[:3]] + [f"{math.degrees(v):.12f}" for v in w[3:]] for w in wanted]
    targets.write_text("x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg\n" + "\n".join(",".join(r) for r in rows) + "\n")
    out = tmp_path / "out.csv"
    argv = ["compensate", model, targets, "--robot", p, "-o", out, "--json"]
    rc, text, err = run(capsys, *argv, "--tip-link", "flange")
    assert rc == 0, err
    rep = json.loads(text)
    assert rep["compensated"] == 3 and rep["max_residual_um"] < 1.0
    table = list(csv.DictReader(out.open()))
    q_out = np.radians([[float(r[f"q{j}_deg"]) for j in (1, 2, 3)] for r in table])
    command = np.array([[float(r[c]) for c in ("x_mm", "y_mm", "z_mm")] for r in table])
    # the controller's command is the NOMINAL flange chain at the identified robot's joints
    np.testing.assert_allclose(command, forward(nominal, q_out, setup=False)[:, :3, 3], atol=1e-5)
    np.testing.assert_allclose(forward(nominal, q_out, ident, setup=False)[:, :3, 3], wanted[:, :3], atol=1e-3)
    assert rep["max_correction_um"] > 100.0  # a real correction, not the identity
    rc, _, err = run(capsys, *argv)
    assert rc == 2 and "choose it with --tip LINK, one of 'flange', 'camera'" in err, err
    rc, _, err = run(capsys, "compensate", model, targets, "--robot", "sr800", "-o", out, "--tip-link", "flange")
    assert rc == 2 and "choose the chain of a URDF; robot" in err and "internal error" not in err, err
