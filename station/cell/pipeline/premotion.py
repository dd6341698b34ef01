"""Every check ``station calibrate`` makes before the first motion, in one function that
``station plan`` runs too (issue 27): what ``plan`` passes, ``calibrate`` does not refuse before
moving, and what ``plan`` refuses (exit 2) it refuses with the same message.

The checks, in order: the probes' stroke can find the body within the set-up's uncertainty
(:mod:`station.cell.plan.locating`); every ``[[tool]]`` can be corrected on this robot; the plan (every
(point, elbow) within reach and the soft limits, enough poses for the identifiable set); the
correction (every verification target inside the table, a table within the controller's
capacity that meets ``correction.max_interpolation_um``); the collision check of every pose and
path the run commands, vias included (:func:`station.cell.plan.run_path.check_plan`, issue 40), and
of the moves the plan does not hold (:mod:`station.cell.plan.first_moves`): every search touch of
locating the body, and the first move from where the robot is parked (``[conformance]
park_joints``, when the file gives them; ``calibrate`` checks it again from the joints the
controller reports, :func:`check_first_motion`, before anything moves).
"""

from __future__ import annotations

from collections.abc import Collection, Sequence
from dataclasses import dataclass

import numpy as np

from station.cell.config.cell_config import CellConfig
from station.cell.correction.precheck import check_correction
from station.cell.correction.robot_tools import check_tools, tool_grid
from station.cell.plan.collision import CollisionReport
from station.cell.plan.first_moves import check_first_move, check_locating_moves
from station.cell.plan.locating import Coverage, check_locating
from station.cell.plan.measurement_plan import Plan, build_plan
from station.cell.plan.run_path import check_plan
from station.cell.plan.steps import PlannedStep
from station.core.table.design import TableDesign
from station.errors import ConfigError

__all__ = ["Premotion", "premotion_check", "check_first_motion", "moves_lines", "moves_json"]


@dataclass(frozen=True)
class Premotion:
    """What the pre-motion checks found: the plan and the correction's design (None for a robot
    without a table)."""

    plan: Plan
    design: TableDesign | None
    locating: Coverage | None = None  # how far the search for the body reaches (issue 37)
    collision: CollisionReport | None = None  # the plan's collision check (issue 40)
    locating_moves: CollisionReport | None = None  # the search touches' (None: no search)
    first_move: CollisionReport | None = None  # from [conformance] park_joints (None: not given)


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
    searches = check_locating_moves(cfg, plan)  # and a search for the body that would
    first = None
    if cfg.conformance is not None:  # where the robot is parked: the first move from there
        steps = plan.run_steps(cfg.plan.verification_cycles, False)
        first = check_first_move(cfg, cfg.conformance.park_joints, steps[0], "[conformance] park_joints")
    return Premotion(plan, design, locating, collision, searches, first)


def check_first_motion(cfg: CellConfig, here: np.ndarray, steps: Sequence[PlannedStep],
                       done: Collection[int]) -> CollisionReport | None:
    """``calibrate``'s check of its first move, from ``here`` (the joints the controller reports)
    to the first step of ``steps`` not in ``done`` (the run's first touch: locating the body starts
    at the plan's first step), before anything moves; raises the
    :class:`~station.errors.UnreachableError` (exit 4) of a collision. None: nothing left to measure."""
    first = next((st for st in steps if st.index not in done), None)
    if first is None:
        return None
    return check_first_move(cfg, here, first, "where the robot stands (the joints the controller reports)")


def moves_lines(pre: Premotion) -> list[str]:
    """What ``station plan`` prints of the moves the plan does not hold (the first line of each
    check's report, with its least clearance)."""
    out = []
    for what, report, none in (("search touches of locating the body", pre.locating_moves, "no search "
                                "([plan] locate_steps = 0)"),
                               ("first move from [conformance] park_joints", pre.first_move, "not checked here "
                                "(no [conformance] park_joints): calibrate checks it from the joints it reads")):
        if report is None:
            out.append(f"  {what}: {none}")
            continue
        least = f"over {2 * report.margin_mm:g} mm" if report.closest is None else report.closest.describe()
        out.append(f"  {what}: {report.poses} poses checked, least clearance: {least}")
    return out


def moves_json(pre: Premotion) -> dict:
    """The same for ``station plan --json`` (the check's report: clearances in mm)."""
    return {"locating_moves": None if pre.locating_moves is None else pre.locating_moves.to_json(),
            "first_move": None if pre.first_move is None else pre.first_move.to_json()}
