"""The correction's pre-motion check as ``station plan`` and ``station calibrate`` run it (issues 27
and 37): the design's check (:func:`station.cell.correction.design.check_design`: every verification
target inside the table, a table within the controller's capacity that meets the bound), its refusal
given the ways out that pass that same check (:mod:`station.cell.correction.advice`).

The advice runs the design's check on each changed cell file, so it stands above the design; this
check stands above both and the design imports neither.
"""

from __future__ import annotations

from typing import Any

from station.cell.config.cell_config import CellConfig
from station.cell.correction.advice import advice_text, coverage_advice
from station.cell.correction.design import CorrectionRefused, check_design
from station.cell.plan.measurement_plan import build_plan
from station.core.table.design import TableDesign

__all__ = ["check_correction"]


def check_correction(cfg: CellConfig, plan: Any = None) -> TableDesign | None:
    """The correction's pre-motion check: the design, or None for a robot without a table (``plan``:
    the cell's plan, built when not given). Raises :class:`CorrectionRefused` when a verification
    target leaves the table or no table meets the bound within the capacity, with the changes that
    pass this same check."""
    if not cfg.model.is_scara:
        return None
    if plan is None:
        plan = build_plan(cfg)
    try:
        return check_design(cfg, plan)
    except CorrectionRefused as exc:
        if exc.widened is not None:
            raise exc.with_way(coverage_advice(cfg, plan, exc.widened)) from None
        if exc.design is not None:
            raise exc.with_way(advice_text(cfg, exc.design, plan)) from None
        raise
