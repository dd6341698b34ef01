"""The simulated controller's own kinematics (simulators/arm_kinematics.py) held to the station's
on random poses: two implementations that share no code, so that a slip in the station's inverse
kinematics is no longer made by the controller too, where the two would cancel end to end
(issue 42)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from simulators.arm_kinematics import ArmKinematics, Unreachable
from simulators.controller_server import SimulatedController
from simulators.truth_kinematics import pose_matrix, true_forward
from simulators.urscript.arm import Arm
from station.core.kinematics.forward import forward, inverse_kinematics, scara_ik
from station.core.kinematics.transforms import matrix_to_pose
from station.errors import UnreachableError
from station.io.robot.files import load_robot

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
SCARAS = [pytest.param("sr800", id="sr800"),
          *(pytest.param(str(EXAMPLES / name / "robot.toml"), id=name) for name in ("scara600", "scara_arc"))]


def _kinematics(model, params):
    return ArmKinematics([t.joint for t in model.transforms], params)


def _off_nominal(model, rng, sigma=1e-3):
    # every parameter off its nominal value, tilts included, so that no term can hide
    return model.nominal + rng.normal(0.0, sigma, model.n_params)


@pytest.mark.parametrize("robot", [*SCARAS, "irb2600"])
def test_forward_agrees_with_the_truth_and_the_station(robot):
    model = load_robot(robot)
    rng = np.random.default_rng(11)
    params = _off_nominal(model, rng)
    lo, hi = model.joint_limits.T
    q = rng.uniform(lo, hi, (30, model.n_joints))
    mine = np.array([_kinematics(model, params).forward(row) for row in q])
    kinds = [t.joint for t in model.transforms]
    np.testing.assert_allclose(mine, true_forward(kinds, params, q, setup=False), atol=1e-9)
    np.testing.assert_allclose(mine, forward(model, q, params=params, setup=False), atol=1e-9)


@pytest.mark.parametrize("robot", SCARAS)
def test_scara_inverse_agrees_with_the_stations_on_random_poses(robot):
    model = load_robot(robot)
    rng = np.random.default_rng(5)
    params = _off_nominal(model, rng)
    arm = _kinematics(model, params)
    lo, hi = model.joint_limits.T
    q = rng.uniform(lo, hi, (40, 4))
    # away from the stretched arm, where the elbow is undefined and both refuse
    q[:, 1] = np.sign(q[:, 1]) * np.clip(np.abs(q[:, 1]), 0.2, None)
    T = forward(model, q, params=params, setup=False)
    for i in range(len(q)):
        elbow = 1 if q[i, 1] > 0 else -1
        mine = arm.scara_inverse(T[i], elbow)
        station = scara_ik(model, T[i][None], elbow=elbow, params=params, check_limits=False)[0]
        np.testing.assert_allclose(mine, station, atol=1e-8, err_msg=f"pose {i}, elbow {elbow}")
        # the joints it was drawn from (yaw of joint 4 up to a turn)
        d = mine - q[i]
        d[[0, 1, 3]] = np.angle(np.exp(1j * d[[0, 1, 3]]))
        np.testing.assert_allclose(d, 0.0, atol=1e-8)


def test_scara_elbows_mirror_and_out_of_reach_is_refused():
    model = load_robot("sr800")
    arm = _kinematics(model, model.nominal)
    T = arm.forward(np.array([0.4, 1.1, -60.0, 0.3]))
    up, down = arm.scara_inverse(T, 1), arm.scara_inverse(T, -1)
    assert up[1] == pytest.approx(1.1, abs=1e-9) and down[1] == pytest.approx(-1.1, abs=1e-9)
    np.testing.assert_allclose(arm.forward(down), T, atol=1e-9)
    far = T.copy()
    far[:2, 3] *= 1000.0 / np.linalg.norm(far[:2, 3])  # 1 m from axis 1: beyond 445 + 355 mm
    with pytest.raises(Unreachable, match="outside the arm's reach"):
        arm.scara_inverse(far, 1)
    with pytest.raises(UnreachableError):
        scara_ik(model, far[None], elbow=1)  # the station agrees it is out of reach


def test_six_axis_inverse_agrees_with_the_stations_from_nearby_starts():
    model = load_robot("irb2600")
    rng = np.random.default_rng(9)
    params = _off_nominal(model, rng)
    arm = _kinematics(model, params)
    lo, hi = model.joint_limits.T
    q = rng.uniform(0.6 * lo, 0.6 * hi, (25, 6))
    T = forward(model, q, params=params, setup=False)
    for i in range(len(q)):
        near = q[i] + rng.normal(0.0, 0.05, 6)
        mine = arm.inverse(T[i], near)
        station = inverse_kinematics(model, T[i][None], near[None], params=params)[0]
        np.testing.assert_allclose(mine, station, atol=1e-8, err_msg=f"pose {i}")
        np.testing.assert_allclose(arm.forward(mine), T[i], atol=1e-8)


def test_six_axis_out_of_reach_is_refused():
    model = load_robot("irb2600")
    arm = _kinematics(model, model.nominal)
    T = arm.forward(np.zeros(6))
    T[:3, 3] = [5000.0, 0.0, 500.0]  # 5 m away
    with pytest.raises(Unreachable):
        arm.inverse(T, np.zeros(6))


@pytest.mark.parametrize("robot", ["sr800", "irb2600"])
def test_the_controller_commands_the_joints_the_station_would_solve(robot):
    # the controller's Cartesian target (no table active) against the station's nominal IK
    model = load_robot(robot)
    ctrl = SimulatedController(model=model)
    rng = np.random.default_rng(3)
    lo, hi = model.joint_limits.T
    for q in rng.uniform(0.5 * lo, 0.5 * hi, (10, model.n_joints)):
        if model.is_scara:
            q[1] = np.sign(q[1]) * max(abs(q[1]), 0.2)
        T = forward(model, q[None], setup=False)[0]
        pose = matrix_to_pose(T)
        np.testing.assert_allclose(pose_matrix(pose), T, atol=1e-9)  # one pose convention
        elbow = 1 if q[1] > 0 else -1
        ctrl._q = q + (0.02 if not model.is_scara else 0.0)  # the arm stands near the target
        got = ctrl.cartesian_target(pose, elbow)
        if model.is_scara:
            want = scara_ik(model, T[None], elbow=elbow, check_limits=False)[0]
        else:
            want = inverse_kinematics(model, T[None], ctrl._q[None])[0]
        np.testing.assert_allclose(got, want, atol=1e-8)


def test_the_urscript_arm_round_trips_its_poses():
    arm = Arm()
    rng = np.random.default_rng(4)
    lo, hi = arm.model.joint_limits.T
    tcp = [0.0, 0.0, 0.1, 0.0, 0.0, 0.0]
    for q in rng.uniform(0.5 * lo, 0.5 * hi, (5, 6)):
        pose = arm.forward(q, tcp)
        T = forward(arm.model, q[None], setup=False)[0]
        np.testing.assert_allclose(np.array(pose[:3]) * 1000.0, (T @ [0.0, 0.0, 100.0, 1.0])[:3], atol=1e-9)
        back = arm.inverse(pose, q + 0.03, tcp, 1e-7, 1e-6)
        assert back is not None
        np.testing.assert_allclose(back, q, atol=1e-7)
