"""Where the simulated robot really is: forward kinematics written from the robot file's
definition, sharing no code with ``station.core`` (issue 33, part 7).

The station's end-to-end tests compare what the station identifies with the simulated truth. If
the truth were computed by the station's own ``station.core.kinematics.forward``, a fault there
(a flipped sign, a wrong rotation order) would move truth and model together and every test would
still agree with itself. So the truth follows the robot file's documented convention
(docs/robot-file.md, "Transforms") directly, with scipy's rotations:

    T_i = Trans(x, y, z) · Rz(yaw) · Ry(pitch) · Rx(roll)   then, for a joint transform,
          · Rz(q) (revolute) or · Trans(0, 0, q) (prismatic)

and the chain is the product over the transforms in file order, the set-up R first and the tool
K last. ``scipy.spatial.transform.Rotation.from_euler("xyz", …)`` with lower-case (extrinsic)
axes is exactly Rz(yaw)·Ry(pitch)·Rx(roll).

Only the chain's structure (which transform carries which kind of joint) and the parameter
vector are taken from the robot model: plain data, no computation.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence

import numpy as np
from scipy.spatial.transform import Rotation

__all__ = ["true_forward", "pose_matrix", "matrix_pose", "inverse", "rotation_angle"]


def _static(params6: np.ndarray) -> np.ndarray:
    """One transform's (4, 4) from its x, y, z [mm], roll, pitch, yaw [rad] (read-only)."""
    return _static_of(np.ascontiguousarray(params6, dtype=float).tobytes())


@functools.lru_cache(maxsize=256)
def _static_of(params6: bytes) -> np.ndarray:
    """The simulated cell asks for the same few fixed links at every probe read (a session: ~10⁴
    reads), and scipy's rotation costs more than the rest of the chain: each distinct transform is
    built once, by the same code, so the truth is the same to the last bit."""
    p = np.frombuffer(params6, dtype=float)
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("xyz", p[3:6]).as_matrix()
    T[:3, 3] = p[:3]
    T.setflags(write=False)
    return T


def pose_matrix(pose: np.ndarray) -> np.ndarray:
    """``(..., 4, 4)`` of poses ``(..., 6)`` x, y, z [mm], roll, pitch, yaw [rad] in the documented
    convention, R = Rz(yaw)·Ry(pitch)·Rx(roll) (docs/robot-file.md; the CMM report's poses too)."""
    p = np.asarray(pose, dtype=float)
    flat = p.reshape(-1, 6)
    T = np.broadcast_to(np.eye(4), (len(flat), 4, 4)).copy()
    T[:, :3, :3] = Rotation.from_euler("xyz", flat[:, 3:6]).as_matrix()
    T[:, :3, 3] = flat[:, :3]
    return T.reshape(p.shape[:-1] + (4, 4))


def matrix_pose(T: np.ndarray) -> np.ndarray:
    """The pose ``(..., 6)`` of ``(..., 4, 4)`` in the same convention (pitch within ±90°)."""
    M = np.asarray(T, dtype=float)
    flat = M.reshape(-1, 4, 4)
    out = np.concatenate([flat[:, :3, 3], Rotation.from_matrix(flat[:, :3, :3]).as_euler("xyz")], axis=1)
    return out.reshape(M.shape[:-2] + (6,))


def inverse(T: np.ndarray) -> np.ndarray:
    """The inverse of a rigid transform ``(4, 4)``: (Rᵀ, −Rᵀt)."""
    T = np.asarray(T, dtype=float)
    out = np.eye(4)
    out[:3, :3] = T[:3, :3].T
    out[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return out


def rotation_angle(R: np.ndarray) -> float:
    """The angle [rad] of the rotation ``(3, 3)``: atan2(|axial vector of R − Rᵀ| / 2, (tr R − 1) / 2),
    accurate near 0 and near π alike. The cell asks it at every probe read (is the body's face
    within the head's capture angle?), where scipy's ``from_matrix`` re-orthogonalises first and
    costs as much as the kinematic chain; tests/simulators/test_truth_fast_paths.py holds it to
    scipy's angle within 1e-12 rad."""
    M = np.asarray(R, dtype=float)
    axial = np.array([M[2, 1] - M[1, 2], M[0, 2] - M[2, 0], M[1, 0] - M[0, 1]])
    return float(np.arctan2(np.linalg.norm(axial) / 2.0, (np.trace(M) - 1.0) / 2.0))


def _joint(kind: str, q: np.ndarray) -> np.ndarray:
    """``(n, 4, 4)`` of the joint motion for joint values ``q`` ``(n,)`` [rad | mm]."""
    T = np.broadcast_to(np.eye(4), (len(q), 4, 4)).copy()
    if kind == "revolute":
        T[:, :3, :3] = Rotation.from_rotvec(np.outer(q, [0.0, 0.0, 1.0])).as_matrix()
    elif kind == "prismatic":
        T[:, 2, 3] = q
    else:
        raise ValueError(f"unknown joint kind {kind!r}")
    return T


def true_forward(joint_kinds: Sequence[str | None], params: np.ndarray, joints: np.ndarray,
                 setup: bool = True) -> np.ndarray:
    """World←tool ``(n, 4, 4)`` of the true robot.

    ``joint_kinds``: per transform, ``None`` (set-up, tool, fixed links), ``"revolute"`` or
    ``"prismatic"``; ``params``: ``(6 · len(joint_kinds),)`` [mm, rad], transform by transform;
    ``joints``: ``(n, g)`` [rad | mm], g the number of joint transforms. ``setup=False`` leaves
    out the first transform (the robot's base frame, where a controller works).
    """
    p = np.asarray(params, dtype=float).reshape(len(joint_kinds), 6)
    q = np.atleast_2d(np.asarray(joints, dtype=float))
    n_joints = sum(kind is not None for kind in joint_kinds)
    if q.shape[-1] != n_joints:
        raise ValueError(f"expected {n_joints} joint values per row, got shape {q.shape}")
    T = np.broadcast_to(np.eye(4), (q.shape[0], 4, 4)).copy()
    j = 0
    for t, kind in enumerate(joint_kinds):
        if t == 0 and not setup:
            continue
        T = T @ _static(p[t])
        if kind is not None:
            T = T @ _joint(kind, q[:, j])
            j += 1
    return T
