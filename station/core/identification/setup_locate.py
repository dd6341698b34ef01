"""The set-up re-estimated from located cube corners (issue 37 §1): arrays in, a pose out.

Each located corner gives the whole set-up on its own: the body point ``P`` (KKS←MPKS, from the
CMM report) equals ``R · T(q) · M`` with ``T(q)`` the nominal base←head pose at the joints read and
``M`` the measured contact (MPKS in MKKS), so ``R = P · (T(q) · M)⁻¹``. The robot's own errors
(tens of µm, arc minutes) make the corners disagree a little; the estimate is their mean: the
translations averaged, the rotations by the chordal mean (the mean matrix projected onto the
rotations). That is a starting guess a few tens of µm good, which is all the plan needs; the
identification fits the set-up properly.
"""

from __future__ import annotations

import numpy as np

from station.core.kinematics.transforms import invert, matrix_to_pose, pose_to_matrix

__all__ = ["setup_from_contacts", "point_shift_mm"]


def setup_from_contacts(body_points: np.ndarray, head_base: np.ndarray, contacts: np.ndarray,
                        roll_pitch: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """The set-up R (world←base, x, y, z [mm], roll, pitch, yaw [rad]) that the located corners
    give: ``body_points (n, 4, 4)`` KKS←MPKS, ``head_base (n, 4, 4)`` base←MKKS (nominal model
    at the joints read), ``contacts (n, 4, 4)`` the measured MPKS in MKKS; n ≥ 1.

    Roll and pitch stay ``roll_pitch`` (the guess's): a corner's measured tilt carries the robot's
    own axis tilts (arc minutes), which over the half metre to the base would move the set-up by
    a millimetre. The yaw comes from the corners' positions (a plane fit) where they lie apart,
    else from the one corner's orientation; the translation is the mean that closes the rest."""
    P = np.asarray(body_points, dtype=float).reshape(-1, 4, 4)
    T = np.asarray(head_base, dtype=float).reshape(-1, 4, 4)
    M = np.asarray(contacts, dtype=float).reshape(-1, 4, 4)
    if not len(P) == len(T) == len(M) or len(P) == 0:
        raise ValueError(f"need as many body points, head poses and contacts (>= 1), got {len(P)}, {len(T)}, {len(M)}")
    corner = T @ M  # base←MPKS as the nominal robot sees each corner
    tilt = pose_to_matrix(np.array([0.0, 0.0, 0.0, roll_pitch[0], roll_pitch[1], 0.0]))[:3, :3]
    a = corner[:, :3, 3] @ tilt.T  # the corners in the base frame, levelled as the guess says
    b = P[:, :3, 3]
    if len(P) >= 2 and float(np.ptp(b[:, :2], axis=0).max()) > SPREAD_MM:
        da, db = a[:, :2] - a[:, :2].mean(axis=0), b[:, :2] - b[:, :2].mean(axis=0)
        yaw = float(np.arctan2(np.sum(da[:, 0] * db[:, 1] - da[:, 1] * db[:, 0]), np.sum(da * db)))
    else:
        r = P[0, :3, :3] @ corner[0, :3, :3].T
        yaw = float(np.arctan2(r[1, 0], r[0, 0]))
    c, s = np.cos(yaw), np.sin(yaw)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ tilt
    t = (b - a @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]).T).mean(axis=0)
    out = np.eye(4)
    out[:3, :3] = rot
    out[:3, 3] = t
    return matrix_to_pose(out)


#: corners farther apart than this [mm] give the yaw by their positions
SPREAD_MM = 50.0


def point_shift_mm(body_points: np.ndarray, setup_a: np.ndarray, setup_b: np.ndarray) -> np.ndarray:
    """``(n,)`` how far [mm] each body point moves in the robot's base frame between two set-ups
    (world←base poses): what a plan made with ``setup_a`` misses by when ``setup_b`` is true."""
    P = np.asarray(body_points, dtype=float).reshape(-1, 4, 4)
    a = invert(pose_to_matrix(np.asarray(setup_a, dtype=float))) @ P
    b = invert(pose_to_matrix(np.asarray(setup_b, dtype=float))) @ P
    return np.linalg.norm(a[:, :3, 3] - b[:, :3, 3], axis=1)
