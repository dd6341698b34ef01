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

from station.cell.config import CellConfig
from station.cell.plan_articulated import build_articulated_plan, preload_offset, retract_from, retract_pose
from station.cell.plan_common import (
    Plan,
    Target,
    assemble_plan,
    head_targets_world,
    hold_out,
    nominal_contact,
    select_d_optimal,
)
from station.cell.safety import MotionGuard
from station.core.kinematics import scara_ik
from station.core.transforms import invert
from station.errors import ConfigError, UnreachableError

# The shared pieces live in plan_common (both planners import them); they stay importable from here.
__all__ = ["Target", "Plan", "nominal_contact", "head_targets_world", "assemble_plan", "hold_out",
           "select_d_optimal", "approach_offsets", "retract_offset", "travel_joints", "retracted",
           "check_joints", "joints_for", "REMEASURE_STEP", "approach_pose", "above_offset", "all_motion_poses",
           "widest_motion_poses", "build_plan", "order_by_travel"]


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
    (``q + retract_offset`` is its last pose before the touch; see :mod:`station.cell.plan_articulated`)."""
    if not cfg.model.is_scara:
        return -preload_offset(cfg)
    return np.array([cfg.plan.clearance_mm if k == "prismatic" else 0.0 for k in cfg.model.joint_types])


# Computed once per configuration object; weak keys, so a configuration's entry goes with it.
_TRAVEL: weakref.WeakKeyDictionary[CellConfig, np.ndarray] = weakref.WeakKeyDictionary()


def travel_joints(cfg: CellConfig) -> np.ndarray:
    """Per joint, the travel position of the prismatic joints (NaN for the others): the clearance
    above the highest measuring point, capped by the soft limit. Lateral moves happen only at
    this height, so the head never sweeps through a cube, wherever a crash left the robot."""
    hit = _TRAVEL.get(cfg)
    if hit is not None:
        return hit
    if not cfg.model.is_scara:  # an articulated arm retracts along the corner's diagonal instead
        out = np.full(cfg.model.n_joints, np.nan)
        out.setflags(write=False)
        _TRAVEL[cfg] = out
        return out
    heads = head_targets_world(cfg)
    q = joints_for(cfg, heads, cfg.plan.elbows[0])
    out = np.full(cfg.model.n_joints, np.nan)
    for j, kind in enumerate(cfg.model.joint_types):
        if kind == "prismatic":
            out[j] = min(cfg.soft_limits[j, 1], float(q[:, j].max()) + cfg.plan.clearance_mm)
    out.setflags(write=False)
    _TRAVEL[cfg] = out
    return out


def retracted(cfg: CellConfig, q: np.ndarray) -> np.ndarray:
    """``q`` with every prismatic joint raised to the travel height (never lowered); an
    articulated arm backs the head off along the corner's diagonal by the clearance."""
    if not cfg.model.is_scara:
        return retract_from(cfg, q)
    t = travel_joints(cfg)
    return np.where(np.isnan(t), q, np.maximum(q, np.nan_to_num(t, nan=-np.inf)))


def check_joints(cfg: CellConfig, q: np.ndarray, what: str) -> None:
    """Refuse (UnreachableError) any joint vector outside the configured soft limits (the
    runner's :class:`~station.cell.safety.MotionGuard`, applied to the plan before any motion)."""
    MotionGuard(cfg.soft_limits).check_joints(q, what)


def joints_for(cfg: CellConfig, head_world: np.ndarray, elbow: int, setup_world_base=None) -> np.ndarray:
    """Nominal-model joints (n, g) that put the head at ``head_world`` (n, 4, 4)."""
    R = cfg.model.nominal[:6] if setup_world_base is None else setup_world_base
    from station.core.transforms import pose_to_matrix

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


def build_plan(cfg: CellConfig) -> Plan:
    if not cfg.model.is_scara:  # head orientations × arm configurations (issue 9)
        return build_articulated_plan(cfg)
    heads = head_targets_world(cfg)
    cands, rejected = [], []
    for j, pid in enumerate(cfg.point_ids):
        for elbow in cfg.plan.elbows:
            try:
                q = joints_for(cfg, heads[j], elbow)[0]
                for qq in (*all_motion_poses(cfg, q), *widest_motion_poses(cfg, q)):
                    check_joints(cfg, qq, f"{pid} elbow {elbow:+d}")
                if cfg.plan.both_directions:
                    for qq in (*all_motion_poses(cfg, q, -1), *widest_motion_poses(cfg, q, -1)):
                        check_joints(cfg, qq, f"{pid} elbow {elbow:+d} (reverse approach)")
            except UnreachableError as exc:
                rejected.append((pid, elbow, str(exc)))
                continue
            cands.append(Target(j, pid, elbow, heads[j], q))
    if not cands:
        raise ConfigError("no measuring point is reachable within the soft limits; check [robot].setup and [limits]")
    held = hold_out(cands, cfg.plan.verification_every, cfg.plan.elbows)
    verification = tuple(c for i, c in enumerate(cands) if i in held)
    ident = [c for i, c in enumerate(cands) if i not in held]
    return assemble_plan(cfg, ident, verification, rejected, order_by_travel)


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
