"""The run's collision clearances (issue 40): the pre-motion check's, and each correction table's
verification path as the controller will move it (:mod:`station.cell.plan.shifted_check`), checked
after the table is designed and before it is activated; a path that collides is refused there
(ConfigError, exit 2) and :func:`station.cell.pipeline.calibration.run_calibration` puts the table
of the run's start back, as after every refusal once measuring began."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from station.cell.config.cell_config import CellConfig
from station.cell.plan.collision import CollisionReport
from station.cell.plan.shifted_check import check_shifted
from station.cell.plan.steps import PlannedStep, StepKind
from station.cell.records.summary import ClearanceSummary, RunSummary
from station.cell.run.facts.events import Event, Notice
from station.core.table.values import CorrectionTableData

__all__ = ["clearance_of", "checked_shifted"]


def clearance_of(check: str, report: CollisionReport | None) -> ClearanceSummary | None:
    """What the run records of a collision check's report (None: no check)."""
    if report is None:
        return None
    c = report.closest
    if c is None:
        return ClearanceSummary(check, None, report.margin_mm, report.poses)
    return ClearanceSummary(check, float(c.clearance_mm), report.margin_mm, report.poses, c.a, c.b, c.where)


def checked_shifted(cfg: CellConfig, steps: tuple[PlannedStep, ...], done: set[int], R_world_base: np.ndarray,
                    table: CorrectionTableData, kind: StepKind, summary: RunSummary,
                    emit: Callable[[Event], None]) -> RunSummary:
    """Check the ``kind`` steps not yet done, shifted by ``table`` (refused: ConfigError, exit 2);
    the summary with the least clearance recorded (its ``clearances``) and a notice."""
    what = "the new correction table" if kind is StepKind.VERIFY_AFTER else "the oracle's table"
    report = check_shifted(cfg, steps, R_world_base, table, {kind}, done, what)
    rec = clearance_of("after (shifted)" if kind is StepKind.VERIFY_AFTER else "oracle (shifted)", report)
    if report is None or rec is None:
        return summary
    least = rec.text().removeprefix(rec.check + " ")
    emit(Notice("info", f"collision check of the verification path with {what}'s correction: {report.poses} poses, "
                        f"least clearance {least}{'' if rec.least_mm is None else ' ' + rec.where}, "
                        f"{report.seconds:.2f} s"))
    return summary.replace(clearances=(*summary.clearances, rec))
