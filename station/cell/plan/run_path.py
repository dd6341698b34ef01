"""The whole plan's collision check (issue 40): every pose a run commands, in the order it commands
them (:func:`plan_path`: each step's approach, the pose above the point, the touch and the retract,
and the travel vias between two measurements), checked before the first motion by
:func:`station.cell.plan.collision.check_path` (:func:`check_plan`).

It stands above the planners and the vias, whose poses it strings together; the shapes and the check
of a path (:mod:`station.cell.plan.collision`) stand below them, so that the vias can ask whether a
single move is clear.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from station.cell.config.cell_config import CellConfig
from station.cell.plan.arm_motion import retract_poses
from station.cell.plan.assembly import Plan
from station.cell.plan.collision import CollisionReport, check_path, require_fcl
from station.cell.plan.measurement_plan import all_motion_poses, cartesian_above, retract_offset, retracted
from station.cell.plan.via_memo import memo_travel_vias
from station.cell.plan.vias import lifted_many
from station.errors import ConfigError

__all__ = ["plan_path", "check_plan", "VIA_NAMES"]


def plan_path(cfg: CellConfig, plan: Plan, with_upload: bool = True) -> list[tuple[np.ndarray, str, int]]:
    """Every pose a run commands, in order: (joints, what it is, the measuring point it touches),
    the via poses between two measurements included (:func:`station.cell.plan.vias.travel_vias`: a
    depart and the stages of a long move belong to the measurement the head leaves, an arrive to the
    one it comes to). The first move, from wherever the robot stands to the first approach, is not
    known before the run."""
    steps = plan.run_steps(cfg.plan.verification_cycles, with_oracle=False, with_upload=with_upload)
    if not steps:
        return []
    lifts: list = [None] * len(steps)
    back = None
    if not cfg.model.is_scara:  # the retract poses (each step's approach and retract) and their lifts at once
        back, _ok = retract_poses(cfg, np.array([s.q for s in steps]))
        up, reached = lifted_many(cfg, back)
        lifts = [u if r else None for u, r in zip(up, reached)]
    out: list[tuple[np.ndarray, str, int]] = []
    last = None  # the previous step's label, point and lift
    for k, s in enumerate(steps):
        q = s.q
        name = f"step {s.index + 1} ({s.label})"
        if back is None:
            moves = all_motion_poses(cfg, q, s.direction)
            leave = retracted(cfg, q)
        else:  # an arm's approach and retract are both its retract pose (all_motion_poses, retracted)
            moves, leave = [back[k], q + retract_offset(cfg), q], back[k]
        if last is not None:
            for v, what in memo_travel_vias(cfg, out[-1][0], moves[0], None if cfg.model.is_scara else (last[2], lifts[k])):
                if what == "arrive":  # the descent to the approach is part of the next touch
                    out.append((v, f"{name}: {what}", s.point))
                else:  # the depart and the stages of a long move, away from any cube
                    out.append((v, f"{last[0]}: {what}", last[1] if what == "depart" else -1))
        names: tuple[str, ...] = ("approach", "above the point", "touch")
        if back is None and s.kind.is_verification:
            # a SCARA's verification touch is a Cartesian target it comes down to from above the
            # point on the approach side (station/cell/run/runner.py _touch, cartesian_above)
            moves = [moves[0], cartesian_above(cfg, q, s.direction), q]
        for what, qq in zip(names, moves):
            out.append((np.asarray(qq, dtype=float), f"{name}: {what}", s.point))
        out.append((np.asarray(leave, dtype=float), f"{name}: retract", s.point))
        last = (name, s.point, lifts[k])
    return out


#: the labels of the via poses (station/cell/plan/vias.py names them; the report's picture draws them)
VIA_NAMES = ("depart", "arrive", "arm upright", "turned upright", "first")


def check_plan(cfg: CellConfig, plan: Plan, with_upload: bool = True) -> CollisionReport:
    """Refuse (ConfigError, exit 2) a plan any of whose poses or paths collides, naming the pair, the
    step and the clearance; the report of a clear plan. Without python-fcl it refuses too (the
    station does not skip the check)."""
    require_fcl()
    poses = plan_path(cfg, plan, with_upload)
    report = check_path(cfg, poses)
    report = dataclasses.replace(report, vias=sum(1 for p in poses if p[1].endswith(VIA_NAMES)))
    if report.clash is not None:
        raise ConfigError(f"the plan collides: {report.clash.describe()} ({report.clashing_moves} poses or moves "
                          f"collide in all); nothing was moved. Move the obstacle or the body, change [limits] or "
                          f"[plan], or state the robot's link radii in its file's [collision] table "
                          f"(docs/collision.md)")
    return report
