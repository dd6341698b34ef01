"""The measurement plan for an articulated arm (a six-axis robot; issue 9).

A SCARA fixes the head's orientation at a cube corner up to the wrist angle; an articulated arm
can reach the same corner with the head turned, and in several arm configurations. The wrist
parameters become observable only when the head's orientation varies, so at every cube corner
the plan visits:

* several **head orientations** (:func:`head_orientations`): the nominal contact, rotations
  about the corner's space diagonal and tilts about two axes normal to it, all about the corner
  itself and well inside the probes' capture range (a few degrees: each probe then reads a
  millimetre or two of its ±5 mm stroke at the nominal pose);
* every **arm configuration** the robot file's limits allow (shoulder front/back, elbow up/down,
  wrist flipped or not: :func:`station.core.ik.configuration`), each solved by
  :func:`station.core.ik.solve_ik` on the full nominal model, which chooses deterministically
  and away from the limits and the wrist singularity; a candidate must also stay
  :data:`LIMIT_MARGIN_RAD` inside the cell's soft limits.

Motion per measurement (:func:`retract_pose`, :func:`preload_offset`): the head retracts along the
corner's diagonal, away from the cube, by ``[plan] clearance_mm``; from there it moves to the
target short of ``[plan] approach_deg`` in every joint, then to the target, so that each joint
arrives from one side (backlash becomes a repeatable offset). Every motion pose of every candidate
passes the :class:`~station.cell.safety.MotionGuard` before anything moves.

Candidates with the nominal head orientation are the verification pool (every k-th held out, per
configuration); the others are identification candidates, optionally reduced by the greedy
D-optimal :func:`station.cell.plan_common.select_d_optimal`, then ordered to keep travel short
(nearest neighbour in joint space, configuration changes last).

The step's ``elbow`` field holds the configuration code (:func:`configuration_code`): its sign is
the elbow (up +, down −), its magnitude ``1 + 2·wrist flipped + 4·shoulder back``; ``+1`` is the
usual front, elbow up, wrist not flipped configuration. Cartesian commands carry its sign only;
the controller keeps the configuration of the joints it stands at.
"""

from __future__ import annotations

import numpy as np

from station.cell.config import CellConfig
from station.cell.plan_common import Target, assemble_plan, head_targets_world, hold_out, nominal_contact
from station.cell.safety import MotionGuard
from station.core.kinematics import forward, joint_jacobian
from station.core.model import RobotModel
from station.core.transforms import invert, pose_error, pose_to_matrix, rotation_exp
from station.errors import ConfigError, UnreachableError

__all__ = ["head_orientations", "follow_ik", "configuration_code", "retract_pose", "retract_poses", "retract_from", "recentred",
           "preload_offset", "motion_poses", "articulated_candidates", "build_articulated_plan",
           "order_by_travel", "OUTWARD_DIAGONAL"]

#: the corner's space diagonal pointing out of the cube, in MPKS (the cube lies in x, y ≥ 0, z ≤ 0)
OUTWARD_DIAGONAL = np.array([-1.0, -1.0, 1.0]) / np.sqrt(3.0)
#: rotations about the corner's diagonal [deg] (each probe moves ≤ 0.3 mm/deg)
DIAGONAL_TURNS_DEG = (-4.0, 4.0)
#: tilts about the two axes normal to the diagonal [deg] (each probe moves ≤ 0.7 mm/deg)
TILTS_DEG = (-2.0, 2.0)
#: joints stay this far inside the soft limits at every planned pose [rad]: room for the
#: approach offsets and for the correction of the compensated targets
LIMIT_MARGIN_RAD = np.deg2rad(3.0)


def head_orientations(cfg: CellConfig) -> np.ndarray:
    """``(m, 4, 4)`` pose of MPKS in MKKS for every head orientation the plan visits at a corner
    (rotations about the corner itself); index 0 is the nominal contact."""
    M0 = nominal_contact(cfg)
    d = OUTWARD_DIAGONAL
    n1 = np.cross(d, [0.0, 0.0, 1.0])
    n1 /= np.linalg.norm(n1)
    n2 = np.cross(d, n1)
    out = [M0]
    for axis, angles in ((d, DIAGONAL_TURNS_DEG), (n1, TILTS_DEG), (n2, TILTS_DEG)):
        for a in angles:
            R = np.eye(4)
            R[:3, :3] = rotation_exp(axis * np.deg2rad(a))
            out.append(M0 @ R)
    return np.stack(out)


# --- inverse kinematics -----------------------------------------------------------------------

def follow_ik(model: RobotModel, T_base: np.ndarray, q0: np.ndarray, params=None,
             tol_mm: float = 1e-7, max_iter: int = 60) -> tuple[np.ndarray, np.ndarray]:
    """Follow a small pose change from known joints: damped least squares from ``q0 (n, g)`` to
    ``T_base (n, 4, 4)`` (robot base frame), so the configuration of ``q0`` is kept (the retract
    and re-centring moves; a target far from ``q0`` needs :func:`station.core.ik.solve_ik`).
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


def configuration_code(conf) -> int:
    """The step's ``elbow`` field for a configuration ``(shoulder, elbow, wrist)`` (signs; 0 counts
    as +): sign = elbow, magnitude ``1 + 2·(wrist = −1) + 4·(shoulder = −1)``."""
    shoulder, elbow, wrist = (int(v) for v in conf)
    return (-1 if elbow < 0 else 1) * (1 + 2 * (wrist < 0) + 4 * (shoulder < 0))


def _within(cfg: CellConfig, q: np.ndarray) -> np.ndarray:
    """``(n,)``: rows of ``q (n, g)`` inside the soft limits with :data:`LIMIT_MARGIN_RAD` (revolute)."""
    rev = np.array([t == "revolute" for t in cfg.model.joint_types])
    m = LIMIT_MARGIN_RAD * rev
    lim = cfg.soft_limits
    return np.all(np.isfinite(q), axis=-1) & np.all((q >= lim[:, 0] + m) & (q <= lim[:, 1] - m), axis=-1)


def _configurations(model: RobotModel) -> tuple:
    """The configurations to try: the eight named ones of a six-axis arm (six revolute joints),
    else one (the solver's choice)."""
    from station.core.ik import ALL_ARM_CONFIGS

    six_r = model.n_joints == 6 and all(t == "revolute" for t in model.joint_types)
    return ALL_ARM_CONFIGS if six_r else (None,)


# --- motion -----------------------------------------------------------------------------------

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


# --- the plan ---------------------------------------------------------------------------------

def articulated_candidates(cfg: CellConfig):
    """(candidates, orientations, rejected): a :class:`station.cell.plan_common.Target` for every point ×
    head orientation × configuration whose every motion pose passes the guard, the orientation
    index of each (0 = nominal), and (point id, configuration code, reason) of those rejected.
    Inverse kinematics: :func:`station.core.ik.solve_ik` on the nominal model per configuration
    (its deterministic choice), the turned heads near the nominal head's solution."""
    from station.core.ik import solve_ik

    model = cfg.model
    guard = MotionGuard(cfg.soft_limits)
    R_inv = invert(pose_to_matrix(model.nominal[:6]))
    Ms = head_orientations(cfg)
    m = len(Ms)
    T0 = R_inv[None] @ head_targets_world(cfg)
    cands: list = []
    orient: list[int] = []
    rejected: list[tuple[str, int, str]] = []
    for conf in _configurations(model):
        r0 = solve_ik(model, T0, configuration=conf)
        code = 1 if conf is None else configuration_code(conf.as_array())
        pts = [j for j in range(len(T0)) if r0.ok[j] and _within(cfg, r0.joints[j][None])[0]]
        if not pts:
            continue
        heads = cfg.body_points[pts][:, None] @ invert(Ms)[None]  # (p, m, 4, 4) KKS←MKKS
        near = np.repeat(r0.joints[pts], m, axis=0)
        rk = solve_ik(model, R_inv[None] @ heads.reshape(-1, 4, 4), configuration=conf, near=near)
        inside = _within(cfg, rk.joints)
        retract, reached = retract_poses(cfg, np.nan_to_num(rk.joints))
        for a, j in enumerate(pts):
            pid = cfg.point_ids[j]
            for k in range(m):
                i = a * m + k
                what = f"{pid} configuration {code:+d} orientation {k}"
                if not (rk.ok[i] and inside[i]):
                    why = rk.reason[i] or "too close to the soft limits"
                    rejected.append((pid, code, f"{what}: {why}"))
                    continue
                q = rk.joints[i]
                try:
                    if not reached[i]:
                        raise UnreachableError(f"{what}: the retract pose {cfg.plan.clearance_mm:g} mm off the point "
                                               f"is not reachable")
                    for qq in motion_poses(cfg, q, retract=retract[i]):
                        guard.check_joints(qq, what)
                except UnreachableError as exc:
                    rejected.append((pid, code, str(exc)))
                    continue
                cands.append(Target(j, pid, code, heads[a, k], q))
                orient.append(k)
    return cands, orient, rejected


def order_by_travel(targets: list, weight_mm_per_rad: float = 500.0) -> list:
    """Greedy nearest neighbour in joint space (rad weighted as ``weight_mm_per_rad``, mm as mm),
    a change of configuration counted as a long move."""
    if not targets:
        return targets
    g = len(targets[0].joints)
    w = np.full(g, weight_mm_per_rad)
    q = np.array([t.joints for t in targets])
    codes = np.array([t.elbow for t in targets])
    left = list(range(len(targets)))
    order = [left.pop(0)]
    while left:
        cur = order[-1]
        d = np.sum(np.abs(q[left] - q[cur]) * w, axis=1) + np.where(codes[left] == codes[cur], 0.0, 1e5)
        order.append(left.pop(int(np.argmin(d))))
    return [targets[i] for i in order]


def build_articulated_plan(cfg: CellConfig):
    """The :class:`station.cell.plan_common.Plan` of an articulated arm (see the module docstring)."""
    if cfg.plan.both_directions:
        raise ConfigError("plan.both_directions: the reversal measurement is planned for SCARA robots only; "
                          "set it to false for an articulated arm")
    cands, orient, rejected = articulated_candidates(cfg)
    if not cands:
        raise ConfigError("no measuring point is reachable within the soft limits; check [robot].setup and [limits]")
    nominal = [i for i, k in enumerate(orient) if k == 0]
    codes = tuple(sorted({cands[i].elbow for i in nominal}, key=lambda c: (abs(c), -c)))
    held_local = hold_out([cands[i] for i in nominal], cfg.plan.verification_every, codes)
    held = {nominal[i] for i in held_local}
    verification = tuple(c for i, c in enumerate(cands) if i in held)
    ident = [c for i, c in enumerate(cands) if i not in held]
    return assemble_plan(cfg, ident, verification, list(rejected), order_by_travel)
