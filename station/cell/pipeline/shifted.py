"""The run's collision clearances (issue 40): the pre-motion check's, and each correction table's
verification path as the controller will move it (:mod:`station.cell.plan.moved_path.shifted_check`), checked
after the table is designed and before it is activated, and an articulated arm's compensated targets
(:mod:`station.cell.plan.moved_path.compensated_check`) before its verification; a path that collides is refused
there (ConfigError, exit 2) and :func:`station.cell.pipeline.calibration.run_calibration` puts the table
of the run's start back, as after every refusal once measuring began. Each checked step's clearance
replaces the pre-motion one the runner streams when the step starts (its NextMove, the TUI's line)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from station.cell.config.cell_config import CellConfig
from station.cell.plan.collision import CollisionReport
from station.cell.plan.moved_path.compensated_check import Targets, check_compensated, standing_at
from station.cell.plan.moved_path.plain_check import check_plain
from station.cell.plan.moved_path.shifted_check import at_setup, check_shifted, preceding, shifted_path
from station.cell.plan.steps import PlannedStep, StepKind
from station.cell.records.summary import ClearanceSummary, RunSummary
from station.cell.run.facts.events import Event, Notice
from station.cell.run.facts.next_move import next_moves
from station.cell.run.locate import located_joints
from station.cell.run.runner import Runner
from station.core.table.values import CorrectionTableData

__all__ = ["clearance_of", "checked_shifted", "checked_compensated", "checked_plain", "reference_skipped", "scara_standing"]


def clearance_of(check: str, report: CollisionReport | None) -> ClearanceSummary | None:
    """What the run records of a collision check's report (None: no check)."""
    if report is None:
        return None
    c = report.closest
    if c is None:
        return ClearanceSummary(check, None, report.margin_mm, report.poses)
    return ClearanceSummary(check, float(c.clearance_mm), report.margin_mm, report.poses, c.a, c.b, c.where)


def scara_standing(cfg: CellConfig, steps: tuple[PlannedStep, ...], kind: StepKind, R_world_base: np.ndarray,
                   table: CorrectionTableData | None) -> tuple[np.ndarray, str, int] | None:
    """Where a SCARA stands when the ``kind`` steps' table becomes active: the retract of the step the
    run measures before the first of them (:func:`preceding`), at the set-up ``R_world_base`` and with
    ``table`` (None: none) that step was measured with."""
    prev = preceding(steps, {kind})
    return None if prev is None else shifted_path(cfg, [prev], R_world_base, table, vias=False)[3]


def checked_shifted(cfg: CellConfig, steps: tuple[PlannedStep, ...], done: set[int], R_world_base: np.ndarray,
                    table: CorrectionTableData, kind: StepKind, summary: RunSummary,
                    emit: Callable[[Event], None], runner: Runner | None = None,
                    start: tuple[np.ndarray, str, int] | None = None) -> RunSummary:
    """Check the ``kind`` steps not yet done, shifted by ``table`` (refused: ConfigError, exit 2),
    from ``start`` (:func:`scara_standing`); the summary with the least clearance recorded (its
    ``clearances``) and a notice; ``runner``'s next moves of those steps the shifted ones."""
    what = "the new correction table" if kind is StepKind.VERIFY_AFTER else "the oracle's table"
    report = check_shifted(cfg, steps, R_world_base, table, {kind}, done, what, start)
    check = "after (shifted)" if kind is StepKind.VERIFY_AFTER else "oracle (shifted)"
    return _recorded(report, check, f"{what}'s correction", steps, done, kind, summary, emit, runner)


def checked_compensated(cfg: CellConfig, steps: tuple[PlannedStep, ...], done: set[int], targets: Targets,
                        kind: StepKind, summary: RunSummary, emit: Callable[[Event], None], runner: Runner,
                        before: Targets, R_world_base: np.ndarray | None) -> RunSummary:
    """An articulated arm's :func:`checked_shifted`: the ``kind`` steps not yet done at their
    compensated ``targets`` (the body placed at ``R_world_base``, None: the configured set-up), from where the step before
    them leaves the robot (measured at ``before``, the targets of its kind)."""
    what = "the compensated targets" if kind is StepKind.VERIFY_AFTER else "the oracle's compensated targets"
    start = standing_at(cfg, preceding(steps, {kind}), before)
    report = check_compensated(cfg, steps, targets, {kind}, done, what, start, R_world_base)
    check = "after (compensated)" if kind is StepKind.VERIFY_AFTER else "oracle (compensated)"
    return _recorded(report, check, what, steps, done, kind, summary, emit, runner)


def checked_plain(cfg: CellConfig, steps: tuple[PlannedStep, ...], done: set[int], targets: Targets,
                  configured: np.ndarray, summary: RunSummary, emit: Callable[[Event], None],
                  runner: Runner) -> RunSummary:
    """An articulated arm's verification steps before correction not yet done, at the joints the
    controller moves for their plain ``targets`` (:func:`check_plain`, refused: exit 2), the body at
    ``cfg``'s set-up (the located one), from where the step before them leaves the robot: an
    identification step at its joints on the located set-up (where the run commanded them; the plan's
    where ``cfg``'s set-up is the ``configured`` one)."""
    prev = preceding(steps, {StepKind.VERIFY_BEFORE})
    start = None
    if prev is not None and not prev.kind.is_verification:
        planned = at_setup(cfg, configured)
        q = prev.q if planned is cfg else located_joints(planned, prev, cfg.model.nominal[:6])
        start = standing_at(cfg, prev, {(prev.point, prev.elbow): (q, np.zeros(6))})
    report = check_plain(cfg, steps, targets, done, start)
    return _recorded(report, "before (plain)", "the plain targets before correction", steps, done,
                     StepKind.VERIFY_BEFORE, summary, emit, runner)


def _recorded(report: CollisionReport | None, check: str, what: str, steps: tuple[PlannedStep, ...], done: set[int],
              kind: StepKind, summary: RunSummary, emit: Callable[[Event], None],
              runner: Runner | None) -> RunSummary:
    """The summary with a clear path's least clearance, its notice, and the runner's next moves."""
    rec = clearance_of(check, report)
    if report is None or rec is None:
        return summary
    if runner is not None:  # the TUI's "next move" line of these steps: the path they will move, not the plan's
        todo = [st for st in steps if st.kind is kind and st.index not in done]
        runner.next_moves = {**runner.next_moves, **next_moves(report, todo, steps, check)}
    least = rec.text().removeprefix(rec.check + " ")
    emit(Notice("info", f"collision check of the verification path with {what}: {report.poses} poses, "
                        f"least clearance {least}{'' if rec.least_mm is None else ' ' + rec.where}, "
                        f"{report.seconds:.2f} s"))
    return summary.replace(clearances=(*summary.clearances, rec))


def reference_skipped(exc: Exception) -> str:
    """The notice of a simulated session's reference (the oracle) left unmeasured because its path's
    check refused it. The reference is a figure beside the result, not the result: its check shifts
    the head by the whole of the reference's correction on the nominal links (the conservative model,
    see :func:`~station.cell.plan.moved_path.compensated_check.check_compensated`), so it can refuse a path the
    robot clears (the built-in six-axis cell, seed 8: 1.8 mm under the 2 mm margin, where the
    simulated controller's own check moved it clear). The run's own verification stands; after/oracle
    is not stated."""
    return f"oracle reference not measured (its path was refused before it moved; the run's result stands): {exc}"
