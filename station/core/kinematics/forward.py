"""Forward kinematics, analytic Jacobians and inverse kinematics of a :class:`RobotModel`.

Shapes: ``joints`` is ``(..., n, g)`` [rad | mm]; ``params`` is ``(..., n_params)`` [mm, rad] with
the same leading batch axes (or none), so that one call evaluates many parameter sets at once
(the Monte Carlo study does). Results are world←tool transforms ``(..., n, 4, 4)``.

Jacobian convention: the *geometric* Jacobian. Column j holds the change of the tool position
[mm] and the world-frame rotation vector [rad] per unit change of parameter j — exactly the
derivative of :func:`station.core.kinematics.transforms.pose_error` at zero residual. Rows: x, y, z, rx, ry, rz.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from station.core.kinematics.model import RobotModel
from station.core.kinematics.transforms import invert, matrix_to_pose, pose_error, pose_to_matrix, rot_y, rot_z
from station.core.units import wrap_angle
from station.errors import UnreachableError

__all__ = [
    "forward",
    "chain_frames",
    "forward_with_jacobian",
    "joint_jacobian",
    "scara_ik",
    "scara_reach_margin",
    "scara_closed_form",
    "inverse_kinematics",
    "KinematicsResult",
]


@dataclass(frozen=True)
class KinematicsResult:
    """``T``: ``(..., n, 4, 4)`` world←tool; ``J``: ``(..., n, 6, n_params)`` geometric Jacobian."""

    T: np.ndarray
    J: np.ndarray

    @property
    def positions(self) -> np.ndarray:
        return self.T[..., :3, 3]


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.cross`` of ``(..., 3)`` vectors without its axis handling (hot loops call it often)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def _params(model: RobotModel, params) -> np.ndarray:
    p = model.nominal if params is None else np.asarray(params, dtype=float)
    if p.shape[-1] != model.n_params:
        raise ValueError(f"expected {model.n_params} parameters, got shape {p.shape}")
    return p


def _turn(T: np.ndarray, kind: str, q: np.ndarray) -> None:
    """``T ← T @ Rz(q)`` (revolute) or ``T ← T @ Trans(0, 0, q)`` (prismatic) in place, written
    out: the motion changes two columns of T (one), so no 4 × 4 joint matrix is built and
    multiplied, and the frame's memory is reused (fresh pages for every intermediate frame of
    ~17 000 poses cost as much as the arithmetic)."""
    # rows 0-2 only: a homogeneous transform's last row (0, 0, 0, 1) is what the motion leaves it
    if kind == "revolute":
        c, s = np.cos(q)[..., None], np.sin(q)[..., None]
        x, y, col0 = T[..., :3, 0].copy(), T[..., :3, 1], T[..., :3, 0]
        # x c + y s and y c − x s, written into the frame's own columns (fewer temporaries)
        np.multiply(y, s, out=col0)
        col0 += x * c
        y *= c
        x *= s
        y -= x
    else:
        T[..., :3, 3] += T[..., :3, 2] * q[..., None]


_EYE = np.eye(4)
_EYE.setflags(write=False)


def _constant_parts(model: RobotModel, params, p: np.ndarray) -> np.ndarray:
    """Every transform's constant part ``(..., nt, 4, 4)``; for the nominal parameters (``params``
    None: the plan's collision checks and the controller-side IK call the chain thousands of times
    with them) the model's own, computed once (its ``nominal`` is read-only)."""
    if params is None:
        return model.nominal_matrices
    return pose_to_matrix(p.reshape(p.shape[:-1] + (len(model.transforms), 6)))


@dataclass(frozen=True)
class _Frames:
    """The composed chain: ``T`` world←tool; ``pres[t]`` the frame in front of transform t (kept
    on request); ``axes[k]`` joint k's axis direction and a point on it ``(..., n, 3, 2)`` (columns
    z and origin of its frame; the joint's own motion leaves both in place); ``consts[t]``
    transform t's constant part; ``p`` the parameters."""

    T: np.ndarray
    pres: list
    axes: list
    consts: list
    p: np.ndarray


def _times(T: np.ndarray, C: np.ndarray) -> np.ndarray:
    """``T @ C`` for frames ``(..., n, 4, 4)`` and one transform per batch entry ``(..., 4, 4)``.
    With batch axes (many parameter sets or joint sets, the Monte Carlo's) each entry's frames are
    one ``(4n, 4) @ (4, 4)`` product: numpy hands it to BLAS whole, 4.5× faster than its own loop
    over 4 × 4 blocks (10 000 sets × 25 poses: 3.2 ms from 14.8 ms), the same values; a BLAS
    product that small never spreads over threads. Without batch axes the stacked product stays
    (one ``(4n, 4)`` product of thousands of poses is what OpenBLAS threads, see :func:`_compose`)."""
    if T.ndim < 4:
        return T @ C
    return (T.reshape(T.shape[:-3] + (-1, 4)) @ C).reshape(T.shape)


def _compose(model: RobotModel, joints, params, setup: bool, keep_frames: bool,
             keep_axes: bool = False) -> _Frames:
    """Compose the chain ``R · A1(q1) · … · K`` over poses and parameter sets; every product
    ``T @ C`` is a fresh array that the joint's motion then turns in place. The stacked matmul
    stays: numpy's own loop for 4 × 4 blocks (one ``(4n, 4) @ (4, 4)`` BLAS product was 20×
    slower on a loaded two-core machine: OpenBLAS's threads wait for busy cores)."""
    q = np.asarray(joints, dtype=float)
    p = _params(model, params)
    shape = np.broadcast_shapes(q.shape[:-2], p.shape[:-1]) + (q.shape[-2], 4, 4)
    T: np.ndarray | None = None  # None: the identity (the first transform costs no product)
    pres: list = []
    axes: list = []
    consts: list = []
    j = 0
    Cs = _constant_parts(model, params, p)
    for t, spec in enumerate(model.transforms):
        C = Cs[..., t, None, :, :]  # (..., 1, 4, 4)
        if keep_frames:
            pres.append(np.broadcast_to(_EYE, shape) if T is None else T)
            consts.append(C)
        if t == 0 and not setup:
            continue
        T = np.array(np.broadcast_to(C, shape)) if T is None else _times(T, Cs[..., t, :, :])
        if spec.joint is not None:
            if keep_axes:
                axes.append(T[..., :3, 2:4].copy())
            _turn(T, spec.joint, q[..., j])
            j += 1
    if T is None:  # only the set-up transform, left out
        T = np.array(np.broadcast_to(_EYE, shape))
    return _Frames(T, pres, axes, consts, p)


def _chain(model: RobotModel, joints, params, setup: bool, keep_frames: bool):
    """Compose the chain; optionally keep the frame in front of every transform."""
    f = _compose(model, joints, params, setup, keep_frames)
    return f.T, f.pres, f.consts, f.p


def forward(model: RobotModel, joints, params=None, setup: bool = True) -> np.ndarray:
    """World←tool transforms ``(..., n, 4, 4)`` for joints ``(..., n, g)``.

    ``setup=False`` skips the set-up transform R: the result is then in the robot base frame,
    which is what a controller works in.
    """
    T, _, _, _ = _chain(model, joints, params, setup, keep_frames=False)
    return T


def chain_frames(model: RobotModel, joints, params=None, setup: bool = True) -> np.ndarray:
    """The frame after every transform (its joint included) ``(..., n, nt, 4, 4)`` for joints
    ``(..., n, g)``: where each link stands (the collision shapes ride on them, issue 40); the last
    is :func:`forward`'s tool frame."""
    T, pres, _, _ = _chain(model, joints, params, setup, keep_frames=True)
    after = [*pres[1:], T]  # the frame before transform t + 1 is the one after transform t
    return np.stack(np.broadcast_arrays(*after), axis=-3)


def forward_with_jacobian(model: RobotModel, joints, params=None, setup: bool = True) -> KinematicsResult:
    """Forward kinematics and the analytic Jacobian with respect to every model parameter."""
    T, pres, _, p = _chain(model, joints, params, setup, keep_frames=True)
    p_tool = T[..., :3, 3]
    nt = len(model.transforms)
    P = np.stack(np.broadcast_arrays(*pres), axis=-3)  # (..., n, nt, 4, 4) frame before each transform
    Rp = P[..., :3, :3]
    pt = p.reshape(p.shape[:-1] + (1, nt, 6))  # (..., 1, nt, 6)
    # The rotation parameters turn about axes through the transform's own origin.
    origin = P[..., :3, 3] + np.einsum("...ij,...j->...i", Rp, pt[..., :3])
    Rz = rot_z(pt[..., 5])
    local = np.empty(Rz.shape)
    local[..., :, 0] = (Rz @ rot_y(pt[..., 4]))[..., :, 0]  # roll axis
    local[..., :, 1] = Rz[..., :, 1]  # pitch axis
    local[..., :, 2] = 0.0
    local[..., 2, 2] = 1.0  # yaw axis
    W = np.swapaxes(Rp @ local, -1, -2)  # (..., n, nt, 3 [roll, pitch, yaw], 3 [vector])
    lever = (p_tool[..., None, :] - origin)[..., None, :]
    blk = np.zeros(W.shape[:-2] + (6, 6))
    blk[..., :3, :3] = Rp
    blk[..., :3, 3:] = np.swapaxes(np.cross(W, lever), -1, -2)
    blk[..., 3:, 3:] = np.swapaxes(W, -1, -2)
    if not setup:
        blk[..., 0, :, :] = 0.0
    J = np.moveaxis(blk, -3, -2).reshape(blk.shape[:-3] + (6, nt * 6))
    return KinematicsResult(T, J)


def joint_jacobian(model: RobotModel, joints, params=None, setup: bool = True) -> KinematicsResult:
    """Forward kinematics and the geometric Jacobian ``(..., n, 6, g)`` with respect to the joints:
    column k is ``z_k × (p_tool − o_k)`` over ``z_k`` for a revolute joint, ``z_k`` over 0 for a
    prismatic one (``z_k``, ``o_k``: joint k's axis and origin, kept while composing the chain)."""
    f = _compose(model, joints, params, setup, keep_frames=False, keep_axes=True)
    T = f.T
    p_tool = T[..., :3, 3]
    J = np.zeros(T.shape[:-2] + (6, model.n_joints))
    for k, (F, kind) in enumerate(zip(f.axes, model.joint_types)):
        axis = F[..., 0]
        if kind == "revolute":
            J[..., :3, k] = _cross(axis, p_tool - F[..., 1])
            J[..., 3:, k] = axis
        else:
            J[..., :3, k] = axis
    return KinematicsResult(T, J)


# --- inverse kinematics -------------------------------------------------------------------

def _scara_lengths(p: np.ndarray) -> tuple[float, float]:
    P = p.reshape(-1, 6)
    c3, s3 = np.cos(P[3, 5]), np.sin(P[3, 5])
    a3 = P[3, :2] + np.array([c3 * P[4, 0] - s3 * P[4, 1], s3 * P[4, 0] + c3 * P[4, 1]])
    return float(np.hypot(*P[2, :2])), float(np.hypot(*a3))


def scara_reach_margin(model: RobotModel, T_base, params=None) -> np.ndarray:
    """``(n,)`` [mm] how far the wrist axis of a SCARA at the targets ``(n, 4, 4)`` (robot base
    frame) lies inside its reach: the smaller of the distance to the stretched arm (outer
    radius L1 + L2 about axis 1) and to the folded arm (inner radius |L1 − L2|); negative out
    of reach. Axis tilts are ignored (a few µm)."""
    p = _params(model, params)
    L1, L2 = _scara_lengths(p)
    _, c_beta = scara_closed_form(model, T_base, 1, p)
    r = np.sqrt(np.maximum(L1**2 + L2**2 + 2 * L1 * L2 * c_beta, 0.0))
    return np.minimum(L1 + L2 - r, r - abs(L1 - L2))


def scara_closed_form(model: RobotModel, T_base, elbow: int, params=None) -> tuple[np.ndarray, np.ndarray]:
    """Closed-form joints ``(n, 4)`` of the ideal SCARA for targets ``(n, 4, 4)`` in the robot
    base frame, and ``cos β`` ``(n,)`` of the elbow angle: ``|cos β| > 1`` is out of reach (the
    joints are then those of the stretched or folded arm, a start value only). Axis tilts are
    ignored here; :func:`scara_ik` and :mod:`station.core.kinematics.ik` refine on the full model.
    """
    p = _params(model, params)
    P = p.reshape(-1, 6)  # rows: R, A1, A2, A3, A4, K
    target = matrix_to_pose(np.asarray(T_base, dtype=float).reshape(-1, 4, 4))
    x, y, z, psi = target[:, 0], target[:, 1], target[:, 2], target[:, 5]
    # Planar geometry of the ideal SCARA read from the parameters.
    a2 = P[2, :2]
    c3, s3 = np.cos(P[3, 5]), np.sin(P[3, 5])
    a3 = P[3, :2] + np.array([c3 * P[4, 0] - s3 * P[4, 1], s3 * P[4, 0] + c3 * P[4, 1]])
    k = P[5, :2]
    ck, sk = np.cos(psi - P[5, 5]), np.sin(psi - P[5, 5])
    wx = x - P[1, 0] - (ck * k[0] - sk * k[1])
    wy = y - P[1, 1] - (sk * k[0] + ck * k[1])
    L1, L2 = np.hypot(*a2), np.hypot(*a3)
    off1, off2 = np.arctan2(a2[1], a2[0]), np.arctan2(a3[1], a3[0])
    c_beta = (wx**2 + wy**2 - L1**2 - L2**2) / (2 * L1 * L2)
    beta = elbow * np.arccos(np.clip(c_beta, -1.0, 1.0))
    alpha = np.arctan2(wy, wx) - np.arctan2(L2 * np.sin(beta), L1 + L2 * np.cos(beta))
    q1 = wrap_angle(alpha - off1 - P[1, 5])
    q2 = wrap_angle(beta - off2 + off1 - P[2, 5])
    q4 = wrap_angle(psi - q1 - q2 - P[1:, 5].sum())
    q3 = z - P[1:, 2].sum()
    return np.stack([q1, q2, q3, q4], axis=-1), c_beta


def scara_ik(model: RobotModel, T_target, elbow: int = 1, params=None, setup: bool = False,
             tol: float = 1e-10, max_iter: int = 20, check_limits: bool = True) -> np.ndarray:
    """Joint values ``(n, 4)`` that put the tool at ``T_target`` ``(n, 4, 4)`` (x, y, z, yaw).

    Closed form for the ideal SCARA (vertical parallel axes) with the chosen elbow
    (``+1``: φ2 > 0, ``-1``: φ2 < 0), then Newton refinement on the full model so that small
    axis tilts and offsets are honoured exactly. Roll and pitch of the target are not
    reachable by a SCARA and are ignored. Raises :class:`UnreachableError` for targets outside
    the reach or the joint limits.
    """
    if not model.is_scara:
        raise ValueError(f"robot {model.name!r} is not a SCARA (R R P R); use inverse_kinematics")
    if elbow not in (1, -1):
        raise ValueError("elbow must be +1 or -1")
    p = _params(model, params)
    Tt = np.asarray(T_target, dtype=float).reshape(-1, 4, 4)
    T_base = invert(pose_to_matrix(p[0:6]))[None] @ Tt if setup else Tt
    q, c_beta = scara_closed_form(model, T_base, elbow, p)
    if np.any(np.abs(c_beta) > 1.0):
        bad = int(np.argmax(np.abs(c_beta) > 1.0))
        x, y = T_base[bad, 0, 3], T_base[bad, 1, 3]
        L1, L2 = _scara_lengths(p)
        raise UnreachableError(
            f"target {bad} at x={x:.1f} y={y:.1f} mm is outside the reach of "
            f"{model.name!r} ({abs(L1 - L2):.0f}..{L1 + L2:.0f} mm from axis 1)"
        )
    # Newton refinement on x, y, z, yaw with the full model.
    for _ in range(max_iter):
        res = joint_jacobian(model, q, p, setup=setup)
        err = pose_error(res.T, Tt)
        e4 = np.concatenate([err[:, :3], err[:, 5:6]], axis=-1)
        J4 = np.concatenate([res.J[:, :3, :], res.J[:, 5:6, :]], axis=-2)
        dq = np.linalg.solve(J4, -e4[..., None])[..., 0]
        q = q + dq
        if np.max(np.abs(dq)) < tol:
            break
    if check_limits:
        inside = model.within_limits(q)
        if not np.all(inside):
            bad = int(np.argmin(inside))
            lim = model.joint_limits
            raise UnreachableError(
                f"target {bad} needs joints {np.array2string(q[bad], precision=4)} outside the "
                f"limits {np.array2string(lim, precision=3)}; try the other elbow (elbow={-elbow})"
            )
    return q


def inverse_kinematics(model: RobotModel, T_target, q0, params=None, setup: bool = False,
                       weights=(1.0, 1.0, 1.0, 100.0, 100.0, 100.0), tol: float = 1e-10,
                       max_iter: int = 100, damping: float = 1e-6) -> np.ndarray:
    """General numerical inverse kinematics (damped least squares), vectorised over targets.

    ``T_target``: ``(n, 4, 4)``; ``q0``: ``(n, g)`` start values (choose the configuration).
    ``weights`` scale mm against rad in the residual; for chains with fewer than six joints the
    solution is the weighted least-squares closest pose. Raises :class:`UnreachableError` when a
    target does not converge or leaves the joint limits.
    """
    Tt = np.asarray(T_target, dtype=float).reshape(-1, 4, 4)
    q = np.array(q0, dtype=float).reshape(Tt.shape[0], model.n_joints)
    w = np.asarray(weights, dtype=float)
    for _ in range(max_iter):
        res = joint_jacobian(model, q, params, setup=setup)
        err = pose_error(res.T, Tt) * w
        J = res.J * w[:, None]
        JT = np.swapaxes(J, -1, -2)
        A = JT @ J + damping * np.eye(model.n_joints)
        dq = np.linalg.solve(A, -(JT @ err[..., None]))[..., 0]
        q = q + dq
        if np.max(np.abs(dq)) < tol:
            break
    final = pose_error(forward(model, q, params, setup=setup), Tt)
    if model.n_joints >= 6 and np.max(np.abs(final[:, :3])) > 1e-6:
        raise UnreachableError("inverse kinematics did not converge; the target may be out of reach")
    if not np.all(model.within_limits(q)):
        raise UnreachableError("inverse kinematics solution leaves the joint limits")
    return q
