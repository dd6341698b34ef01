"""The fast forward chain, joint Jacobian and SCARA IK give the values of the straightforward ones
(a 4 × 4 matrix per transform and per joint motion, multiplied in turn: the implementation before
the speed-up, kept here as the reference) to floating-point noise, for a SCARA, an MDH six-axis
arm and a URDF arm, each with error terms (parameters off the nominal), with one parameter vector
and with a batch of them; and the joint Jacobian matches finite differences of the forward chain."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from station.core.kinematics.forward import (
    chain_frames,
    forward,
    forward_with_jacobian,
    joint_jacobian,
    scara_ik,
)
from station.core.kinematics.model import RobotModel
from station.core.kinematics.poses import spread_joints
from station.core.kinematics.transforms import pose_error, pose_to_matrix
from station.io.robot.files import load_robot

ROOT = Path(__file__).resolve().parents[2]
ROBOTS = {
    "sr800": lambda: load_robot("sr800"),
    "puma560 (MDH)": lambda: load_robot(ROOT / "examples" / "puma560" / "puma560.mdh.csv"),
    "ur5e (URDF)": lambda: load_robot(ROOT / "examples" / "ur5e" / "ur5e.urdf", tip="tool0"),
    "irb2600": lambda: load_robot("irb2600"),
}


def _reference_chain(model: RobotModel, q: np.ndarray, p: np.ndarray, setup: bool):
    """World←tool ``(..., n, 4, 4)`` and joint k's frame (its z axis the joint axis) ``[(..., n, 4, 4)]``,
    each transform and motion as its own 4 × 4 matrix."""
    batch = np.broadcast_shapes(q.shape[:-2], p.shape[:-1])
    T = np.broadcast_to(np.eye(4), batch + (q.shape[-2], 4, 4))
    axes = []
    j = 0
    for t, spec in enumerate(model.transforms):
        if t == 0 and not setup:
            continue
        T = T @ pose_to_matrix(p[..., 6 * t:6 * t + 6])[..., None, :, :]
        if spec.joint is not None:
            axes.append(T)
            M = np.zeros(q.shape[:-1] + (4, 4))
            M[..., 3, 3] = 1.0
            qj = q[..., j]
            if spec.joint == "revolute":
                M[..., 0, 0], M[..., 0, 1], M[..., 1, 0], M[..., 1, 1] = np.cos(qj), -np.sin(qj), np.sin(qj), np.cos(qj)
                M[..., 2, 2] = 1.0
            else:
                M[..., 0, 0] = M[..., 1, 1] = M[..., 2, 2] = 1.0
                M[..., 2, 3] = qj
            T = T @ M
            j += 1
    return T, axes


def _reference_joint_jacobian(model: RobotModel, q: np.ndarray, p: np.ndarray, setup: bool) -> np.ndarray:
    T, axes = _reference_chain(model, q, p, setup)
    cols = []
    for F, kind in zip(axes, model.joint_types, strict=True):
        z = np.broadcast_to(F[..., :3, 2], T.shape[:-2] + (3,))
        if kind == "revolute":
            cols.append(np.concatenate([np.cross(z, T[..., :3, 3] - F[..., :3, 3]), z], axis=-1))
        else:
            cols.append(np.concatenate([z, np.zeros(z.shape)], axis=-1))
    return np.stack(cols, axis=-1)


def _with_errors(model: RobotModel, rng: np.random.Generator, size=()) -> np.ndarray:
    """Parameters off the nominal: 0.5 mm and 1 mrad per parameter (a robot's geometric errors)."""
    scale = np.where(model.is_angle(), 1e-3, 0.5)
    return model.nominal + rng.standard_normal(tuple(size) + (model.n_params,)) * scale


@pytest.mark.parametrize("name", list(ROBOTS))
@pytest.mark.parametrize("setup", [True, False])
def test_forward_and_jacobians_match_the_reference_chain(name, setup):
    model = ROBOTS[name]()
    rng = np.random.default_rng(7)
    q = spread_joints(model, 40, rng)
    p = _with_errors(model, rng)
    T_ref, _ = _reference_chain(model, q, p, setup)
    scale = 1.0 + np.abs(T_ref)
    assert np.all(np.abs(forward(model, q, p, setup=setup) - T_ref) <= 1e-12 * scale)
    J = joint_jacobian(model, q, p, setup=setup)
    assert np.all(np.abs(J.T - T_ref) <= 1e-12 * scale)
    J_ref = _reference_joint_jacobian(model, q, p, setup)
    assert J.J.shape == J_ref.shape == (40, 6, model.n_joints)
    assert np.allclose(J.J, J_ref, rtol=0, atol=1e-9 * (1.0 + np.abs(J_ref).max()))
    # the frames the collision shapes ride on end at the tool frame
    frames = chain_frames(model, q, p, setup=setup)
    assert np.allclose(frames[:, -1], T_ref, rtol=0, atol=1e-9)
    assert np.allclose(forward_with_jacobian(model, q, p, setup=setup).T, T_ref, rtol=0, atol=1e-9)


@pytest.mark.parametrize("name", list(ROBOTS))
def test_batched_parameter_sets_match_one_set_at_a_time(name):
    model = ROBOTS[name]()
    rng = np.random.default_rng(3)
    q = spread_joints(model, 12, rng)
    P = _with_errors(model, rng, (5,))
    T = forward(model, q, P)
    J = forward_with_jacobian(model, q, P).J
    for i in range(5):
        T_ref, _ = _reference_chain(model, q, P[i], True)
        assert np.allclose(T[i], T_ref, rtol=0, atol=1e-9)
        assert np.allclose(J[i], forward_with_jacobian(model, q, P[i]).J, rtol=0, atol=1e-9)


@pytest.mark.parametrize("name", list(ROBOTS))
def test_joint_jacobian_is_the_derivative_of_the_forward_chain(name):
    model = ROBOTS[name]()
    rng = np.random.default_rng(11)
    q = spread_joints(model, 10, rng)
    p = _with_errors(model, rng)
    res = joint_jacobian(model, q, p)
    h = 1e-6
    for k in range(model.n_joints):
        dq = np.zeros(model.n_joints)
        dq[k] = h
        fd = (pose_error(forward(model, q + dq, p), res.T) - pose_error(forward(model, q - dq, p), res.T)) / (2 * h)
        assert np.allclose(res.J[..., k], fd, rtol=1e-6, atol=1e-6), (name, k)


def _reference_scara_ik(model: RobotModel, T_target: np.ndarray, q0: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Newton on x, y, z, yaw from ``q0`` with the reference chain, to convergence."""
    q = q0.copy()
    for _ in range(30):
        T, _ = _reference_chain(model, q, p, False)
        err = pose_error(T, T_target)
        J = _reference_joint_jacobian(model, q, p, False)
        e4 = np.concatenate([err[:, :3], err[:, 5:6]], axis=-1)
        J4 = np.concatenate([J[:, :3, :], J[:, 5:6, :]], axis=-2)
        q = q + np.linalg.solve(J4, -e4[..., None])[..., 0]
    return q


@pytest.mark.parametrize("elbow", [1, -1])
def test_scara_ik_matches_newton_on_the_reference_chain(elbow):
    model = load_robot("sr800")
    rng = np.random.default_rng(5)
    p = _with_errors(model, rng)
    q_true = spread_joints(model, 60, rng)
    q_true[:, 1] = elbow * np.abs(q_true[:, 1]).clip(0.2)
    T_target = forward(model, q_true, p, setup=False)
    q = scara_ik(model, T_target, elbow=elbow, params=p, check_limits=False)
    q_ref = _reference_scara_ik(model, T_target, q, p)
    assert np.allclose(q, q_ref, rtol=0, atol=1e-9)
    T_back, _ = _reference_chain(model, q, p, False)
    assert np.allclose(T_back[:, :3, 3], T_target[:, :3, 3], rtol=0, atol=1e-7)
    # the elbow's own solution: the joints the targets were made from
    assert np.allclose(q[:, :3], q_true[:, :3], rtol=0, atol=1e-7)
