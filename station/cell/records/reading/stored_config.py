"""A run's configuration and plan read back from the run database, as the run was made with them.

The pipeline (on resume), the tools' correction, the recheck and the report all read them here;
this module sits below all of them, so none imports another to get at a stored run.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Protocol

import numpy as np

from station.cell.config.cell_config import CellConfig, parse_text
from station.cell.plan.steps import PlannedStep
from station.cell.records.record_checks import check_step_joints, checked
from station.cell.records.record_fields import RunContext, check_plan_against
from station.cell.records.run_records import RunRecord
from station.errors import StationError

__all__ = ["POSTPROCESSED_CONFIG", "config_source", "run_context", "stored_config", "stored_plan"]

#: how far beyond the robot's joint limits a stored joint may lie (read-back, wrapping): a fraction of the range
JOINT_MARGIN = 0.1

#: result key of the configuration text a resume with changed post-processing finished the run with
POSTPROCESSED_CONFIG = "config_toml_resumed"


class RunDB(Protocol):
    """What these readers need of the run database (:class:`station.cell.records.rundb.RunDB`
    satisfies it; the database itself calls :func:`run_context`, so importing it here would be a
    circle)."""

    def run(self, run_id: int) -> RunRecord: ...
    def load_result(self, run_id: int, key: str, default: Any = ...) -> Any: ...


def config_source(cfg: CellConfig) -> str:
    """Where ``cfg`` was read, absolute (a label such as ``<simulated cell>`` as it is): a run
    stores it so that its relative robot, head and body files resolve beside the configuration
    when the run is resumed or reported from another directory."""
    if not cfg.source or cfg.source.startswith("<"):
        return cfg.source
    return str(Path(cfg.source).resolve())


def stored_config(db: RunDB, run_id: int) -> CellConfig:
    """The configuration run ``run_id`` was made with, read from its stored text; relative files
    resolve beside the configuration file it came from (:func:`config_source`)."""
    source = db.load_result(run_id, "config_source", default=None)
    # a resume with only post-processing changed (the correction grid, tolerances, [cell] …) stores
    # the configuration it finished with: the table and the report are made with that one
    text = db.load_result(run_id, POSTPROCESSED_CONFIG, default=None)
    if not isinstance(text, str):
        text = db.run(run_id).config_toml
    return parse_text(text, source or f"run {run_id}")


def stored_plan(db: RunDB, run_id: int, n_joints: int | None = None) -> tuple[PlannedStep, ...]:
    """The run's plan as typed steps, checked: one joint value per joint of the robot the run was
    made with (``n_joints``; by default the stored configuration's robot), a known step kind."""
    plan = db.run(run_id).plan
    steps = tuple(checked(run_id, f"plan step {i}", PlannedStep.from_record, rec)
                  for i, rec in enumerate(plan))
    check_step_joints(plan, run_id, _stored_joint_count(db, run_id) if n_joints is None else n_joints)
    return steps


def _stored_joint_count(db: RunDB, run_id: int) -> int | None:
    """The joints of the stored configuration's robot; None where it does not read (its robot file
    moved): then the steps are only checked against each other, and the configuration's reader
    reports its own error."""
    try:
        return int(stored_config(db, run_id).model.n_joints)
    except StationError:
        return None


def run_context(db: RunDB, run_id: int) -> RunContext | None:
    """What the run's stored configuration says its records hold: the robot's joints and their
    range (its limits widened by :data:`JOINT_MARGIN`), the body's points, the head's probes.
    None where the configuration does not read (its robot file moved): the records are then checked
    without it, and the configuration's reader reports its own error where it is needed."""
    try:
        cfg = stored_config(db, run_id)
    except StationError:
        return None
    limits = np.asarray(cfg.model.joint_limits, dtype=float)
    margin = JOINT_MARGIN * (limits[:, 1] - limits[:, 0])
    lo, hi = tuple((limits[:, 0] - margin).tolist()), tuple((limits[:, 1] + margin).tolist())
    head = cfg.head
    ctx = RunContext(n_joints=int(cfg.model.n_joints), joint_lo=lo, joint_hi=hi,
                     point_ids=tuple(str(p) for p in cfg.point_ids),
                     n_probes=None if head is None else len(head.probe_channels))
    check_plan_against(db.run(run_id).plan, run_id, ctx)
    return ctx
