"""A run's configuration and plan read back from the run database, as the run was made with them.

The pipeline (on resume), the tools' correction, the recheck and the report all read them here;
this module sits below all of them, so none imports another to get at a stored run.
"""

from __future__ import annotations

from pathlib import Path

from station.cell.config import CellConfig, parse_text
from station.cell.rundb import RunDatabaseError, RunDB
from station.cell.steps import PlannedStep

__all__ = ["config_source", "stored_config", "stored_plan"]


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
    return parse_text(db.run(run_id).config_toml, source or f"run {run_id}")


def stored_plan(db: RunDB, run_id: int) -> tuple[PlannedStep, ...]:
    """The run's plan as typed steps."""
    try:
        return tuple(PlannedStep.from_record(rec) for rec in db.run(run_id).plan)
    except (KeyError, ValueError, TypeError) as exc:
        raise RunDatabaseError(f"run {run_id}: the stored plan is not readable ({exc}); start a new run") from None
