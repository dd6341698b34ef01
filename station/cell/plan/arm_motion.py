"""An articulated arm's moves at a measuring point (issue 9), which its plan, the travel vias, the
whole plan's collision check and the runner all command: the retract along the corner's outward
diagonal by ``[plan] clearance_mm`` (:func:`retract_pose`), the pose short of the target from which
every joint arrives from one side (:func:`preload_offset`), the re-centring on a corner
(:func:`recentred`), and the inverse kinematics that follows a small pose change from known joints
(:func:`follow_ik`: the retract, a via's lift, the re-centring). :data:`LIMIT_MARGIN_RAD` is how far
inside the soft limits every planned pose stays.

It imports no other planner module: the plan (:mod:`station.cell.plan.articulated`), the vias and
the collision check stand above it.
"""

from __future__ import annotations

import numpy as np

from station.cell.config.cell_config import CellConfig
from station.cell.plan.assembly import nominal_contact
from station.core.kinematics.forward import forward, joint_jacobian
from station.core.kinematics.model import RobotModel
from station.core.kinematics.transforms import invert, pose_error
from station.errors import UnreachableError

__all__ = ["OUTWARD_DIAGONAL", "LIMIT_MARGIN_RAD", "follow_ik", "retract_poses", "retract_pose", "retract_from",
           "recentred", "preload_offset", "motion_poses"]

#: the corner's space diagonal pointing out of the cube, in MPKS (the cube lies in x, y ≥ 0, z ≤ 0)
OUTWARD_DIAGONAL = np.array([-1.0, -1.0, 1.0]) / np.sqrt(3.0)
#: joints stay this far inside the soft limits at every planned pose [rad]: room for the
#: approach offsets and for the correction of the compensated targets
LIMIT_MARGIN_RAD = np.deg2rad(3.0)

def follow_ik(model: RobotModel, T_base: np.ndarray, q0: np.ndarray, params=None,
             tol_mm: float = 1e-7, max_iter: int = 60) -> tuple[np.ndarray, np.ndarray]:
    """Follow a small pose change from known joints: damped least squares from ``q0 (n, g)`` to
    ``T_base (n, 4, 4)`` (robot base frame), so the configuration of ``q0`` is kept (the retract
    and re-centring moves; a target far from ``q0`` needs :func:`station.core.kinematics.ik.solve_ik`).
    Returns the joints ``(n, g)`` and a mask ``(n,)`` of the rows that converged (position within
    ``tol_mm``, orientation within 1e-9 rad); limits are not checked."""
    Tt = np.asarray(T_base, dtype=float).reshape(-1, 4, 4)
    q = np.array(q0, dtype=float).reshape(len(Tt), model.n_joints)
    w = np.array([1.0, 1.0, 1.0, 500.0, 500.0, 500.0])
    eye = np.eye(model.n_joints)
    for _ in range(max_iter):
        res = joint_jacobian(model, q, params, setup=False)
        err = pose_error(res.T, Tt) * w
        J = res.J * w[:, None]
        JT = np.swapaxes(J, -1, -2)
        lam = 1e-6 + 1e-4 * np.minimum(np.sum(err**2, axis=-1), 1e4)[:, None, None]
        dq = np.linalg.solve(JT @ J + lam * eye, -(JT @ err[..., None]))[..., 0]
        dq = np.clip(dq, -0.5, 0.5)
        q = q + dq
        if np.max(np.abs(dq)) < 1e-12:
            break
    e = pose_error(forward(model, q, params, setup=False), Tt)
    ok = (np.linalg.norm(e[:, :3], axis=1) < tol_mm) & (np.linalg.norm(e[:, 3:], axis=1) < 1e-9) \
        & np.all(np.isfinite(q), axis=1)
    return q, ok


def retract_poses(cfg: CellConfig, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`retract_pose` of every row of ``q (n, g)``: the joints ``(n, g)`` and a mask ``(n,)``
    of the rows the IK reached."""
    q = np.asarray(q, dtype=float).reshape(-1, cfg.model.n_joints)
    T = forward(cfg.model, q, setup=False)
    M = nominal_contact(cfg)
    shift = np.eye(4)
    shift[:3, 3] = M[:3, :3] @ OUTWARD_DIAGONAL * cfg.plan.clearance_mm
    return follow_ik(cfg.model, T @ shift, q)


def retract_pose(cfg: CellConfig, q: np.ndarray) -> np.ndarray:
    """Joints ``(g,)`` with the head backed off from ``q`` along the corner's outward diagonal by
    ``[plan] clearance_mm`` (the head's orientation kept), by IK from ``q``."""
    q = np.asarray(q, dtype=float)
    sol, ok = retract_poses(cfg, q[None])
    if not ok[0]:
        raise UnreachableError(f"the retract pose {cfg.plan.clearance_mm:g} mm off the point is not reachable "
                               f"from joints {np.round(np.degrees(q), 2).tolist()} deg; the motion was not "
                               f"commanded. Reduce [plan] clearance_mm or move the body")
    return sol[0]


def retract_from(cfg: CellConfig, q: np.ndarray) -> np.ndarray:
    """Retract from where the robot stands: :func:`retract_pose` when the head at ``q`` touches a
    measuring point (its contact within half the clearance of one), else ``q`` unchanged (so a
    second retract, or one from a travel pose, does not move)."""
    q = np.asarray(q, dtype=float)
    contact = forward(cfg.model, q[None], setup=True)[0] @ nominal_contact(cfg)
    d = np.linalg.norm(cfg.body_points[:, :3, 3] - contact[:3, 3], axis=1)
    if d.size == 0 or float(d.min()) > 0.5 * cfg.plan.clearance_mm:
        return q
    return retract_pose(cfg, q)


def recentred(cfg: CellConfig, q: np.ndarray, M_measured: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Re-centring: the joints ``(g,)`` and base←head ``(4, 4)`` that bring the measured contact
    ``M_measured`` (MPKS in MKKS) back to the one planned at ``q`` (the nearest measuring point
    seen from the nominal head at ``q``, its orientation kept), by IK from ``q``."""
    q = np.asarray(q, dtype=float)
    T_world = forward(cfg.model, q[None], setup=True)[0]
    contact = T_world @ nominal_contact(cfg)
    j = int(np.argmin(np.linalg.norm(cfg.body_points[:, :3, 3] - contact[:3, 3], axis=1)))
    M_target = invert(T_world) @ cfg.body_points[j]
    T_new = forward(cfg.model, q[None], setup=False)[0] @ M_measured @ invert(M_target)
    sol, ok = follow_ik(cfg.model, T_new[None], q[None])
    if not ok[0]:
        raise UnreachableError("re-centring the head needs a pose the inverse kinematics does not reach; "
                               "the motion was not commanded. Check the cell's set-up and body")
    return sol[0], T_new


def preload_offset(cfg: CellConfig, direction: int = 1) -> np.ndarray:
    """Joint offsets ``(g,)`` of the pose short of the target (``q - offset``) from which every
    joint arrives at it from one side: ``approach_deg`` per revolute, ``approach_mm`` per
    prismatic joint."""
    off = [np.deg2rad(cfg.plan.approach_deg) if k == "revolute" else cfg.plan.approach_mm
           for k in cfg.model.joint_types]
    return direction * np.array(off)


def motion_poses(cfg: CellConfig, q: np.ndarray, direction: int = 1, retract: np.ndarray | None = None
                 ) -> list[np.ndarray]:
    """Every joint vector a measurement at ``q`` commands: retract, short of the target, target
    (and the retract after reading, the same as before); ``retract``: the retract pose when known."""
    return [retract_pose(cfg, q) if retract is None else retract, q - preload_offset(cfg, direction), q]
