"""Every check ``station calibrate`` makes before the first motion, in one function that
``station plan`` runs too (issue 27): what ``plan`` passes, ``calibrate`` does not refuse before
moving, and what ``plan`` refuses (exit 2) it refuses with the same message.

The checks, in order: the probes' stroke can find the body within the set-up's uncertainty
(:mod:`station.cell.plan.locating`); every ``[[tool]]`` can be corrected on this robot; the plan (every
(point, elbow) within reach and the soft limits, enough poses for the identifiable set); the
correction (every verification target inside the table, a table within the controller's
capacity that meets ``correction.max_interpolation_um``); the collision check of every pose and
path the run commands, vias included (:func:`station.cell.plan.collision.check_plan`, issue 40).
"""

from __future__ import annotations

from dataclasses import dataclass

from station.cell.config.cell_config import CellConfig
from station.cell.correction.design import check_correction
from station.cell.correction.robot_tools import check_tools, tool_grid
from station.cell.plan.collision import CollisionReport, check_plan
from station.cell.plan.locating import Coverage, check_locating
from station.cell.plan.measurement_plan import Plan, build_plan
from station.core.table.design import TableDesign
from station.errors import ConfigError

__all__ = ["Premotion", "premotion_check"]


@dataclass(frozen=True)
class Premotion:
    """What the pre-motion checks found: the plan and the correction's design (None for a robot
    without a table)."""

    plan: Plan
    design: TableDesign | None
    locating: Coverage | None = None  # how far the search for the body reaches (issue 37)
    collision: CollisionReport | None = None  # the plan's collision check (issue 40)


def premotion_check(cfg: CellConfig) -> Premotion:
    """Run every pre-motion check; raises the :class:`~station.errors.ConfigError` (exit 2) or
    :class:`~station.errors.UnreachableError` of the first that fails."""
    locating = check_locating(cfg)
    check_tools(cfg)
    plan = build_plan(cfg)
    design = check_correction(cfg, plan)
    if cfg.model.is_scara:
        for t in cfg.tools:  # each tool's grid: its own axes and the head's, within the capacity
            try:
                tool_grid(cfg, t)
            except ConfigError as exc:
                raise ConfigError(f"tool {t.name!r}: {exc} ([[tool]] x_mm, y_mm, z_mm give its own grid)") from None
    collision = check_plan(cfg, plan)  # refuses a plan that collides, or a check it cannot do
    return Premotion(plan, design, locating, collision)
