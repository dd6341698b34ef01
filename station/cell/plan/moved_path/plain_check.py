"""An articulated arm's verification path before correction as the controller will move it (issue 40):
the plain Cartesian targets (:func:`station.cell.pipeline.articulated.articulated_targets` with no
parameters), which the controller's nominal inverse kinematics turns into joints the pre-motion check
did not see: the plan's at the configured set-up, these at the set-up they are commanded in.

They were commanded through the identified set-up, and an arm's merges with its first joint's zero (a
minimal set: the fit put 0.26° of the base's turn about axis 1 into the set-up and the opposite into
A2's angle): the nominal robot took the set-up's share alone, joint 1 0.43° from the plan's on the
built-in six-axis cell at seed 5 (7 mm at the head), where the controller's own collision model found
probe 6's housing 0.5 mm into cube 1 and refused the run's first Cartesian move (UNREACHABLE); the
station's check at those joints put 72 of the 108 steps under the margin. They are now commanded in
the frame the uncorrected robot located the body in, at the joints its identification poses took.

:func:`check_plain` checks those steps' path (the runner's poses: :func:`compensated_path`, from where
the step before leaves the robot) on the nominal robot, before any verification motion; a pose or a
move that collides or comes under the margin is refused
(:class:`~station.cell.plan.moved_path.shifted_check.ShiftedPathCollides`, exit 2) naming the step, the pair, the
clearance and how far the targets turned the joints from the plan's.
"""

from __future__ import annotations

from collections.abc import Collection, Sequence

import numpy as np

from station.cell.config.cell_config import CellConfig
from station.cell.plan.collision import CollisionReport, require_fcl
from station.cell.plan.moved_path.compensated_check import Targets, compensated_path, path_report
from station.cell.plan.moved_path.shifted_check import Pose, ShiftedPathCollides, at_setup
from station.cell.plan.steps import PlannedStep, StepKind

__all__ = ["check_plain", "joint_turn_deg"]


def joint_turn_deg(steps: Sequence[PlannedStep], targets: Targets) -> tuple[float, int, str]:
    """The largest difference [deg] of a verification step's commanded joints (``targets``) from its
    planned ones, the joint (1-based) and the step's label: how far the set-up they are commanded in
    moved them."""
    worst = (0.0, 0, "")
    for st in steps:
        q = targets.get((st.point, st.elbow))
        if q is None:
            continue
        d = np.degrees(np.abs(np.asarray(q[0], dtype=float) - np.asarray(st.q, dtype=float)))
        j = int(np.argmax(d))
        if d[j] > worst[0]:
            worst = (float(d[j]), j + 1, st.label)
    return worst


def check_plain(cfg: CellConfig, steps: Sequence[PlannedStep], targets: Targets, done: Collection[int] = (),
                start: Pose | None = None, R_world_base: np.ndarray | None = None) -> CollisionReport | None:
    """Refuse (:class:`ShiftedPathCollides`, exit 2) the path of an arm's verification steps before
    correction not in ``done`` at ``targets`` (the plain targets' joints) where a pose or a move collides
    or comes under ``[plan] collision_margin_mm``; the report of a clear path, None where no such step is
    left or the robot is a SCARA. ``start``: where the robot stands before the first of them;
    ``R_world_base``: where the body and the obstacles are placed (None: ``cfg``'s set-up, the located
    one after locating, as :func:`~station.cell.plan.moved_path.compensated_check.check_compensated` places them)."""
    todo = [st for st in steps if st.kind is StepKind.VERIFY_BEFORE and st.index not in done]
    if not todo or cfg.model.is_scara:
        return None
    require_fcl()
    placed = cfg if R_world_base is None else at_setup(cfg, R_world_base)
    report = path_report(cfg, placed, compensated_path(placed, todo, targets, start), len(todo), start)
    if report.clash is None:
        return report
    turn, joint, label = joint_turn_deg(todo, targets)
    raise ShiftedPathCollides(
        f"the verification path before correction collides at the joints the controller moves for the plain "
        f"targets: {report.clash.describe()} ({report.clashing_moves} poses or moves "
        f"in all; {len(todo)} steps checked on the nominal robot; their set-up "
        f"moves joint {joint} {turn:.2f}° from the plan's at {label}); no verification step was moved",
        "the set-up the body was located at turns the arm from the planned joints toward what the message names: "
        "hold that point out of "
        "verification ([plan] verification_every), move the obstacle or the body's cube away from it, or lower "
        "[plan] collision_margin_mm where the cell allows it (docs/collision.md), then start the run again")
