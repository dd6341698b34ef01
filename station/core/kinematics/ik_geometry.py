"""The geometry of a chain's joint axes at given joints, and the named arm configuration it defines.

:func:`configuration` reads shoulder, elbow and wrist from the axis lines (the definitions are in
:mod:`station.core.kinematics.ik`'s docstring), so a configuration means the same for any parameter set; the
closed-form start values (:mod:`station.core.kinematics.ik_seeds`) and the solver's wrist-singularity score
(:mod:`station.core.kinematics.ik`) use the same axis lines. Shapes: joints ``(n, g)`` [rad | mm].
"""

from __future__ import annotations

import numpy as np

from station.core.kinematics.forward import _chain, _cross
from station.core.kinematics.model import RobotModel

__all__ = ["configuration"]

def _axes(model: RobotModel, joints, params, setup: bool) -> tuple[np.ndarray, np.ndarray]:
    """Points on and unit directions of every joint axis at ``joints`` ``(..., g)``:
    ``(..., g, 3)`` each."""
    q = np.asarray(joints, dtype=float)
    T, pres, consts, _ = _chain(model, q[..., None, :], params, setup, keep_frames=True)
    pts, dirs = [], []
    for t in model.joint_transforms:
        F = (pres[t] @ consts[t])[..., 0, :, :]
        F = np.broadcast_to(F, q.shape[:-1] + (4, 4))
        pts.append(F[..., :3, 3])
        dirs.append(F[..., :3, 2])
    return np.stack(pts, axis=-2), np.stack(dirs, axis=-2)


def _closest_point(p, d) -> np.ndarray:
    """Least-squares point closest to the lines ``p + t·d`` ``(..., k, 3)`` → ``(..., 3)``."""
    P = np.eye(3) - d[..., :, None] * d[..., None, :]  # (..., k, 3, 3)
    A = P.sum(axis=-3)
    b = np.einsum("...kij,...kj->...i", P, p)
    return np.linalg.solve(A + 1e-12 * np.eye(3), b[..., None])[..., 0]


def _unit(v) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 0, n, 1.0)


def _is_six_r(model: RobotModel) -> bool:
    return model.n_joints == 6 and all(j == "revolute" for j in model.joint_types)


def _wrist_sine(dirs) -> np.ndarray:
    return np.einsum("...i,...i->...", _cross(dirs[..., 3, :], dirs[..., 5, :]), dirs[..., 4, :])


def configuration(model: RobotModel, joints, params=None, setup: bool = False) -> np.ndarray:
    """``(n, 3)`` int: shoulder, elbow, wrist signs of ``joints`` ``(n, g)`` (:mod:`station.core.kinematics.ik`).

    Six revolute joints: all three; a SCARA: elbow only; other chains: zeros.
    """
    q = np.asarray(joints, dtype=float)
    q2 = q.reshape(-1, model.n_joints)
    out = np.zeros((q2.shape[0], 3), dtype=int)
    if model.is_scara:
        out[:, 1] = np.where(q2[:, 1] >= 0.0, 1, -1)
        return out.reshape(q.shape[:-1] + (3,))
    if not _is_six_r(model):
        return out.reshape(q.shape[:-1] + (3,))
    pts, dirs = _axes(model, q2, params, setup)
    w = _closest_point(pts[:, 3:6], dirs[:, 3:6])
    z1, o1 = dirs[:, 0], pts[:, 0]
    o2, z2 = pts[:, 1], dirs[:, 1]
    o3 = pts[:, 2]
    # the axis-2 offset from axis 1, perpendicular to axis 1; without one, z2 × z1
    h = o2 - o1
    h = h - np.einsum("ni,ni->n", h, z1)[:, None] * z1
    fallback = _cross(z2, z1)
    h = np.where((np.linalg.norm(h, axis=-1) > 1.0)[:, None], h, fallback)
    h = _unit(h - np.einsum("ni,ni->n", h, z1)[:, None] * z1)
    shoulder = np.where(np.einsum("ni,ni->n", w - o1, h) >= 0.0, 1, -1)
    # Elbow: in the arm plane spanned by the forward direction f (towards the wrist) and z1,
    # the elbow is up when (w − o2) turns counter-clockwise onto (o3 − o2).
    # Points on axes 2 and 3 are taken in the plane through w normal to z2.
    o2p = o2 + np.einsum("ni,ni->n", w - o2, z2)[:, None] * z2
    o3p = o3 + np.einsum("ni,ni->n", w - o3, z2)[:, None] * z2
    f = shoulder[:, None] * h
    normal = _cross(f, z1)
    bend = np.einsum("ni,ni->n", _cross(w - o2p, o3p - o2p), normal)
    elbow = np.where(bend >= 0.0, 1, -1)
    wrist = np.where(_wrist_sine(dirs) >= 0.0, 1, -1)
    out[:, 0], out[:, 1], out[:, 2] = shoulder, elbow, wrist
    return out.reshape(q.shape[:-1] + (3,))
