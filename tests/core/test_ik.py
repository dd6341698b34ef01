"""General inverse kinematics (station.core.kinematics.ik): all branches, limits, configurations, choice."""

from __future__ import annotations

import math

import numpy as np
import pytest

from station.core.kinematics.forward import forward, scara_ik
from station.core.kinematics.ik import ALL_ARM_CONFIGS, ArmConfig, IKStatus, configuration, has_closed_form, solve_ik
from station.core.kinematics.model import RobotModel
from station.core.kinematics.poses import spread_joints
from station.core.kinematics.transforms import pose_error, pose_to_matrix
from station.errors import ConfigError, UnreachableError
from station.io.robot.files import load_robot
from station.io.robot.formats import robot_from_dh

ARM = load_robot("irb2600")
SR800 = load_robot("sr800")
DEG = math.pi / 180


def _with_limits(model: RobotModel, limits) -> RobotModel:
    return RobotModel(model.name, model.transforms, model.nominal, np.asarray(limits, dtype=float),
                      model.description, model.prefer)


def _arm_joints(n, seed, min_q5_deg=10.0):
    q = spread_joints(ARM, n, np.random.default_rng(seed))
    q[:, 4] = np.sign(q[:, 4]) * np.maximum(np.abs(q[:, 4]), min_q5_deg * DEG)
    return q


def _errors(model, q, T, params=None):
    e = pose_error(forward(model, q, params, setup=False), T)
    return np.abs(e[:, :3]).max(), np.abs(e[:, 3:]).max()


def test_closed_form_applies_to_the_spherical_wrist_arm_only():
    assert has_closed_form(ARM)
    ur5 = robot_from_dh([("revolute", 0, 89.159, 0, math.pi / 2, -6.0, 6.0), ("revolute", 0, 0, -425, 0, -6.0, 6.0),
                         ("revolute", 0, 0, -392.25, 0, -6.0, 6.0), ("revolute", 0, 109.15, 0, math.pi / 2, -6.0, 6.0),
                         ("revolute", 0, 94.65, 0, -math.pi / 2, -6.0, 6.0), ("revolute", 0, 82.3, 0, 0, -6.0, 6.0)])
    assert not has_closed_form(ur5)
    # without a closed form the fixed start values still solve it
    rng = np.random.default_rng(2)
    q = rng.uniform(-2, 2, (12, 6))
    T = forward(ur5, q, setup=False)
    r = solve_ik(ur5, T)
    assert np.all(r.has_joints)
    pos, ang = _errors(ur5, r.joints, T)
    assert pos < 1e-8 and ang < 1e-10


def test_solves_the_full_model_inside_the_limits():
    rng = np.random.default_rng(11)
    identified = ARM.nominal + rng.standard_normal(ARM.n_params) * np.where(ARM.is_angle(), 5e-4, 0.3)
    q = _arm_joints(60, 1)
    T = forward(ARM, q, identified, setup=False)
    r = solve_ik(ARM, T, identified)
    assert all(s is IKStatus.OK for s in r.status), r.failures()
    assert np.all(ARM.within_limits(r.joints))
    pos, ang = _errors(ARM, r.joints, T, identified)
    assert pos < 1e-8 and ang < 1e-11
    assert np.all(r.n_solutions >= 1)


def test_deterministic_and_independent_of_the_batch():
    q = _arm_joints(40, 2)
    T = forward(ARM, q, setup=False)
    a, b = solve_ik(ARM, T), solve_ik(ARM, T)
    np.testing.assert_array_equal(a.joints, b.joints)
    perm = np.random.default_rng(0).permutation(40)
    c = solve_ik(ARM, T[perm])
    np.testing.assert_allclose(c.joints, a.joints[perm], atol=1e-9)
    np.testing.assert_array_equal(c.config, a.config[perm])


def test_eight_configurations_of_a_spherical_wrist_arm():
    wide = _with_limits(ARM, [[-math.pi, math.pi]] * 6)
    # wrist centre close to axis 1: reachable forwards and over backwards
    T = forward(wide, np.array([[0.3, -0.3, -1.4, 0.5, 0.8, -0.3]]), setup=False)
    r = solve_ik(wide, T)
    sol = r.solutions
    assert sol.valid[0].sum() == 8
    assert set(sol.configs_of(0)) == set(ALL_ARM_CONFIGS)
    for k in np.nonzero(sol.valid[0])[0]:
        pos, ang = _errors(wide, sol.joints[0, k][None], T)
        assert pos < 1e-8 and ang < 1e-11


@pytest.mark.parametrize("cfg", ALL_ARM_CONFIGS, ids=str)
def test_requested_configuration_is_honoured(cfg):
    wide = _with_limits(ARM, [[-math.pi, math.pi]] * 6)
    q = np.array([[0.3, -0.3, -1.4, 0.5, 0.8, -0.3], [-1.0, 0.1, -2.0, -1.0, -0.6, 2.0]])
    T = forward(wide, q, setup=False)
    r = solve_ik(wide, T, configuration=cfg)
    assert all(s is IKStatus.OK for s in r.status)
    assert np.all(r.config == cfg.as_array())
    np.testing.assert_array_equal(configuration(wide, r.joints), r.config)
    pos, ang = _errors(wide, r.joints, T)
    assert pos < 1e-8 and ang < 1e-11


def test_partial_configuration_and_unavailable_configuration():
    q = _arm_joints(20, 3)
    T = forward(ARM, q, setup=False)
    r = solve_ik(ARM, T, configuration=ArmConfig(elbow=-1))
    got = r.config[r.has_joints]
    assert np.all(got[:, 1] == -1)
    # the irb2600 cannot reach over backwards with the arm stretched far forward: ask for it
    far = forward(ARM, np.array([[0.0, 1.2, -0.6, 0.0, 0.5, 0.0]]), setup=False)
    back = solve_ik(ARM, far, configuration=ArmConfig(shoulder=-1))
    assert back.status[0] is IKStatus.CONFIGURATION
    assert "reachable:" in back.reason[0] and np.isnan(back.joints[0]).all()


def test_zero_pose_configuration_reads_as_named():
    # zeros: upper arm up, forearm forward: shoulder forward, elbow above the shoulder-wrist line
    cfg = configuration(ARM, np.array([[0, 0, 0, 0, 0.5, 0], [math.pi, 0, 0, 0, 0.5, 0]]))
    assert tuple(cfg[0, :2]) == (1, 1)
    assert cfg[1, 0] == 1  # turning axis 1 carries the wrist along: still forward
    flipped = configuration(ARM, np.array([[0, 0, 0, 0, -0.5, 0]]))
    assert flipped[0, 2] == -cfg[0, 2]


def test_limits_are_respected_and_reported():
    narrow = _with_limits(ARM, np.vstack([[-10 * DEG, 10 * DEG], ARM.joint_limits[1:]]))
    q = np.array([[math.pi / 2, 0.3, -0.3, 0.2, 0.6, 0.1]])
    T = forward(ARM, q, setup=False)
    r = solve_ik(narrow, T)
    assert r.status[0] is IKStatus.OUTSIDE_LIMITS
    assert "joint 1" in r.reason[0] and np.isnan(r.joints[0]).all()
    # a solution near a limit is not preferred over one farther away
    ok = solve_ik(ARM, forward(ARM, _arm_joints(30, 4), setup=False))
    for i in range(30):
        v = ok.solutions.valid[i]
        assert ok.margin[i] >= np.min(np.minimum(ok.solutions.margin[i][v], 0.5 * ok.solutions.wrist_sine[i][v])) - 1e-12


def test_unreachable_and_near_singular_targets_are_flagged():
    T = pose_to_matrix(np.array([[3000.0, 0.0, 500.0, 0.0, 0.0, 0.0]]))
    r = solve_ik(ARM, T)
    assert r.status[0] is IKStatus.UNREACHABLE and "out of reach" in r.reason[0]
    q = np.array([[0.2, 0.3, -0.4, 0.3, 0.2 * DEG, 0.1]])
    T = forward(ARM, q, setup=False)
    free = solve_ik(ARM, T)  # another branch (elbow flipped) keeps the wrist away from q5 = 0
    assert free.status[0] is IKStatus.OK and free.wrist_sine[0] > math.sin(5 * DEG)
    s = solve_ik(ARM, T, configuration=configuration(ARM, q))
    assert s.status[0] is IKStatus.NEAR_SINGULARITY and "singularity" in s.reason[0]
    assert s.has_joints[0] and not s.ok[0]
    with pytest.raises(UnreachableError, match="cannot be reached"):
        s.raise_for_failures()
    np.testing.assert_array_equal(s.raise_for_failures(allow_singular=True), s.joints)


def test_near_joints_choose_the_nearest_solution():
    q = _arm_joints(10, 5)
    T = forward(ARM, q, setup=False)
    r = solve_ik(ARM, T, near=q + 0.01)
    np.testing.assert_allclose(r.joints, q, atol=1e-8)


def test_scara_matches_the_closed_form_and_honours_the_elbow():
    q = spread_joints(SR800, 30, np.random.default_rng(6))
    T = forward(SR800, q, setup=False)
    for elbow in (1, -1):
        r = solve_ik(SR800, T, configuration=ArmConfig(elbow=elbow))
        ok = r.has_joints
        assert ok.sum() >= 20
        assert np.all(np.sign(r.joints[ok, 1]) == elbow)
        np.testing.assert_allclose(r.joints[ok], scara_ik(SR800, T[ok], elbow, check_limits=False), atol=1e-9)
    with pytest.raises(ConfigError, match="only the elbow"):
        solve_ik(SR800, T, configuration=ArmConfig(shoulder=1))


def test_setup_frame_targets():
    p = ARM.nominal.copy()
    p[:6] = [1200.0, -300.0, 50.0, 0.01, -0.02, 0.7]
    q = _arm_joints(5, 7)
    T_world = forward(ARM, q, p, setup=True)
    r = solve_ik(ARM, T_world, p, setup=True, near=q)
    np.testing.assert_allclose(r.joints, q, atol=1e-8)
