"""Why identification poses are invalid, and the setting that fixes it (issue 37 §4).

A run that measured every step and then has too few valid identification poses stopped with
"only 32 of 74 identification poses are valid" and advice that named no setting. Here the invalid
readings are sorted by what refused them, as the runner stored it (:mod:`station.cell.run.runner`):

* **the plane residual**: the pose was solved and stored, and only ``[plan] max_residual_um``
  refused it. The bound that makes enough poses valid is read off the stored residuals, and the
  fix only judges the stored readings again (:func:`rejudge`): ``--resume`` reuses every
  measurement and measures again only those still invalid
  (:data:`station.cell.records.fingerprint.JUDGING_KEYS`);
* **no pose** (probes out of stroke or silent, a touch the redundant probes disagree on): the
  measurement itself must change (``[plan] recenter_attempts``, ``remeasure_attempts``, where the
  body is: ``[robot] setup`` and ``setup_uncertainty_mm``): a new run, as a resume refuses a cell
  measured differently; after cleaning a probe, a resume measures the invalid poses again.

Each cause is named with its count, the setting, the value to write and whether a resume keeps the
measurements.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence

from station.cell.config.cell_config import CellConfig
from station.cell.plan.steps import StepKind
from station.cell.records.run_records import MeasurementRecord
from station.cell.records.rundb import RunDB
from station.cell.run.facts.events import Event, Notice

__all__ = ["rejudge", "invalid_advice", "residual_bound_for"]

#: the kinds whose validity the identification counts, and which are judged again
JUDGED_KINDS = (StepKind.IDENTIFICATION.value, StepKind.REVERSAL.value)
#: a suggested bound sits this much above the residual it must admit (the stored value is rounded)
BOUND_MARGIN = 1.1
#: the schema's largest [plan] max_residual_um
MAX_BOUND_UM = 1000.0


def _judgeable(r: MeasurementRecord) -> bool:
    """A reading whose pose was solved and whose residual alone decided it (runner: ``ok`` is
    ``residual <= max_residual_um`` on every path that stores a pose with a residual)."""
    return r.pose is not None and r.pose_residual_um is not None and math.isfinite(r.pose_residual_um)


def rejudge(cfg: CellConfig, db: RunDB, run_id: int, emit: Callable[[Event], None]) -> int:
    """Judge the stored identification readings again against ``[plan] max_residual_um`` (a
    resume after the bound changed); a reading that flips is stored again with its new verdict.
    Returns how many flipped."""
    bound = cfg.plan.max_residual_um
    now_ok = now_bad = 0
    for r in db.measurements(run_id):
        if r.kind not in JUDGED_KINDS or not _judgeable(r):
            continue
        ok = float(r.pose_residual_um or 0.0) <= bound
        if ok == r.ok:
            continue
        verdict = "within" if ok else "exceeds"
        message = (f"plane residual {r.pose_residual_um:.2f} µm {verdict} [plan] max_residual_um = {bound:g} µm "
                   f"(judged again on resume)")
        fields = dataclasses.asdict(r) | {"ok": ok, "message": message}
        fields.pop("run_id")
        step = fields.pop("step_index")
        db.record_measurement(run_id, step, replace=True, **fields)
        now_ok, now_bad = now_ok + ok, now_bad + (not ok)
    if now_ok or now_bad:
        emit(Notice("info", f"the stored identification readings judged again against [plan] max_residual_um = "
                            f"{bound:g} µm: {now_ok} now valid, {now_bad} now invalid; nothing was measured again "
                            f"for them"))
    return now_ok + now_bad


def residual_bound_for(records: Sequence[MeasurementRecord], needed: int) -> float | None:
    """The ``max_residual_um`` that makes ``needed`` identification readings valid (rounded up to
    0.1 µm with :data:`BOUND_MARGIN`), or None when fewer than ``needed`` have a solved pose."""
    ident = [r for r in records if r.kind == StepKind.IDENTIFICATION.value]
    solved = sorted(float(r.pose_residual_um or 0.0) if _judgeable(r) else 0.0
                    for r in ident if r.pose is not None)
    if needed < 1 or len(solved) < needed:
        return None
    # rounded to 1e-9 first: 2.0 × 1.1 is 2.2000000000000002 in floating point, and a bare ceil
    # of its tenths advised 2.3 µm where 2.2 µm already makes the reading valid
    bound = math.ceil(round(solved[needed - 1] * BOUND_MARGIN * 10.0, 9)) / 10.0
    return bound if bound <= MAX_BOUND_UM else None


def invalid_advice(cfg: CellConfig, records: Sequence[MeasurementRecord], needed: int) -> str:
    """The invalid identification readings by cause, each with the setting to change and its value."""
    ident = [r for r in records if r.kind == StepKind.IDENTIFICATION.value]
    bad = [r for r in ident if not (r.ok and r.pose is not None)]
    by_residual = [r for r in bad if _judgeable(r)]
    unsolved = [r for r in bad if r.pose is None]
    parts = []
    bound = residual_bound_for(records, needed)
    if by_residual:
        worst = max(float(r.pose_residual_um or 0.0) for r in by_residual)
        if bound is not None:
            valid = sum(1 for r in ident if r.pose is not None and (float(r.pose_residual_um or 0.0) <= bound
                                                                    if _judgeable(r) else r.ok))
            parts.append(f"{len(by_residual)} were solved and refused only by their plane residual (up to {worst:.2f} "
                         f"µm against [plan] max_residual_um = {cfg.plan.max_residual_um:g}): set [plan] "
                         f"max_residual_um = {bound:g} ({valid} valid with it) if the head's own noise is that large "
                         f"(else clean and check the probes), then resume with --resume: it judges the stored "
                         f"readings again, keeps every measurement and measures again only those still invalid")
        else:
            parts.append(f"{len(by_residual)} were refused by their plane residual (up to {worst:.2f} µm against [plan] "
                         f"max_residual_um = {cfg.plan.max_residual_um:g}), but no bound alone makes {needed} valid")
    if unsolved:
        stroke = sum(1 for r in unsolved if "stroke" in r.message or "no valid reading" in r.message
                     or "without a reading" in r.message)
        other = len(unsolved) - stroke
        if stroke:
            attempts = min(10, cfg.plan.recenter_attempts + 2)
            parts.append(f"{stroke} had probes out of their stroke: set [plan] recenter_attempts = {attempts} (now "
                         f"{cfg.plan.recenter_attempts}), or correct [robot] setup to where the robot stands and "
                         f"give [robot] setup_uncertainty_mm its real size (now {cfg.plan.setup_uncertainty_mm:g}); "
                         f"then start a new run (leave out --resume): these change how poses are measured")
        if other:
            again = min(5, cfg.plan.remeasure_attempts + 1)
            parts.append(f"{other} gave no pose (the probes disagreed or touched another surface): clean and check "
                         f"the probes, then resume: the invalid poses are measured again (or set [plan] "
                         f"remeasure_attempts = {again}, now {cfg.plan.remeasure_attempts}, and start a new run)")
    return "; ".join(parts)
