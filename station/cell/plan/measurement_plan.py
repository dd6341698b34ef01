"""The measurement plan over the calibration body (issue: measuring points × elbow
configurations × wrist angles × heights).

Each body point is a cube corner at a known height whose frame fixes the wrist angle at which
the 3-2-1 head fits it, so the plan's dimensions are: points (their corners carry the wrist
angles and pillars the heights) × elbows. Every candidate is checked for reachability and the
soft limits — including the approach and retract poses — before any motion. Every k-th
candidate is held out for verification. Identification steps are ordered to keep joint travel
short; optionally only the most informative are kept (greedy D-optimality on the identification
Jacobian of the minimal parameter set).
"""

from __future__ import annotations

import weakref

import numpy as np

from station.cell.config.cell_config import CellConfig
from station.cell.limits.joint_text import joint_value
from station.cell.limits.motion_guard import MotionGuard
from station.cell.plan.arm_motion import preload_offset, retract_from, retract_pose
from station.cell.plan.articulated import build_articulated_plan
from station.cell.plan.assembly import (
    Plan,
    Target,
    assemble_plan,
    head_targets_world,
    hold_out,
    nominal_contact,
    select_d_optimal,
)
from station.cell.plan.collision_shapes import head_depth_mm
from station.core.kinematics.forward import scara_ik
from station.core.kinematics.transforms import invert
from station.errors import ConfigError, UnreachableError

# The shared pieces live in station.cell.plan.assembly (both planners import them); they stay importable from here.
__all__ = ["Target", "Plan", "nominal_contact", "head_targets_world", "assemble_plan", "hold_out",
           "select_d_optimal", "approach_offsets", "retract_offset", "travel_joints", "retracted",
           "check_joints", "joints_for", "REMEASURE_STEP", "approach_pose", "above_offset", "all_motion_poses",
           "widest_motion_poses", "build_plan", "order_by_travel", "point_joints", "reach_reason", "limit_reason",
           "candidate_reason", "check_enough_poses", "MIN_IDENTIFICATION_TARGETS"]


def approach_offsets(cfg: CellConfig, direction: int = 1) -> np.ndarray:
    """Joint offsets (g,) subtracted from a target so the last move of every joint runs in
    ``direction`` (backlash becomes a repeatable offset); prismatic joints come from above."""
    off = []
    for kind in cfg.model.joint_types:
        off.append(np.deg2rad(cfg.plan.approach_deg) if kind == "revolute" else -cfg.plan.approach_mm)
    return direction * np.array(off)


def retract_offset(cfg: CellConfig) -> np.ndarray:
    """Joint offset (g,) that lifts the head by the clearance (prismatic joints only). An
    articulated arm instead stands short of the target by the approach offset in every joint
    (``q + retract_offset`` is its last pose before the touch; see :mod:`station.cell.plan.articulated`)."""
    if not cfg.model.is_scara:
        return -preload_offset(cfg)
    return np.array([cfg.plan.clearance_mm if k == "prismatic" else 0.0 for k in cfg.model.joint_types])


# Computed once per configuration object; weak keys, so a configuration's entry goes with it.
_TRAVEL: weakref.WeakKeyDictionary[CellConfig, np.ndarray] = weakref.WeakKeyDictionary()


def travel_joints(cfg: CellConfig) -> np.ndarray:
    """Per joint, the travel position of the prismatic joints (NaN for the others): the head's
    lowest point the clearance above the highest reachable measuring point, capped by the soft limit. Lateral moves happen
    only at this height, so the head never sweeps through a cube, wherever a crash left the robot.
    A point out of reach is left out here (the plan names it); with none in reach, the soft limit."""
    hit = _TRAVEL.get(cfg)
    if hit is not None:
        return hit
    out = np.full(cfg.model.n_joints, np.nan)
    if cfg.model.is_scara:  # an articulated arm retracts along the corner's diagonal instead
        q = point_joints(cfg, cfg.plan.elbows[0])
        # the clearance is the head's lowest point's above the highest cube, not the contact's: a side
        # probe hanging below the corner would otherwise drag over a neighbouring cube (issue 40)
        lift = cfg.plan.clearance_mm + head_depth_mm(cfg)
        for j, kind in enumerate(cfg.model.joint_types):
            if kind == "prismatic":
                col = q[:, j][np.isfinite(q[:, j])]
                top = float(col.max()) + lift if col.size else np.inf
                out[j] = min(cfg.soft_limits[j, 1], top)
    out.setflags(write=False)
    _TRAVEL[cfg] = out
    return out


def point_joints(cfg: CellConfig, elbow: int) -> np.ndarray:
    """Nominal joints (n_points, g) of every measuring point with ``elbow``; NaN rows for the
    points out of the arm's reach (each point solved on its own, so one cannot fail the rest)."""
    heads = head_targets_world(cfg)
    out = np.full((len(heads), cfg.model.n_joints), np.nan)
    for j in range(len(heads)):
        try:
            out[j] = joints_for(cfg, heads[j], elbow)[0]
        except UnreachableError:
            continue
    return out


def reach_reason(cfg: CellConfig, head_world: np.ndarray) -> str:
    """Why a SCARA cannot put the head at ``head_world`` (4, 4): which radius about axis 1 the
    wrist misses, and by how much [mm]."""
    from station.core.kinematics.forward import scara_closed_form, scara_reach_margin
    from station.core.kinematics.transforms import pose_to_matrix

    T_base = invert(pose_to_matrix(cfg.model.nominal[:6]))[None] @ np.asarray(head_world).reshape(-1, 4, 4)
    margin = float(scara_reach_margin(cfg.model, T_base)[0])
    _, c_beta = scara_closed_form(cfg.model, T_base, 1)
    side = "beyond the stretched arm" if float(c_beta[0]) > 0 else "inside the folded arm"
    return f"out of the arm's reach by {abs(margin):.1f} mm ({side}); move the point or the robot ([robot].setup)"


def limit_reason(cfg: CellConfig, q: np.ndarray) -> str | None:
    """None when every joint of ``q`` is inside the soft limits; else the first joint outside:
    which limit and by how much, in the units of [limits] (deg | mm)."""
    lo, hi = cfg.soft_limits[:, 0], cfg.soft_limits[:, 1]
    for j, kind in enumerate(cfg.model.joint_types):
        v = float(q[j])
        if not np.isfinite(v):
            return f"joint {j + 1} has no solution"
        if v < lo[j] or v > hi[j]:
            side, limit = ("lower", float(lo[j])) if v < lo[j] else ("upper", float(hi[j]))
            return (f"joint {j + 1} = {joint_value(v, kind)} is {joint_value(abs(v - limit), kind)} beyond its "
                    f"{side} soft limit {joint_value(limit, kind)}")
    return None


def retracted(cfg: CellConfig, q: np.ndarray) -> np.ndarray:
    """``q`` with every prismatic joint raised to the travel height (never lowered); an
    articulated arm backs the head off along the corner's diagonal by the clearance."""
    if not cfg.model.is_scara:
        return retract_from(cfg, q)
    t = travel_joints(cfg)
    return np.where(np.isnan(t), q, np.maximum(q, np.nan_to_num(t, nan=-np.inf)))


def check_joints(cfg: CellConfig, q: np.ndarray, what: str) -> None:
    """Refuse (UnreachableError) any joint vector outside the configured soft limits (the
    runner's :class:`~station.cell.limits.motion_guard.MotionGuard`, applied to the plan before any motion)."""
    MotionGuard(cfg.soft_limits, joint_types=cfg.model.joint_types).check_joints(q, what)


def joints_for(cfg: CellConfig, head_world: np.ndarray, elbow: int, setup_world_base=None) -> np.ndarray:
    """Nominal-model joints (n, g) that put the head at ``head_world`` (n, 4, 4)."""
    R = cfg.model.nominal[:6] if setup_world_base is None else setup_world_base
    from station.core.kinematics.transforms import pose_to_matrix

    T_base = invert(pose_to_matrix(R))[None] @ np.asarray(head_world).reshape(-1, 4, 4)
    return scara_ik(cfg.model, T_base, elbow, setup=False, check_limits=False)


#: a re-measure of a touch approaches with this much more offset per attempt: a path no other
#: visit or cycle takes, so the repeat is a fresh touch, not a replay of the one that disagreed
REMEASURE_STEP = 0.037


def approach_pose(cfg: CellConfig, q: np.ndarray, direction: int = 1, cycle: int = 0,
                  remeasure: int = 0) -> np.ndarray:
    """Where a measurement at ``q`` starts its final approach: every revolute joint offset
    against its direction of arrival, the quill at travel height. ``cycle`` varies the offset a
    little between repetitions (from the same side), ``remeasure`` (the touch's re-measure
    attempt) a little more. An articulated arm: the target's retract pose (backed off along the
    corner's diagonal); its offset comes right before the touch."""
    if not cfg.model.is_scara:
        return retract_pose(cfg, q)
    a = approach_offsets(cfg, direction) * (1.0 + 0.25 * cycle + REMEASURE_STEP * remeasure)
    return retracted(cfg, np.where(retract_offset(cfg) > 0, q, q - a))


def above_offset(cfg: CellConfig, cycle: int = 0, remeasure: int = 0) -> np.ndarray:
    """Joint offset (g,) of the pose above the point a SCARA's touch comes down from."""
    return retract_offset(cfg) * (1.0 + 0.1 * cycle + REMEASURE_STEP * remeasure)


#: the share of the approach offset a SCARA's Cartesian touch keeps on the approach side above the
#: point: the last move then sweeps a quarter of it (0.125° at 0.5°, ten times the simulated arm's
#: backlash at 450 mm) while it comes down; the runner keeps it to the joints the table corrects to
#: (station.cell.run.runner.AboveCartesian), so it arrives from the approach side whatever the correction
CARTESIAN_SIDE = 0.25


def cartesian_above(cfg: CellConfig, q: np.ndarray, direction: int = 1, cycle: int = 0,
                    remeasure: int = 0) -> np.ndarray:
    """Where a SCARA's Cartesian touch (verification, the table active) comes down from: above the
    point by the clearance (at most as high as its approach, which the soft limits hold), its
    revolute joints still :data:`CARTESIAN_SIDE` of the approach offset on the approach side (of the
    nominal joints here; the runner adds the active table's correction, which the plan cannot know).
    Straight from the approach, the head swept the whole offset while it came down and a probe's
    housing grazed a face (issue 40: the integrator's SCARA, refused by the simulated controller's
    own collision check)."""
    approach = approach_pose(cfg, q, direction, cycle, remeasure)
    lift = retract_offset(cfg) > 0
    above = q + above_offset(cfg, cycle, remeasure)
    side = q + CARTESIAN_SIDE * (approach - q)
    return np.where(lift, np.minimum(above, approach), side)


def all_motion_poses(cfg: CellConfig, q: np.ndarray, direction: int = 1) -> list[np.ndarray]:
    """Every joint vector a measurement at ``q`` commands (approach, above the point, target)."""
    return [approach_pose(cfg, q, direction), q + retract_offset(cfg), q]


def widest_motion_poses(cfg: CellConfig, q: np.ndarray, direction: int = 1) -> list[np.ndarray]:
    """The approach and the pose above the point farthest from ``q`` that a run commands: the
    last repetition's (identification repeats, verification cycles) with every re-measure. The
    soft limits are a box, so every approach in between lies inside when these and ``q`` do."""
    last = max(cfg.plan.repeats, cfg.plan.verification_cycles) - 1
    n = cfg.plan.remeasure_attempts
    return [approach_pose(cfg, q, direction, last, n), q + above_offset(cfg, last, n)]


#: what each of a candidate's motion poses is, in the order all_motion_poses + widest_motion_poses give them
_POSE_NAMES = ("its approach", "the pose above it", "the touch", "the last repetition's approach",
               "the last repetition's pose above it")


def candidate_reason(cfg: CellConfig, q: np.ndarray, label: str) -> str | None:
    """None when every pose a measurement at ``q`` commands (both directions when planned) is
    inside the soft limits; else the first that is not, named with the joint and the amount."""
    for direction in ((1, -1) if cfg.plan.both_directions else (1,)):
        where = label + ("" if direction == 1 else " (reverse approach)")
        poses = (*all_motion_poses(cfg, q, direction), *widest_motion_poses(cfg, q, direction))
        for name, qq in zip(_POSE_NAMES, poses):
            why = limit_reason(cfg, qq)
            if why is not None:
                return f"{where}: {name} leaves the soft limits, {why}"
    return None


def build_plan(cfg: CellConfig) -> Plan:
    """The plan over every (point, elbow) that can be measured; every other is left out with its
    reason (out of reach, or a pose outside the soft limits: joint, side and amount). Too few left
    for the identifiable set is a :class:`ConfigError` saying how many are needed."""
    if not cfg.model.is_scara:  # head orientations × arm configurations (issue 9)
        return build_articulated_plan(cfg)
    heads = head_targets_world(cfg)
    cands, rejected = [], []
    for elbow in cfg.plan.elbows:
        q_all = point_joints(cfg, elbow)
        for j, pid in enumerate(cfg.point_ids):
            if not np.all(np.isfinite(q_all[j])):
                rejected.append((pid, elbow, f"{pid} elbow {elbow:+d}: {reach_reason(cfg, heads[j])}"))
                continue
            why = candidate_reason(cfg, q_all[j], f"{pid} elbow {elbow:+d}")
            if why is not None:
                rejected.append((pid, elbow, why))
                continue
            cands.append(Target(j, pid, elbow, heads[j], q_all[j]))
    order = {pid: i for i, pid in enumerate(cfg.point_ids)}  # points in the body's order, then elbows
    cands.sort(key=lambda c: (order[c.point_id], cfg.plan.elbows.index(c.elbow)))
    rejected.sort(key=lambda r: (order[r[0]], cfg.plan.elbows.index(r[1])))
    if not cands:
        raise ConfigError("no measuring point is reachable within the soft limits: "
                          + "; ".join(why for _, _, why in rejected)
                          + ". Check [robot].setup, [limits] and the body's points")
    held = hold_out(cands, cfg.plan.verification_every, cfg.plan.elbows)
    verification = tuple(c for i, c in enumerate(cands) if i in held)
    ident = [c for i, c in enumerate(cands) if i not in held]
    check_enough_poses(cfg, ident, len(rejected))
    return assemble_plan(cfg, ident, verification, rejected, order_by_travel)


def check_enough_poses(cfg: CellConfig, ident: list[Target], n_rejected: int) -> None:
    """Refuse (ConfigError) identification targets too few for the identifiable set: fewer
    pose rows than parameters with redundancy, or a rank below the minimal model's."""
    from station.core.identification.identifiability import analyze
    from station.core.measurement.measurements import synthetic_set

    p = cfg.model.minimal_param_count  # 4R + 2P + 6 (Everett/Hollerbach): what a well-spread plan identifies
    needed = max(MIN_IDENTIFICATION_TARGETS, -(-2 * p // 6))  # twice as many pose rows as parameters
    left_out = f" ({n_rejected} (point, elbow) left out, listed by 'station plan')" if n_rejected else ""
    if len(ident) < needed:
        raise ConfigError(f"only {len(ident)} identification targets can be measured{left_out}; the {p} parameters "
                          f"of the minimal model need at least {needed}: bring more points within reach and the "
                          f"soft limits, or add points to the body")
    q = np.array([t.joints for t in ident])
    data = synthetic_set(cfg.model, "pose", q, cfg.model.nominal, sigma=cfg.identification.pose_sigma())
    a = analyze(cfg.model, data, describe=False)  # the structural rank: [identification].fix does not lower it
    if a.rank < p:
        raise ConfigError(f"the {len(ident)} identification targets that can be measured{left_out} identify only "
                          f"{a.rank} of the {p} parameters of the minimal model: spread the reachable points over "
                          f"more heights, wrist angles and both elbows")


#: fewest identification targets a plan may hold, whatever the parameter count
MIN_IDENTIFICATION_TARGETS = 5


def order_by_travel(targets: list[Target]) -> list[Target]:
    """Greedy nearest neighbour in joint space (rad weighted as 500 mm, roughly the arm)."""
    if not targets:
        return targets
    g = len(targets[0].joints)
    w = np.array([500.0, 500.0, 1.0, 100.0]) if g == 4 else np.full(g, 500.0)
    left = list(range(len(targets)))
    order = [left.pop(0)]
    while left:
        cur = targets[order[-1]].joints
        d = [np.sum(np.abs((targets[i].joints - cur) * w)) + (0 if targets[i].elbow == targets[order[-1]].elbow else 1e4) for i in left]
        order.append(left.pop(int(np.argmin(d))))
    return [targets[i] for i in order]
