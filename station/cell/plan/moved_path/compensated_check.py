"""An articulated arm's verification path as the controller will move it with its correction
(issue 40): an arm takes no table; its correction is the compensated Cartesian targets
(:func:`station.core.kinematics.compensation.compensated_targets`: the command C = FK_nominal(q'),
where q' puts the identified robot on the target), which the controller's nominal inverse kinematics
turns into exactly q', up to ~0.5° from the plan's joints at a fitted set-up and joint zeros. The
pre-motion check (:func:`station.cell.plan.run_path.check_plan`) saw the plan's joints only.

Once the compensated targets are known (:func:`station.cell.pipeline.articulated.articulated_targets`,
every one reachable) and before any verification motion, :func:`check_compensated` checks the remaining
steps' path through the same collision check (:func:`station.cell.plan.collision.check_path`), each
pose as the runner commands it (:mod:`station.cell.run.runner`, ``_touch``, with
:func:`station.cell.pipeline.articulated._articulated_proc`'s targets): the vias from where the head
stands (:func:`station.cell.plan.vias.travel_vias`, the runner's ``Travel``), the approach (the
target's retract pose, backed off along the corner's diagonal), the pose short of it by the approach
offset, the Cartesian touch at q', and the retract from there; a redundant head's re-measures as
:func:`station.cell.plan.moved_path.shifted_check.shifted_path` holds them. A pose or move that collides or comes
under the margin is refused with the SCARA's error (:class:`ShiftedPathCollides`, exit 2).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Collection, Mapping, Sequence

import numpy as np

from station.cell.config.cell_config import CellConfig
from station.cell.plan.arm_motion import retract_poses
from station.cell.plan.collision import CollisionReport, check_path, require_fcl
from station.cell.plan.measurement_plan import above_offset
from station.cell.plan.moved_path.shifted_check import Pose, at_setup, refuse_clash, remeasures
from station.cell.plan.steps import PlannedStep, StepKind
from station.cell.plan.via_memo import memo_travel_vias
from station.errors import UnreachableError

__all__ = ["Targets", "compensated_path", "check_compensated", "standing_at"]

#: per verification target (point, configuration code): the joints the controller moves to for its
#: Cartesian command and the command (6,) in the base frame [mm, rad] (articulated_targets' mapping)
Targets = Mapping[tuple[int, int], tuple[np.ndarray, np.ndarray]]


def _backed_off(cfg: CellConfig, steps: Sequence[PlannedStep], targets: Targets) -> list[np.ndarray]:
    """Each step's retract pose (its approach and its retract: the runner's approach_pose and
    retract_from of an arm) at its target's joints, all at once; the UnreachableError of one that
    the arm cannot reach (the runner's retract_pose would raise it before that motion)."""
    q = np.array([targets[st.point, st.elbow][0] for st in steps], dtype=float)
    back, ok = retract_poses(cfg, q)
    if not np.all(ok):
        st = steps[int(np.flatnonzero(~ok)[0])]
        raise UnreachableError(f"step {st.index + 1} ({st.label}): the retract pose {cfg.plan.clearance_mm:g} mm off "
                               f"the compensated target is not reachable; the motion was not commanded. Reduce "
                               f"[plan] clearance_mm or move the body")
    return list(back)


def standing_at(cfg: CellConfig, step: PlannedStep | None, targets: Targets) -> Pose | None:
    """Where the robot stands after ``step`` measured at ``targets``' joints (its retract pose),
    labelled as the step's retract: the start of the next phase's path (None: no step)."""
    if step is None:
        return None
    return (_backed_off(cfg, [step], targets)[0], f"step {step.index + 1} ({step.label}): retract", step.point)


def compensated_path(cfg: CellConfig, steps: Sequence[PlannedStep], targets: Targets,
                     start: Pose | None = None) -> list[Pose]:
    """The poses the runner commands for an arm's verification ``steps`` (in order) at ``targets``,
    labelled as :func:`station.cell.plan.run_path.plan_path` labels an arm's (a depart and the stages
    of a long move the step the head leaves, an arrive the step it comes to); ``start``: where the
    robot stands before the first (the path begins there)."""
    out: list[Pose] = [] if start is None else [start]
    for st, back in zip(steps, _backed_off(cfg, steps, targets)):
        q = np.asarray(targets[st.point, st.elbow][0], dtype=float)
        name = f"step {st.index + 1} ({st.label})"
        for again in range(remeasures(cfg) + 1):  # the runner's touch, then its re-measures (_touch)
            if out:  # from where the head stands, as the runner's Travel asks them
                leaving, point = out[-1][1].rsplit(": ", 1)[0], out[-1][2]
                for v, what in memo_travel_vias(cfg, out[-1][0], back):
                    out.append((v, f"{name}: {what}", st.point) if what == "arrive" else
                               (v, f"{leaving}: {what}", point if what == "depart" else -1))
            named = "" if not again else f" (re-measure {again})"
            # an arm stands short of its target by the approach offset, then the Cartesian move to it
            for what, qq in (("approach", back), ("above the point", q + above_offset(cfg, st.cycle, again)),
                             ("touch", q), ("retract", back)):
                out.append((np.asarray(qq, dtype=float), f"{name}: {what}{named}", st.point))
    return out


def path_report(cfg: CellConfig, placed: CellConfig, path: list[Pose], n_steps: int,
                start: Pose | None) -> CollisionReport:
    """The collision report of an arm's verification ``path`` of ``n_steps`` steps in the cell as
    ``placed``, its ``vias`` counted: every pose but the steps' own (four a step and a re-measure's
    four, :func:`compensated_path`) and the start."""
    report = check_path(placed, path)
    own = 4 * n_steps * (remeasures(cfg) + 1) + (start is not None)
    return dataclasses.replace(report, vias=report.poses - own)


def check_compensated(cfg: CellConfig, steps: Sequence[PlannedStep], targets: Targets, kinds: Collection[StepKind],
                      done: Collection[int] = (), what: str = "the compensated targets",
                      start: Pose | None = None, R_world_base: np.ndarray | None = None) -> CollisionReport | None:
    """Refuse (:class:`~station.cell.plan.moved_path.shifted_check.ShiftedPathCollides`, exit 2) the path of an
    arm's verification steps of ``kinds`` not in ``done`` at ``targets`` where a pose or a move collides
    or comes under ``[plan] collision_margin_mm``, naming the step, the pair and the clearance; the
    report of a clear path, None where no such step is left (or the robot is a SCARA: its table's
    path is :func:`~station.cell.plan.moved_path.shifted_check.check_shifted`'s). ``start``: where the robot
    stands before the first of them; the move from there is checked too. ``R_world_base``: a set-up
    that places the body and the obstacles in the robot's base frame (None: the configured one;
    :func:`~station.cell.plan.moved_path.shifted_check.at_setup`). The links are the nominal robot's: an arm's
    identified parameters are a minimal set (its set-up and first joint's frame merge), no link's place,
    so the check sees the compensated joints on the nominal robot, the correction's whole move."""
    todo = [st for st in steps if st.kind in kinds and st.index not in done]
    if not todo or cfg.model.is_scara:
        return None
    require_fcl()
    placed = cfg if R_world_base is None else at_setup(cfg, R_world_base)
    report = path_report(cfg, placed, compensated_path(cfg, todo, targets, start), len(todo), start)
    refuse_clash(report, len(todo), what, "at their compensated joints (the controller's inverse kinematics of the "
                 "compensated Cartesian targets)", "the compensation moves the head")
    return report
