"""The verification path as the controller will move it (issue 40): the pre-motion check
(:func:`station.cell.plan.run_path.check_plan`) sees the plan's verification touches at their nominal
joints, but with a correction table active the controller commands a Cartesian target's nominal
inverse kinematics plus the table's Δq (the controller's interpolation rule; up to ~0.3° on the
built-in cell, a few mm at full reach), so the path it moves was never checked.

Once the table is designed (it is what the upload writes and reads back, CRC-32 for CRC-32) and before
it is activated, :func:`check_shifted` checks the remaining verification steps' path through the same
collision check (:func:`station.cell.plan.collision.check_path`), each pose as the runner will command
it (:mod:`station.cell.run.runner`, ``_touch``): the approach at the target's nominal joints (a joint
move: no table), the pose above the point moved in its revolute joints by the table's Δq (the runner's
``AboveCartesian``), the Cartesian touch at nominal + Δq (the guard's copy of the controller's rule,
:meth:`station.cell.limits.motion_guard.MotionGuard.commanded_joints`), the retract lifted from there,
and the vias between two touches (:func:`station.cell.plan.vias.travel_vias`, as the runner's
``Travel``). The targets are the run's (its identified set-up, :func:`verification_targets`), not the
plan's. A pose or move that collides or comes under the margin is refused (ConfigError, exit 2, as the
pre-motion refusal) before any verification motion; the caller leaves the table inactive.

The move into the first checked step is in the path too (``start``): from where the robot stands
after the step before it (the last verification step before correction, or the station's table's
last), as that step leaves it, to the first approach with the table active, the transition the
pre-motion check saw only at the plan's joints (:func:`preceding`).

A redundant head's re-measure comes back to its touch from a larger approach offset (3.7 % more a
re-measure, :func:`station.cell.plan.measurement_plan.approach_pose`); where the head re-measures
(more than six probes, ``[plan] remeasure_attempts`` > 0), each step's path holds those approaches
too, as the runner moves them: retract, the re-measure's approach, above the point, the touch.

An articulated arm's correction takes no table: its compensated joint targets are checked by
:mod:`station.cell.plan.moved_path.compensated_check`, refused with the same error.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Collection, Sequence

import numpy as np

from station.cell.config.cell_config import CellConfig
from station.cell.limits.motion_guard import MotionGuard
from station.cell.plan.assembly import head_targets_world
from station.cell.plan.collision import CollisionReport, check_path, require_fcl
from station.cell.plan.measurement_plan import approach_pose, cartesian_above, joints_for, retract_offset, retracted
from station.cell.plan.steps import PlannedStep, StepKind
from station.cell.plan.via_memo import memo_travel_vias
from station.core.kinematics.transforms import invert, matrix_to_pose, pose_to_matrix
from station.core.table.values import CorrectionTableData
from station.errors import ConfigError

__all__ = ["ShiftedPathCollides", "verification_targets", "shifted_path", "check_shifted", "preceding",
           "remeasures", "refuse_clash", "at_setup"]

#: a pose of a path: (joints (g,) [rad, mm], what it is, the measuring point it touches; -1: none)
Pose = tuple[np.ndarray, str, int]


class ShiftedPathCollides(ConfigError):
    """The verification path, shifted by a table's correction, collides or comes under the margin
    (exit 2, as the pre-motion refusal of a plan that collides); ``hint``: the settings to change."""

    def __init__(self, message: str, hint: str):
        super().__init__(message)
        self.hint = hint


def verification_targets(cfg: CellConfig, steps: Sequence[PlannedStep], R_world_base: np.ndarray
                         ) -> list[tuple[np.ndarray, np.ndarray, int]]:
    """Per verification step, what the pipeline commands (station/cell/pipeline/calibration.py
    ``_proc_for``): (the target's nominal joints, its Cartesian pose (6,) in the base frame [mm, rad],
    the elbow), at the set-up ``R_world_base`` (the identified one)."""
    heads = head_targets_world(cfg)
    to_base = invert(pose_to_matrix(np.asarray(R_world_base, dtype=float)))
    q_nom: dict[tuple[int, int], np.ndarray] = {}
    for elbow in {int(st.elbow) for st in steps}:  # each elbow's inverse kinematics at once
        points = sorted({st.point for st in steps if st.elbow == elbow})
        q_nom.update(zip(((p, elbow) for p in points), joints_for(cfg, heads[points], elbow, R_world_base)))
    return [(np.asarray(q_nom[st.point, int(st.elbow)], dtype=float), matrix_to_pose(to_base @ heads[st.point]),
             int(st.elbow)) for st in steps]


def at_setup(cfg: CellConfig, R_world_base: np.ndarray) -> CellConfig:
    """``cfg`` with the robot's base at ``R_world_base``, where the check places the body and the
    obstacles in the base frame: a simulated arm's oracle targets are compensated at the true set-up,
    a few mm from the configured guess, and checked at the guess their path is off by that much (the
    built-in six-axis cell's came 1.5 mm from a cube, 2.7 mm at the true set-up). Not the identified
    set-up: an arm's merges with its first joint's frame (a minimal set), no place of the base alone."""
    R = np.asarray(R_world_base, dtype=float)
    if np.array_equal(R, cfg.model.nominal[:6]):
        return cfg
    return dataclasses.replace(cfg, model=cfg.model.with_setup(R))


def preceding(steps: Sequence[PlannedStep], kinds: Collection[StepKind], done: Collection[int] = ()
              ) -> PlannedStep | None:
    """The step the run measures right before the first step of ``kinds`` not in ``done`` (None: none
    left, or none before it): where the robot stands when that step's correction becomes active. The
    uninterrupted run's: a resumed session's first move, from where the robot stands, is checked by
    :func:`station.cell.pipeline.premotion.check_first_motion`."""
    k = next((k for k, st in enumerate(steps) if st.kind in kinds and st.index not in done), None)
    return None if not k else steps[k - 1]


def remeasures(cfg: CellConfig) -> int:
    """How many re-measures a touch may take (the runner's, :func:`station.cell.run.runner._touch`):
    ``[plan] remeasure_attempts`` where the head has more than six probes, else none (a 3-2-1 head's
    touch cannot disagree with itself)."""
    n = 6 if cfg.head is None else int(cfg.head.n_probes)  # None: the built-in 3-2-1 head
    return int(cfg.plan.remeasure_attempts) if n > 6 else 0


def shifted_path(cfg: CellConfig, steps: Sequence[PlannedStep], R_world_base: np.ndarray,
                 table: CorrectionTableData | None, vias: bool = True, start: Pose | None = None
                 ) -> list[Pose]:
    """The poses the runner commands for ``steps`` (verification steps, in order) with ``table``
    active (None: none, a Cartesian touch at its nominal joints), labelled as
    :func:`station.cell.plan.run_path.plan_path` labels them: (joints, what it is, the measuring point).
    Raises the guard's UnreachableError of a target outside the table's grid. ``vias=False``: the direct
    moves between two steps (what :func:`travel_vias` keeps where they are clear). ``start``: where the
    robot stands before the first (the path begins there); each step's re-measures follow its touch
    (:func:`remeasures`)."""
    guard = MotionGuard(cfg.soft_limits, elbows=cfg.plan.elbows, joint_types=cfg.model.joint_types)
    guard.table = table
    lift = retract_offset(cfg) > 0  # the quill keeps its height above the point (the runner's _above_corrected)
    out: list[Pose] = [] if start is None else [start]
    for st, (q, pose, elbow) in zip(steps, verification_targets(cfg, steps, R_world_base)):
        name = f"step {st.index + 1} ({st.label})"
        touch = guard.commanded_joints(pose, elbow, q)
        for again in range(remeasures(cfg) + 1):  # the runner's touch, then its re-measures (_touch)
            approach = approach_pose(cfg, q, 1, st.cycle, again)  # verification approaches from direction 1
            if out and vias:  # labelled as plan_path labels a SCARA's: the step the head leaves, no point
                leaving = out[-1][1].rsplit(": ", 1)[0]
                out += [(v, f"{leaving}: {what}", -1) for v, what in memo_travel_vias(cfg, out[-1][0], approach)]
            above = cartesian_above(cfg, q, 1, st.cycle, again) + np.where(lift, 0.0, touch - q)
            named = "" if not again else f" (re-measure {again})"
            for what, qq in (("approach", approach), ("above the point", above), ("touch", touch),
                             ("retract", retracted(cfg, touch))):
                out.append((np.asarray(qq, dtype=float), f"{name}: {what}{named}", st.point))
    return out


def check_shifted(cfg: CellConfig, steps: Sequence[PlannedStep], R_world_base: np.ndarray,
                  table: CorrectionTableData, kinds: Collection[StepKind], done: Collection[int] = (),
                  what: str = "the new correction table", start: Pose | None = None) -> CollisionReport | None:
    """Refuse (ConfigError, exit 2) the verification path of the steps of ``kinds`` not in ``done``
    where, shifted by ``table``, a pose or a move collides or comes under ``[plan]
    collision_margin_mm``, naming the step, the pair and the clearance; the report of a clear path
    (its ``closest``: the least clearance, shifted), None where no such step is left. ``start``: where
    the robot stands before the first of them (:func:`preceding`'s retract): the move from there is
    checked too."""
    todo = [st for st in steps if st.kind in kinds and st.index not in done]
    if not todo or not cfg.model.is_scara:  # an articulated arm: no table shifts its touches
        return None
    require_fcl()
    # The direct moves first: where none of the path clashes, travel_vias (a SCARA's way around an
    # obstacle) keeps every direct move (it keeps one whose move is clear at the full margin, and every
    # candidate of its ends the same), so this is the runner's path; its vias asked the check of each
    # move again (0.99 of 1.22 s on scara_arc's 120 steps). Else the path with the vias decides.
    report = check_path(cfg, shifted_path(cfg, todo, R_world_base, table, vias=False, start=start))
    if report.clash is not None:
        report = check_path(cfg, shifted_path(cfg, todo, R_world_base, table, start=start))
    own = 4 * len(todo) * (remeasures(cfg) + 1) + (start is not None)  # the steps' poses and the start; the rest vias
    report = dataclasses.replace(report, vias=report.poses - own)
    refuse_clash(report, len(todo), what, "with the table's correction added to their Cartesian touches",
                 "the table's correction moves the head")
    return report


def refuse_clash(report: CollisionReport, n_steps: int, what: str, how: str, mover: str) -> None:
    """Raise :class:`ShiftedPathCollides` (exit 2) where ``report`` found a clash, naming the step,
    the pair, the clearance and the least clearance; ``how`` the steps were checked, ``mover``
    what moved the head toward the obstacle (for the hint)."""
    if report.clash is None:
        return
    least = report.closest
    deepest = "" if least is None or least == report.clash else (
        f"; the least clearance: {least.clearance_mm:.1f} mm ({least.a} and {least.b} {least.where})")
    raise ShiftedPathCollides(
        f"with {what} active the verification path collides: {report.clash.describe()} "
        f"({report.clashing_moves} poses or moves in all{deepest}; {n_steps} steps checked {how}); none of "
        f"these steps was moved and the correction is not left active",
        f"{mover} toward what the message names by more than the nominal path keeps from it: move that "
        "obstacle away from the verification point, or hold other points out ([plan] verification_every), or "
        "lower [plan] collision_margin_mm where the cell allows it (docs/collision.md), then start the run again")
