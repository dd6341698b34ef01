"""A simulated cell's judgement of a run (issue 42): after verification the session hands the
identified model to the cell's judge (:class:`station.cell.records.judge.RunJudge`), which
computes the figures only a simulator can (the corrected robot in its true base frame); they
are stored (result ``simulation``), stated as a notice and reported as the summary's
``simulation``. A real cell has no judge and never comes here.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from station.cell.config.cell_config import CellConfig
from station.cell.pipeline.results import grid_for, reference_params
from station.cell.plan.measurement_plan import head_targets_world
from station.cell.records.judge import JudgeFigure, RunJudge, judge_figures
from station.cell.records.rundb import RunDB
from station.cell.records.summary import RunSummary
from station.cell.run.facts.events import Event, Notice
from station.core.kinematics.transforms import invert, pose_to_matrix
from station.errors import StationError

#: an arm's region around the head's targets [mm]: the body's targets and the moves between them
ARM_MARGIN_MM = 150.0


def judged_region(cfg: CellConfig) -> tuple[np.ndarray, np.ndarray]:
    """The box [mm, robot base frame] the judge draws its targets in: a SCARA's correction grid
    (what its table covers), an arm's head targets ± ``ARM_MARGIN_MM`` (its compensated targets)."""
    if cfg.model.is_scara:
        g = grid_for(cfg)
        return (np.array([g.x_range[0], g.y_range[0], g.z_range[0]], dtype=float),
                np.array([g.x_range[1], g.y_range[1], g.z_range[1]], dtype=float))
    heads = invert(pose_to_matrix(cfg.model.nominal[:6])) @ head_targets_world(cfg)
    return heads[:, :3, 3].min(axis=0) - ARM_MARGIN_MM, heads[:, :3, 3].max(axis=0) + ARM_MARGIN_MM


def judge_run(cfg: CellConfig, judge: RunJudge, summary: RunSummary) -> tuple[JudgeFigure, ...]:
    """The judge's figures of the run's identified model (none before an identification)."""
    ident = summary.identification
    if ident is None:
        return ()
    params = np.array(cfg.model.nominal, dtype=float)
    chosen = tuple(e.name for e in ident.parameters)
    params[[cfg.model.param_index(n) for n in chosen]] = [e.value for e in ident.parameters]
    return judge_figures(judge.figures(cfg.model, reference_params(cfg, judge), params, chosen, ident.objective,
                                       judged_region(cfg)))


def judged(cfg: CellConfig, judge: RunJudge, db: RunDB, run_id: int, summary: RunSummary,
           emit: Callable[[Event], None]) -> RunSummary:
    """``summary`` with the judge's figures, stored as result ``simulation``. A figure beside the
    result never stops the run: a failure to compute it is a warning."""
    try:
        figures = judge_run(cfg, judge, summary)
    except (StationError, ValueError, np.linalg.LinAlgError) as exc:  # e.g. its reference not identifiable
        emit(Notice("warning", f"simulation: the judge's figures were not computed ({exc})"))
        return summary
    if not figures:
        return summary
    db.save_result(run_id, "simulation", {f.name: {"value": f.value, "unit": f.unit, "caption": f.caption}
                                          for f in figures})
    emit(Notice("info", "simulation: " + ", ".join(f"{f.name} {f.value:.2f} {f.unit}" for f in figures)))
    return summary.replace(simulation=figures)
