"""The run database's writer of a calibration's facts, a subscriber of its stream (issue 42).

The pipeline no longer writes its run's start, plan, identification, table, upload, status and
end to the run database itself: it emits them (:mod:`station.cell.run.facts.events`) and
:class:`RunWriter`, subscribed first to the runner's stream for the whole run, stores each one as
the pipeline stored it before (the same result keys, the same values: docs/run-database.md). The
measurements are :class:`~station.cell.run.facts.recorder.RunRecorder`'s, subscribed likewise while steps
are measured.

Being first, the writer stores a fact before any view hears of it (a view that reads the run
database back finds what it was told), and a write that fails (a full disk, a damaged file)
raises through the emit: the pipeline stops where it stands, before its next motion, with every
measurement made so far on disk (the recorder's guarantee), and the run's status says so.
"""

from __future__ import annotations

from functools import singledispatchmethod
from typing import Any

from station.cell.records.reading.stored_config import POSTPROCESSED_CONFIG
from station.cell.records.rundb import RunDB
from station.cell.run.facts.events import (
    CellChanged,
    Event,
    Identified,
    RunFinished,
    RunPlanned,
    RunStarted,
    StatusChanged,
    TableDesigned,
    Uploaded,
)

__all__ = ["RunWriter"]


class RunWriter:
    """Stores one calibration run's facts in ``db`` as they are streamed. ``run_id``: the run a
    resumed attempt continues; None for a new run, which :class:`RunPlanned` creates."""

    def __init__(self, db: RunDB, run_id: int | None = None) -> None:
        self.db = db
        self._run_id = run_id

    @property
    def run_id(self) -> int:
        """The run written to: the resumed one, or the one the run's :class:`RunPlanned` created."""
        if self._run_id is None:
            raise RuntimeError("no run yet: the writer creates one when it is told of a RunPlanned")
        return self._run_id

    def _of_this_run(self, run_id: int, what: str) -> int:
        if run_id != self.run_id:  # another run's stream: a slip that must not write here
            raise ValueError(f"run {run_id}'s {what} streamed to the writer of run {self.run_id}")
        return run_id

    @singledispatchmethod
    def __call__(self, event: Event) -> None:
        """Every other event (progress, notices, views' snapshots): nothing to store."""

    @__call__.register
    def _planned(self, e: RunPlanned) -> None:
        if self._run_id is not None:
            raise ValueError(f"a second run planned on the writer of run {self._run_id}")
        run_id = self.db.create_run(e.config_toml, [dict(step) for step in e.plan], seed=e.seed)
        self._run_id = run_id
        self.db.save_result(run_id, "config_source", e.config_source)
        self.db.save_result(run_id, "fingerprint", dict(e.fingerprint))

    @__call__.register
    def _changed(self, e: CellChanged) -> None:
        run_id = self._of_this_run(e.run_id, "changed cell")
        self.db.save_result(run_id, POSTPROCESSED_CONFIG, e.config_toml)
        self.db.save_result(run_id, "config_source", e.config_source)
        self.db.save_result(run_id, "fingerprint", dict(e.fingerprint))

    @__call__.register
    def _started(self, e: RunStarted) -> None:
        run_id = self._of_this_run(e.run_id, "start")
        if e.devices:  # the devices of the latest attempt, for the report
            self.db.save_result(run_id, "devices", dict(e.devices))
        self.db.log(run_id, "info", f"run {'resumed' if e.resume else 'started'}: {e.n_steps} steps, "
                                    f"{e.resumed_from} on disk")

    @__call__.register
    def _status(self, e: StatusChanged) -> None:
        if e.error:
            self.db.log(self.run_id, "error", e.error)
        if e.note:
            self.db.log(self.run_id, "info", e.note)
        self.db.set_status(self.run_id, e.status)

    @__call__.register
    def _identified(self, e: Identified) -> None:
        ident = e.identification
        record: dict[str, Any] = {
            "params": list(e.params), "chosen": [p.name for p in ident.parameters],
            "sigma": [p.sigma for p in ident.parameters],
            "covariance": e.covariance,  # of the chosen parameters, [mm, rad]² (the fleet store's)
            "rms_normalized": ident.rms_normalized, "outliers": list(ident.outliers),
            "residuals": e.residuals}
        self.db.save_result(self.run_id, "identification", record)
        self.db.set_status(self.run_id, "identified")

    @__call__.register
    def _designed(self, e: TableDesigned) -> None:
        c = e.correction
        self.db.save_result(self.run_id, "correction_grid", {
            **(e.grid or {}), "bound_um": c.interpolation_bound_um, "predicted_bound_um": c.predicted_bound_um,
            "sampled_bounds_um": list(e.sampled_bounds_um), "error_terms": e.error_terms})

    @__call__.register
    def _uploaded(self, e: Uploaded) -> None:
        self.db.set_status(self.run_id, "uploaded")

    @__call__.register
    def _finished(self, e: RunFinished) -> None:
        run_id = self.run_id if e.summary.run_id is None else self._of_this_run(e.summary.run_id, "end")
        self.db.save_result(run_id, "summary", e.summary.to_json())
