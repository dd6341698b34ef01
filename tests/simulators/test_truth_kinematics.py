"""The simulated truth's kinematics (simulators/truth_kinematics.py) against closed forms worked
by hand, and the station's kinematics against it: two implementations of the robot file's
convention that share no code (issue 33, part 7)."""

from __future__ import annotations

import numpy as np
import pytest

from simulators.truth_kinematics import true_forward
from station.core.kinematics.forward import forward
from station.io.robot.files import load_robot


def test_planar_two_link_arm_matches_its_closed_form():
    # set-up R at the origin, A1 revolute, A2 revolute 300 mm further along x, tool 200 mm on
    kinds = [None, "revolute", "revolute", None]
    p = np.zeros(24)
    p[6 * 2 + 0] = 300.0
    p[6 * 3 + 0] = 200.0
    q = np.array([[0.3, -0.7], [np.pi / 2, 0.0], [0.0, np.pi]])
    T = true_forward(kinds, p, q)
    x = 300 * np.cos(q[:, 0]) + 200 * np.cos(q[:, 0] + q[:, 1])
    y = 300 * np.sin(q[:, 0]) + 200 * np.sin(q[:, 0] + q[:, 1])
    np.testing.assert_allclose(T[:, 0, 3], x, atol=1e-9)
    np.testing.assert_allclose(T[:, 1, 3], y, atol=1e-9)
    np.testing.assert_allclose(np.arctan2(T[:, 1, 0], T[:, 0, 0]), np.angle(np.exp(1j * q.sum(axis=1))), atol=1e-12)


def test_roll_pitch_yaw_order_is_the_robot_files():
    # docs/robot-file.md: T = Trans · Rz(yaw) · Ry(pitch) · Rx(roll); a pure pitch of +90° takes
    # the tool's x axis to the world's -z
    p = np.zeros(12)
    p[6 + 4] = np.pi / 2
    T = true_forward([None, None], p, np.zeros((1, 0)))
    np.testing.assert_allclose(T[0, :3, 0], [0.0, 0.0, -1.0], atol=1e-12)
    p = np.zeros(12)
    p[6 + 3], p[6 + 5] = np.pi / 2, np.pi / 2  # roll, then yaw about the fixed z
    T = true_forward([None, None], p, np.zeros((1, 0)))
    np.testing.assert_allclose(T[0, :3, :3] @ [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(T[0, :3, :3] @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-12)


def test_prismatic_joint_moves_along_its_z():
    p = np.zeros(18)
    T = true_forward([None, "prismatic", None], p, np.array([[12.5], [-3.0]]))
    np.testing.assert_allclose(T[:, :3, 3], [[0, 0, 12.5], [0, 0, -3.0]], atol=1e-12)


@pytest.mark.parametrize("robot", ["sr800", "irb2600"])
def test_the_station_kinematics_agree_with_the_independent_truth(robot):
    model = load_robot(robot)
    rng = np.random.default_rng(7)
    params = model.nominal + rng.normal(0.0, 0.05, model.n_params)  # off nominal: every term counts
    lo, hi = model.joint_limits.T
    q = rng.uniform(lo, hi, (40, model.n_joints))
    kinds = [t.joint for t in model.transforms]
    for setup in (True, False):
        np.testing.assert_allclose(forward(model, q, params=params, setup=setup),
                                   true_forward(kinds, params, q, setup=setup), atol=1e-9)


def test_a_wrong_joint_count_is_refused():
    with pytest.raises(ValueError, match="joint values"):
        true_forward([None, "revolute", None], np.zeros(18), np.zeros((2, 2)))
