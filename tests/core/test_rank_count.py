"""How many parameters a chain's measurements determine, and where the station's count was one
short (issue 30, item 5: a humanoid arm's complete model has one parameter more than `station
analyze` reported for the same chain).

The complete minimal model of a serial chain measured from outside (free set-up): every revolute
axis is a line (4 numbers), every prismatic one a direction (2), plus the tool frame where the
chain stands at zero: 6 from full poses, 3 from positions of a point off the last axis, and 6
fewer from distances, which do not see the set-up (Everett, Hollerbach: 4R + 2P + 6). The
station's rank is that of its x, y, z, roll, pitch, yaw parameters, and at pitch ±90° roll and
yaw turn about one axis: the count then depends on how a transform is written, not on the
chain. :func:`chain_jacobian` perturbs every frame along and about its own axes instead (no
Euler angles) and gives the chain's count."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from station.core.identification.identifiability import _scaled_rank, analyze, chain_jacobian, gimbal_locked
from station.core.kinematics.forward import forward
from station.core.kinematics.poses import spread_joints
from station.core.kinematics.transforms import invert, matrix_to_pose, pose_to_matrix, rot_z
from station.core.measurement.measurements import synthetic_set
from station.io.robot.files import load_robot
from station.ui.cli.main import main

#: a 7-axis humanoid arm as URDFs describe one: shoulder pitch (y), roll (x) and yaw (z), elbow
#: (y), wrist yaw (z), pitch (y) and roll (x), a marker on the hand; joints about x import with
#: the frame turned 90° about y (pitch ±90°)
_JOINTS = [("shoulder_pitch", "0 0.2 0.4", "0 1 0"), ("shoulder_roll", "0 0.05 0", "1 0 0"),
           ("shoulder_yaw", "0 0 -0.1", "0 0 1"), ("elbow", "0.02 0 -0.2", "0 1 0"),
           ("wrist_yaw", "0 0 -0.25", "0 0 1"), ("wrist_pitch", "0 0 -0.03", "0 1 0"),
           ("wrist_roll", "0 0 -0.02", "1 0 0")]


def _urdf(path: Path, marker_rpy: str) -> Path:
    links = ["torso"] + [f"l{i}" for i in range(len(_JOINTS))] + ["marker"]
    body = "".join(f'<link name="{n}"/>' for n in links)
    for i, (name, xyz, axis) in enumerate(_JOINTS):
        body += (f'<joint name="{name}" type="revolute"><parent link="{links[i]}"/><child link="{links[i + 1]}"/>'
                 f'<origin xyz="{xyz}"/><axis xyz="{axis}"/>'
                 f'<limit lower="-1.5" upper="1.5" effort="1" velocity="1"/></joint>')
    body += (f'<joint name="marker" type="fixed"><parent link="{links[-2]}"/><child link="marker"/>'
             f'<origin xyz="0.03 0.02 -0.08" rpy="{marker_rpy}"/></joint>')
    path.write_text(f'<robot name="humanoid_arm">{body}</robot>')
    return path


@pytest.fixture(scope="module")
def arms(tmp_path_factory):
    d = tmp_path_factory.mktemp("arm")
    # the hand frame as the URDF has it: its x axis along the wrist roll axis, K at pitch -90°
    return load_robot(_urdf(d / "arm.urdf", "0 0 0")), load_robot(_urdf(d / "arm_k.urdf", "0.3 0.2 0.1")), d


def _set(model, kind, n=34, seed=0):
    q = spread_joints(model, n, np.random.default_rng(seed))
    pairs = np.array(np.triu_indices(n, 1)).T if kind == "distance" else None
    return synthetic_set(model, kind, q, model.nominal, pairs=pairs)


def _chain_rank(model, data) -> int:
    return _scaled_rank(chain_jacobian(model, data), set(), model.param_names)


COMPLETE = {"pose": 4 * 7 + 6, "position": 4 * 7 + 3, "distance": 4 * 7 + 3 - 6}


@pytest.mark.parametrize("kind", ["pose", "position", "distance"])
def test_the_chain_has_the_complete_count_and_the_imported_arm_shows_it(arms, kind):
    _, arm, _ = arms
    data = _set(arm, kind)
    assert _chain_rank(arm, data) == COMPLETE[kind]
    a = analyze(arm, data, describe=False)
    assert a.rank == COMPLETE[kind] and a.lost_to_gimbal_lock == 0
    assert not [t for t in gimbal_locked(arm) if t != "R" and t != "K"]  # import turns joint frames off the lock
    # the rank's tolerance is no off-by-one: the last counted and the first uncounted singular
    # values lie orders of magnitude either side of RANK_RTOL (1e-9)
    s = a.singular_values / a.singular_values[0]
    assert s[a.rank - 1] > 1e-4 and (a.rank == len(s) or s[a.rank] < 1e-13)


def test_a_tool_frame_at_pitch_90_costs_pose_data_one_parameter_and_analyze_says_so(arms, capsys):
    arm, _, d = arms
    assert gimbal_locked(arm) == ("K",)
    a = analyze(arm, _set(arm, "pose"), describe=False)
    assert (a.rank, a.chain_rank, a.lost_to_gimbal_lock) == (33, 34, 1)
    note = a.gimbal_note()
    assert note is not None and "K sits at pitch ±90°" in note and "tool frame" in note
    assert analyze(arm, _set(arm, "position"), describe=False).lost_to_gimbal_lock == 0  # K's turn is not seen
    rc = main(["analyze", "--robot", str(d / "arm.urdf"), "--poses", "34"])
    out, err = capsys.readouterr()
    assert rc == 0 and "identifiable parameters (rank): 33 (the chain itself: 34)" in out
    assert "4R+2P+6 = 34" in out and "note: the chain determines 34 parameters" in out
    rc = main(["analyze", "--robot", str(d / "arm.urdf"), "--poses", "34", "--objective", "position"])
    out, _ = capsys.readouterr()
    assert rc == 0 and "4R+2P+3 = 31" in out and "rank): 31\n" in out


@pytest.mark.parametrize("kind,complete", [("pose", 34), ("position", 31)])
def test_the_same_chain_written_at_the_lock_was_one_short(arms, kind, complete):
    """At pitch -90° only roll + yaw is fixed: A3 written as (roll 90°, yaw -90°) is the same
    matrix, the same kinematics, and the station's count drops by one where the chain's does not:
    the station's count was the wrong one, the complete model's right."""
    _, arm, _ = arms
    i = arm.transform_names.index("A3")
    p = np.array(arm.nominal)
    # undo the import's quarter turn about axis 3: A3 back at pitch -90°, A4 turned back
    quarter = np.eye(4)
    quarter[:3, :3] = rot_z(np.pi / 2)
    M3 = pose_to_matrix(p[6 * i:6 * i + 6]) @ invert(quarter)
    p[6 * i + 6:6 * i + 12] = matrix_to_pose(quarter @ pose_to_matrix(p[6 * i + 6:6 * i + 12]))
    rpy = matrix_to_pose(M3)[3:]
    assert rpy[1] == pytest.approx(-np.pi / 2)
    # at pitch -90° the matrix holds only roll + yaw: put roll at 90°, the rest in yaw
    p[6 * i:6 * i + 6] = [*M3[:3, 3], np.pi / 2, -np.pi / 2, rpy[0] + rpy[2] - np.pi / 2]
    locked = arm.with_params(p)
    q = spread_joints(arm, 34, np.random.default_rng(0))
    np.testing.assert_allclose(forward(locked, q), forward(arm, q), atol=1e-9)
    a = analyze(locked, _set(locked, kind), describe=False)
    assert a.gimbal_locked == ("A3",) and a.chain_rank == complete and a.rank == complete - 1
    assert a.gimbal_note() is not None and "A3 sits at pitch ±90°" in a.gimbal_note()


def test_a_dh_import_turns_a_locked_joint_frame_about_its_axis_keeping_the_kinematics(tmp_path):
    # θ2 = -90° after α1 = -90°: the frame in front of joint 2 is Rx(-90°)·Rz(-90°), pitch -90°
    rows = [(0.0, 675.0, 260.0, -90.0), (-90.0, 0.0, 680.0, 0.0), (0.0, 0.0, -35.0, 90.0),
            (0.0, -670.0, 0.0, -90.0), (0.0, 0.0, 0.0, 90.0), (0.0, -115.0, 0.0, 0.0)]
    f = tmp_path / "arm6.dh.csv"
    f.write_text("type,theta [deg],d [mm],a [mm],alpha [deg],lower [deg|mm],upper [deg|mm]\n"
                 + "".join(f"revolute,{t},{d},{a},{al},-170,170\n" for t, d, a, al in rows))
    m = load_robot(f)
    assert gimbal_locked(m) == ()
    q = spread_joints(m, 20, np.random.default_rng(4))
    T = np.broadcast_to(np.eye(4), (len(q), 4, 4)).copy()
    for j, (t, d, a, al) in enumerate(rows):  # the DH product itself
        th, alr = np.radians(t) + q[:, j], np.radians(al)
        A = np.zeros((len(q), 4, 4))
        A[:, 0] = np.stack([np.cos(th), -np.sin(th) * np.cos(alr), np.sin(th) * np.sin(alr), a * np.cos(th)], 1)
        A[:, 1] = np.stack([np.sin(th), np.cos(th) * np.cos(alr), -np.cos(th) * np.sin(alr), a * np.sin(th)], 1)
        A[:, 2] = np.stack([np.zeros(len(q)), np.full(len(q), np.sin(alr)), np.full(len(q), np.cos(alr)),
                            np.full(len(q), d)], 1)
        A[:, 3, 3] = 1.0
        T = T @ A
    np.testing.assert_allclose(forward(m, q), T, atol=1e-9)
    for kind, complete in (("pose", 30), ("position", 25)):  # the tool point on axis 6: 27 − 2
        data = _set(m, kind)
        assert analyze(m, data, describe=False).rank == _chain_rank(m, data) == complete


@pytest.mark.parametrize("robot,counts", [("irb2600", {"pose": 30, "position": 25, "distance": 19}),
                                          ("sr800", {"pose": 20, "position": 17, "distance": 11})])
def test_the_shipped_robots_count_what_their_chains_determine(robot, counts):
    m = load_robot(robot)
    for kind, n in counts.items():
        data = _set(m, kind, n=30)
        a = analyze(m, data, describe=False)
        assert a.rank == _chain_rank(m, data) == n and a.chain_rank is None
