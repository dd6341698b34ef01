"""Reload parity of the exports of issue 41 §2: the identified model written into the robot's own
URDF and as UR's kinematics YAML, read back by readers that are not the station's (yourdfpy's
URDF parser and forward kinematics; PyYAML and UR's description's formula written again here),
reproduce the model's forward kinematics within 1 µm and 1 µrad at 10 000 configurations drawn
inside the joint limits. The rest of the URDF stays byte for byte; what a format cannot hold is
named in the file and on stderr."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml
import yourdfpy
from scipy.spatial.transform import Rotation

from station.core.kinematics.forward import forward
from station.core.kinematics.model import robot_to_toml
from station.io.export.model_files import export_model
from station.io.export.urdf_calibrated import write_calibrated_urdf
from station.io.robot.files import load_robot
from station.ui.cli.main import main

ROOT = Path(__file__).resolve().parents[2]
UR5E = ROOT / "examples" / "ur5e" / "ur5e.urdf"
PUMA = ROOT / "examples" / "puma560" / "puma560.mdh.csv"
N = 10_000
UM, URAD = 1e-3, 1e-6  # [mm], [rad]


def _identified(model, seed: int) -> np.ndarray:
    """The model's parameters moved as an identification moves them (0.3 mm, 0.5 mrad σ), every
    transform, the set-up R included: no parameter the export may skip stays nominal."""
    rng = np.random.default_rng(seed)
    d = rng.normal(size=model.nominal.shape).reshape(-1, 6)
    d[:, :3] *= 0.3
    d[:, 3:] *= 5e-4
    return np.asarray(model.nominal) + d.ravel()


def _configs(model, seed: int = 7) -> np.ndarray:
    lim = np.asarray(model.joint_limits)
    return np.random.default_rng(seed).uniform(lim[:, 0], lim[:, 1], size=(N, model.n_joints))


def _pose_gap(A: np.ndarray, B: np.ndarray) -> tuple[float, float]:
    """Largest position [mm] and rotation-angle [rad] difference of two transform stacks."""
    dp = np.linalg.norm(A[:, :3, 3] - B[:, :3, 3], axis=1).max()
    R = np.einsum("nji,njk->nik", A[:, :3, :3], B[:, :3, :3])
    da = np.linalg.norm(Rotation.from_matrix(R).as_rotvec(), axis=1).max()
    return float(dp), float(da)


def _yourdfpy_fk(urdf: yourdfpy.URDF, base: str, tip: str, q: np.ndarray) -> np.ndarray:
    """URDF semantics over yourdfpy's parsed joints: each joint's origin, then its motion about /
    along its axis; [mm]. Vectorised over the configurations (yourdfpy's own per-configuration
    forward kinematics is checked against it on a sample)."""
    chain, link = [], tip
    parent_of = {j.child: j for j in urdf.robot.joints}
    while link != base:
        j = parent_of[link]
        chain.append(j)
        link = j.parent
    T = np.tile(np.eye(4), (len(q), 1, 1))
    k = 0
    for j in reversed(chain):
        origin = np.array(j.origin if j.origin is not None else np.eye(4), dtype=float)
        T = T @ origin
        if j.type in ("revolute", "continuous", "prismatic"):
            M = np.tile(np.eye(4), (len(q), 1, 1))
            axis = np.asarray(j.axis, dtype=float)
            axis = axis / np.linalg.norm(axis)
            if j.type == "prismatic":
                M[:, :3, 3] = q[:, k:k + 1] / 1000.0 * axis
            else:
                M[:, :3, :3] = Rotation.from_rotvec(q[:, k:k + 1] * axis).as_matrix()
            T = T @ M
            k += 1
    T[:, :3, 3] *= 1000.0
    return T


def _urdf_parity(path: Path, base: str, tip: str, seed: int, tmp_path: Path):
    nominal = load_robot(path, base, tip)
    p = _identified(nominal, seed)
    p_base = p.copy()
    p_base[:6] = 0.0  # a robot's URDF starts at its base: R is named, not written
    edit = write_calibrated_urdf(path, nominal, p_base, base, tip)
    out = tmp_path / f"calibrated_{path.name}"
    out.write_bytes(edit.data)
    urdf = yourdfpy.URDF.load(str(out), load_meshes=False, build_collision_scene_graph=False)
    q = _configs(nominal)
    want = forward(nominal, q, p_base, setup=False)
    got = _yourdfpy_fk(urdf, base, tip, q)
    dp, da = _pose_gap(want, got)
    assert dp < UM and da < URAD, (dp, da)
    for qi, Ti in zip(q[:50], want[:50]):  # yourdfpy's own forward kinematics agrees on a sample
        urdf.update_cfg(list(qi / np.where(np.array(nominal.joint_types) == "prismatic", 1000.0, 1.0)))
        T = urdf.get_transform(tip, base)
        assert np.linalg.norm(T[:3, 3] * 1000.0 - Ti[:3, 3]) < UM
    # the nominal parameters written back are not the file: the calibration moved every origin
    assert _pose_gap(forward(nominal, q[:100], setup=False), got[:100])[0] > 0.1
    return path.read_bytes(), edit


def _same_outside_origins(before: bytes, after: bytes) -> None:
    """The files equal byte for byte once the inserted header comment is cut and every xyz / rpy
    attribute value blanked; and every origin outside the chain's joints keeps its value."""
    header = re.search(rb"<!-- station export-model.*?-->\n", after, re.S)
    assert header is not None
    after = after[:header.start()] + after[header.end():]
    blank = re.compile(rb'((?:xyz|rpy)\s*=\s*)"[^"]*"')
    assert blank.sub(rb'\1""', before) == blank.sub(rb'\1""', after)


def test_urdf_robot_into_its_own_urdf_reloads_within_a_micrometre(tmp_path):
    before, edit = _urdf_parity(UR5E, "base_link_inertia", "tool0", 1, tmp_path)
    _same_outside_origins(before, edit.data)
    # the fixed joints before the chain and the other branch are untouched
    for name in ("base_link-base_link_inertia", "base_link-base_fixed_joint", "wrist_3-flange"):
        assert name not in edit.joints
    assert "flange-tool0" in edit.joints  # K goes into the tip's own fixed joint


def test_scara_from_its_urdf_reloads_within_a_micrometre(tmp_path):
    """The built-in SCARA has no URDF of its own; written as one (urdf-new), it is a URDF robot
    with a prismatic axis, and its calibration goes back into that file."""
    sr800 = load_robot("sr800")
    path = tmp_path / "sr800.urdf"
    path.write_text(export_model(sr800, "urdf", setup=False).text)
    before, edit = _urdf_parity(path, "base_link", "tool0", 2, tmp_path)
    _same_outside_origins(before, edit.data)


#: axes off z (the import turns them onto z), a joint without <origin> (one is inserted), single
#: quotes, a comment holding a joint that is no joint, and a branch that stays as it was
ODD_ARM = """<?xml version='1.0' encoding='utf-8'?>
<robot name='odd_arm'>
  <!-- <joint name='j2' type='fixed'><origin xyz='9 9 9'/></joint> -->
  <link name='base'/><link name='l1'/><link name='l2'/><link name='l3'/><link name='flange'/><link name='cam'/>
  <joint name='j1' type='revolute'><parent link='base'/><child link='l1'/>
    <axis xyz='0 0 1'/><limit lower='-2.5' upper='2.5' effort='1' velocity='1'/></joint>
  <joint name='j2' type='revolute'>
    <parent link='l1'/><child link='l2'/>
    <origin rpy='0.1 0 0'   xyz='0.05 0 0.4'/>
    <axis xyz='0 1 0'/><limit lower='-1.5' upper='1.6' effort='1' velocity='1'/></joint>
  <joint name='cam_mount' type='fixed'><parent link='l1'/><child link='cam'/><origin xyz='0.1 0 0.1'/></joint>
  <joint name='j3' type='prismatic'><parent link='l2'/><child link='l3'/>
    <origin xyz='0.3 0 0' rpy='0 0 0.2'/><axis xyz='1 0 0'/><limit lower='0' upper='0.2' effort='1' velocity='1'/></joint>
  <joint name='j4' type='fixed'><parent link='l3'/><child link='flange'/>
    <origin xyz='0.25 0 0' rpy='0 1.5707963267948966 0'/></joint>
</robot>
"""


def test_urdf_with_axes_off_z_and_a_missing_origin_reloads_within_a_micrometre(tmp_path):
    path = tmp_path / "odd_arm.urdf"
    path.write_text(ODD_ARM)
    before, edit = _urdf_parity(path, "base", "flange", 4, tmp_path)
    assert edit.joints == ("j1", "j2", "j3", "j4")
    assert b"<origin xyz='9 9 9'/>" in edit.data  # the comment is no joint
    assert b"<origin xyz='0.1 0 0.1'/>" in edit.data  # the branch is kept
    assert b"<origin rpy='" in edit.data  # j2's own quotes and order kept, its values replaced


def _ur_formula(frames: dict, q: np.ndarray) -> np.ndarray:
    """UR's description (ur_macro.xacro): joint k's origin is the frame's xyz [m] and rpy
    (URDF: fixed-axis x, y, z), then a turn about z by q_k; [mm]."""
    T = np.tile(np.eye(4), (len(q), 1, 1))
    for k, name in enumerate(("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3")):
        f = frames[name]
        origin = np.eye(4)
        origin[:3, :3] = Rotation.from_euler("xyz", [f["roll"], f["pitch"], f["yaw"]]).as_matrix()
        origin[:3, 3] = [f["x"] * 1000.0, f["y"] * 1000.0, f["z"] * 1000.0]
        M = np.tile(np.eye(4), (len(q), 1, 1))
        M[:, :3, :3] = Rotation.from_euler("z", q[:, k:k + 1]).as_matrix()
        T = T @ origin @ M
    return T


@pytest.mark.parametrize("robot, links", [(str(UR5E), ["--base-link", "base_link_inertia", "--tip-link", "tool0"]),
                                          (str(PUMA), [])])
def test_ur_calibration_reloads_within_a_micrometre(robot, links, tmp_path, capsys):
    nominal = load_robot(robot, *(links[1::2] or [None, None]))
    p = _identified(nominal, 3)
    model_file = tmp_path / "identified.toml"
    model_file.write_text(robot_to_toml(nominal, p, angle_unit="rad"))
    out = tmp_path / "kinematics.yaml"
    extra = ["--robot", robot, *links] if robot.endswith(".urdf") else []
    assert main(["export-model", str(model_file), "--format", "ur-calibration", "-o", str(out), *extra]) == 0
    err = capsys.readouterr().err
    text = out.read_text()
    data = yaml.safe_load(text)["kinematics"]
    assert data["hash"].startswith("station-sha256-") and len(data["hash"]) == len("station-sha256-") + 16
    q = _configs(nominal)
    bare = p.copy()
    bare[:6] = bare[-6:] = 0.0  # the file holds the robot base to the wrist_3 frame
    dp, da = _pose_gap(forward(nominal, q, bare, setup=False), _ur_formula(data, q))
    assert dp < UM and da < URAD, (dp, da)
    for what in ("the set-up R", "the tool K"):  # named in the file and on stderr, with their values
        assert f"# NOT HELD: {what}" in text and f"not held: {what}" in err


def test_ur_calibration_hash_follows_the_frames(tmp_path):
    nominal = load_robot(PUMA)
    hashes = []
    for seed in (3, 3, 4):
        f = tmp_path / f"m{seed}.toml"
        f.write_text(robot_to_toml(nominal, _identified(nominal, seed), angle_unit="rad"))
        main(["export-model", str(f), "--format", "ur-calibration", "-o", str(tmp_path / "k.yaml")])
        hashes.append(yaml.safe_load((tmp_path / "k.yaml").read_text())["kinematics"]["hash"])
    assert hashes[0] == hashes[1] != hashes[2]


def test_scara_is_refused_by_both_formats_with_a_reason(tmp_path, capsys):
    for fmt, says in (("ur-calibration", "six revolute joints"), ("urdf", "does not come from a URDF")):
        rc = main(["export-model", "sr800", "--format", fmt, "-o", str(tmp_path / "out")])
        err = capsys.readouterr().err
        assert rc == 2 and says in err and "Traceback" not in err
        assert not (tmp_path / "out").exists()


def test_urdf_of_another_chain_is_refused(tmp_path, capsys):
    model_file = tmp_path / "puma.toml"
    model_file.write_text(robot_to_toml(load_robot(PUMA), load_robot(PUMA).nominal, angle_unit="rad"))
    sr = tmp_path / "sr800.urdf"
    sr.write_text(export_model(load_robot("sr800"), "urdf", setup=False).text)
    rc = main(["export-model", str(model_file), "--format", "urdf", "--robot", str(sr), "-o", str(tmp_path / "o")])
    assert rc == 2 and "not the model's" in capsys.readouterr().err


def test_a_chain_ending_at_a_moving_joint_names_the_tool_it_cannot_hold(tmp_path, capsys):
    src = tmp_path / "arm.urdf"
    shutil.copy(UR5E, src)
    nominal = load_robot(src, "base_link_inertia", "wrist_3_link")
    p = _identified(nominal, 5)
    f = tmp_path / "m.toml"
    f.write_text(robot_to_toml(nominal, p, angle_unit="rad"))
    out = tmp_path / "out.urdf"
    rc = main(["export-model", str(f), "--format", "urdf", "--robot", str(src), "--base-link", "base_link_inertia",
               "--tip-link", "wrist_3_link", "--base", "-o", str(out)])
    err = capsys.readouterr().err
    assert rc == 0 and "the tool K" in err and "NOT HELD: the tool K" in out.read_text()
    assert "the set-up R" not in err  # --base: the robot in its base frame, nothing to name
