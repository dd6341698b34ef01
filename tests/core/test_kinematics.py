"""Forward kinematics, analytic Jacobians (vs finite differences), batching, inverse kinematics."""

from __future__ import annotations

import math

import numpy as np
import pytest

from station.core.kinematics.forward import forward, forward_with_jacobian, inverse_kinematics, joint_jacobian, scara_ik
from station.core.kinematics.transforms import pose_error, pose_to_matrix
from station.errors import UnreachableError
from station.io.robot.files import load_robot
from station.io.robot.formats import robot_from_dh

SR800 = load_robot("sr800")
DEG = math.pi / 180


def random_params(model, rng, length=0.5, angle=0.02):
    """Nominal with every parameter perturbed, incl. a non-trivial set-up R."""
    p = model.nominal + rng.standard_normal(model.n_params) * np.where(model.is_angle(), angle, length)
    p[:6] = [120.0, -40.0, 15.0, 0.1, -0.05, 0.7]
    return p


def random_joints(model, rng, n, margin=0.05):
    lim = model.joint_limits
    span = lim[:, 1] - lim[:, 0]
    return rng.uniform(lim[:, 0] + margin * span, lim[:, 1] - margin * span, (n, model.n_joints))


def fd_param_jacobian(model, q, p, setup, h_len=1e-4, h_ang=1e-7):
    """Central differences of pose_error(forward(p ± h e_j), forward(p)) -> (n, 6, P)."""
    T0 = forward(model, q, p, setup=setup)
    cols = []
    for j in range(model.n_params):
        h = h_ang if model.is_angle()[j] else h_len
        dp = np.zeros_like(p)
        dp[j] = h
        ep = pose_error(forward(model, q, p + dp, setup=setup), T0)
        em = pose_error(forward(model, q, p - dp, setup=setup), T0)
        cols.append((ep - em) / (2 * h))
    return np.stack(cols, axis=-1)


def assert_columns_close(J, J_ref, rtol=1e-6):
    """Column-wise relative agreement (a column may mix mm and rad rows, scaled by its norm)."""
    scale = np.maximum(np.linalg.norm(J_ref, axis=(0, 1)), 1e-9)
    err = np.linalg.norm(J - J_ref, axis=(0, 1)) / scale
    assert err.max() < rtol, f"worst column {int(err.argmax())}: relative error {err.max():.2e}"


@pytest.mark.parametrize("setup", [True, False])
@pytest.mark.parametrize("seed", [0, 1])
def test_param_jacobian_vs_finite_differences(setup, seed):
    rng = np.random.default_rng(seed)
    p = random_params(SR800, rng)
    q = random_joints(SR800, rng, 12)
    res = forward_with_jacobian(SR800, q, p, setup=setup)
    np.testing.assert_array_equal(res.T, forward(SR800, q, p, setup=setup))
    J_fd = fd_param_jacobian(SR800, q, p, setup)
    assert_columns_close(res.J, J_fd)
    if not setup:
        assert np.all(res.J[..., :6] == 0.0)  # R has no effect in the base frame
    else:
        assert np.all(np.linalg.norm(res.J[..., :6], axis=(0, 1)) > 0)


def test_param_jacobian_six_axis_robot():
    rng = np.random.default_rng(2)
    m = robot_from_dh(PUMA)
    p = random_params(m, rng, length=1.0, angle=0.05)
    q = random_joints(m, rng, 8)
    assert_columns_close(forward_with_jacobian(m, q, p).J, fd_param_jacobian(m, q, p, True))


@pytest.mark.parametrize("setup", [True, False])
def test_joint_jacobian_vs_finite_differences(setup):
    rng = np.random.default_rng(3)
    p = random_params(SR800, rng)
    q = random_joints(SR800, rng, 10)
    res = joint_jacobian(SR800, q, p, setup=setup)
    assert res.J.shape == (10, 6, 4)
    T0 = forward(SR800, q, p, setup=setup)
    cols = []
    for j, kind in enumerate(SR800.joint_types):
        h = 1e-4 if kind == "prismatic" else 1e-7
        dq = np.zeros(4)
        dq[j] = h
        cols.append((pose_error(forward(SR800, q + dq, p, setup=setup), T0)
                     - pose_error(forward(SR800, q - dq, p, setup=setup), T0)) / (2 * h))
    assert_columns_close(res.J, np.stack(cols, axis=-1))
    # a prismatic joint only translates
    assert np.all(res.J[:, 3:, 2] == 0.0)


def test_batched_params_equal_per_set():
    rng = np.random.default_rng(4)
    P = np.stack([random_params(SR800, rng) for _ in range(5)])
    q = random_joints(SR800, rng, 7)
    Tb = forward(SR800, q, P)
    rb = forward_with_jacobian(SR800, q, P)
    jb = joint_jacobian(SR800, q, P)
    assert Tb.shape == (5, 7, 4, 4) and rb.J.shape == (5, 7, 6, 36) and jb.J.shape == (5, 7, 6, 4)
    for b in range(5):
        np.testing.assert_allclose(Tb[b], forward(SR800, q, P[b]), rtol=0, atol=1e-12)
        r1 = forward_with_jacobian(SR800, q, P[b])
        np.testing.assert_allclose(rb.T[b], r1.T, rtol=0, atol=1e-12)
        np.testing.assert_allclose(rb.J[b], r1.J, rtol=0, atol=1e-10)
        np.testing.assert_allclose(jb.J[b], joint_jacobian(SR800, q, P[b]).J, rtol=0, atol=1e-10)
    # batched joints as well: (B, n, g) with (B, P)
    Q = np.stack([random_joints(SR800, rng, 7) for _ in range(5)])
    TQ = forward(SR800, Q, P, setup=False)
    for b in range(5):
        np.testing.assert_allclose(TQ[b], forward(SR800, Q[b], P[b], setup=False), atol=1e-12)


def test_wrong_param_count():
    with pytest.raises(ValueError, match="expected 36 parameters"):
        forward(SR800, np.zeros((1, 4)), np.zeros(35))


# --- SCARA inverse kinematics ---------------------------------------------------------------------

def tilted_sr800(rng):
    """Small tilts and offsets everywhere (arc minutes, tenths of mm)."""
    return SR800.nominal + rng.standard_normal(36) * np.where(SR800.is_angle(), 1e-3, 0.2)


@pytest.mark.parametrize("setup", [False, True])
@pytest.mark.parametrize("elbow", [1, -1])
def test_scara_ik_recovers_joints(elbow, setup):
    rng = np.random.default_rng(10 + elbow)
    p = tilted_sr800(rng)
    if setup:
        p[:6] = [300.0, -150.0, 20.0, 0.002, -0.001, 0.6]
    n = 40
    q = np.column_stack([rng.uniform(-2.0, 2.0, n), elbow * rng.uniform(0.3, 2.3, n),
                         rng.uniform(-190, -10, n), rng.uniform(-3.0, 3.0, n)])
    T = forward(SR800, q, p, setup=setup)
    q_ik = scara_ik(SR800, T, elbow=elbow, params=p, setup=setup)
    np.testing.assert_allclose(q_ik, q, rtol=0, atol=1e-9)


def test_scara_ik_other_elbow_reaches_same_point():
    rng = np.random.default_rng(12)
    p = tilted_sr800(rng)
    q = np.array([[0.4, 1.0, -80.0, 0.3], [-0.5, 0.8, -20.0, -1.0]])
    T = forward(SR800, q, p, setup=False)
    q_other = scara_ik(SR800, T, elbow=-1, params=p)
    assert np.all(q_other[:, 1] < 0)
    err = pose_error(forward(SR800, q_other, p, setup=False), T)
    # x, y, z and yaw are reached; roll/pitch differ only by the tilt effects (tiny)
    assert np.abs(err[:, :3]).max() < 1e-9
    assert np.abs(err[:, 5]).max() < 1e-9


def test_scara_ik_unreachable():
    T = pose_to_matrix(np.array([[2000.0, 0.0, 400.0, 0, 0, 0]]))
    with pytest.raises(UnreachableError, match="outside the reach"):
        scara_ik(SR800, T)
    # inside the annulus but needs q2 beyond its ±145° limit -> limit error
    T_close = pose_to_matrix(np.array([[120.0, 0.0, 400.0, 0, 0, 0]]))
    with pytest.raises(UnreachableError, match="outside the\\s+limits"):
        scara_ik(SR800, T_close)


def test_scara_ik_rejects_non_scara():
    with pytest.raises(ValueError, match="not a SCARA"):
        scara_ik(robot_from_dh(PUMA), np.eye(4)[None])


# --- general inverse kinematics ------------------------------------------------------------------

PUMA = [  # PUMA 560 (mm, rad), limits ±170°
    ("revolute", 0.0, 0.0, 0.0, math.pi / 2, -170 * DEG, 170 * DEG),
    ("revolute", 0.0, 0.0, 431.8, 0.0, -170 * DEG, 170 * DEG),
    ("revolute", 0.0, 150.05, 20.32, -math.pi / 2, -170 * DEG, 170 * DEG),
    ("revolute", 0.0, 431.8, 0.0, math.pi / 2, -170 * DEG, 170 * DEG),
    ("revolute", 0.0, 0.0, 0.0, -math.pi / 2, -170 * DEG, 170 * DEG),
    ("revolute", 0.0, 56.25, 0.0, 0.0, -170 * DEG, 170 * DEG),
]


def test_inverse_kinematics_six_axis():
    m = robot_from_dh(PUMA, name="puma")
    rng = np.random.default_rng(20)
    q = rng.uniform(-1.2, 1.2, (10, 6))
    q[:, 4] = np.sign(q[:, 4]) * np.maximum(np.abs(q[:, 4]), 0.4)  # away from the wrist singularity
    T = forward(m, q, setup=False)
    q0 = q + rng.uniform(-0.05, 0.05, q.shape)
    q_ik = inverse_kinematics(m, T, q0)
    np.testing.assert_allclose(q_ik, q, rtol=0, atol=1e-8)
    err = pose_error(forward(m, q_ik, setup=False), T)
    assert np.abs(err).max() < 1e-8


def test_inverse_kinematics_unreachable():
    m = robot_from_dh(PUMA, name="puma")
    T = pose_to_matrix(np.array([[3000.0, 0, 0, 0, 0, 0]]))
    with pytest.raises(UnreachableError):
        inverse_kinematics(m, T, np.zeros((1, 6)) + 0.1)
