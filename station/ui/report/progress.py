"""How far a run got, and the document ID its report carries on every printed page.

Every run that ends gets a report (issue 29): one that stopped before the identification (an
abort, a device fault after a few steps) or at the correction still has a record, a
configuration and the measurements it took. :func:`run_progress` says in one paragraph what was
measured and which phases were not reached; :func:`partial_report_data` is the report of a run
with nothing identified (no parameters, no residuals), whose sections then say so.
"""

from __future__ import annotations

import hashlib
import re
from collections.abc import Sequence
from typing import Any

import numpy as np

from station.cell.plan.steps import PlannedStep, StepKind
from station.cell.records.rundb import RunDB
from station.cell.records.summary import RunSummary
from station.errors import Outcome

__all__ = ["document_id", "run_progress", "partial_report_data"]

_SLUG = re.compile(r"[^A-Za-z0-9]+")

#: the phases of a calibration in order, as the report names them
_KIND_WORDS = ((StepKind.IDENTIFICATION, "identification"), (StepKind.REVERSAL, "reversal"),
               (StepKind.VERIFY_BEFORE, "verification before correction"),
               (StepKind.VERIFY_AFTER, "verification after correction"), (StepKind.REFERENCE, "oracle check"))


def _slug(text: str, limit: int = 24) -> str:
    return _SLUG.sub("-", text).strip("-")[:limit].strip("-")


def document_id(*, cell: str, serial: str, robot: str, run_id: int, created: str, config_toml: str) -> str:
    """``<cell>-<robot serial or name>-run<N>-<digest>``: letters, digits and hyphens only (it goes
    into the print style sheet). The digest (8 hex digits of SHA-256 over the run's creation time
    and configuration) tells apart two runs numbered alike in two run databases; a report
    rebuilt from the same run carries the same ID."""
    digest = hashlib.sha256(f"{created}\n{config_toml}".encode()).hexdigest()[:8]
    parts = [p for p in (_slug(cell), _slug(serial or robot)) if p]
    return "-".join([*parts, f"run{int(run_id)}", digest])


def run_progress(db: RunDB, run_id: int, steps: Sequence[PlannedStep], summary: RunSummary | None,
                 status: str) -> str:
    """What an unfinished run measured and which phases it did not reach; "" for a run that
    finished (SUCCESS, TARGET_MISSED, NOT_UPLOADED without a failure)."""
    finished = summary is not None and summary.failure is None and summary.outcome is not Outcome.ABORTED
    if finished:
        return ""
    done = db.completed_steps(run_id)
    counts = []
    for kind, words in _KIND_WORDS:
        planned = [st for st in steps if st.kind is kind]
        if planned:
            counts.append(f"{words} {sum(1 for st in planned if st.index in done)} of {len(planned)}")
    if summary is None:
        ended = f"the run has no stored outcome (database status '{status}': still running, or its process ended " \
                f"without one)"
    else:
        ended = f"the run ended {summary.outcome.name} (exit code {summary.exit_code})"
        if summary.failure is not None:
            ended += f": {summary.failure.message}"
    reached: list[str] = []
    missing: list[str] = []
    for name, got in (("the measurements", bool(done)),
                      ("the identification", summary is not None and summary.identification is not None),
                      ("the correction table", summary is not None and summary.correction is not None),
                      ("the upload", summary is not None and summary.upload is not None),
                      ("the verification after correction", summary is not None and summary.after is not None)):
        (reached if got else missing).append(name)
    text = f"{ended[0].upper()}{ended[1:]}. Steps measured: {len(done)} of {len(steps)}"
    text += f" ({'; '.join(counts)})." if counts else "."
    if reached:
        text += f" Reached: {', '.join(reached)}."
    if missing:
        text += f" Not reached: {', '.join(missing)}; the sections below say where a figure is missing for that reason."
    return text


def partial_report_data(*, robot_name: str, run_id: int, reason: str, **fields: Any) -> dict[str, Any]:
    """The :class:`~station.ui.report.contents.ReportData` fields of a run with nothing identified:
    no parameters, residuals or predicted accuracy; ``reason`` (why) goes into its notes."""
    empty = np.zeros(0)
    notes = (*fields.pop("notes", ()), f"nothing identified: {reason}")
    return dict(robot_name=robot_name, run_id=run_id, param_names=(), param_nominal=empty, param_identified=empty,
                param_sigma=empty, param_is_angle=np.zeros(0, dtype=bool), residuals=np.zeros((0, 3)),
                accuracy_xy_mm=np.zeros((0, 2)), accuracy_sigma_mm=empty, notes=notes, **fields)


def bare_report_for_run(db_path: str, run_id: int, out_dir: Any, why: str) -> Any:
    """The report of a stored run whose full report could not be built (``why``): its record,
    stored outcome and configuration, and how far it got. Returns the HTML path."""
    from pathlib import Path

    from station.ui.report.contents import ReportData
    from station.ui.report.writer import write_report

    with RunDB(db_path) as db:
        run = db.run(run_id)
        stored = db.load_result(run_id, "summary", default=None)
        try:
            summary = RunSummary.from_json(stored) if stored else None
        except (KeyError, TypeError, ValueError):
            summary = None
        try:
            steps: Sequence[PlannedStep] = tuple(PlannedStep.from_record(r) for r in run.plan)
            progress = run_progress(db, run_id, steps, summary, run.status)
        except Exception:  # noqa: BLE001 - the bare report must not fail on what the full one failed on
            progress = ""
    robot = summary.robot if summary is not None and summary.robot else "robot"
    ident = document_id(cell=summary.cell if summary is not None else "", serial="", robot=robot, run_id=run_id,
                        created=run.created_utc, config_toml=run.config_toml)
    data = ReportData(**partial_report_data(
        robot_name=robot, run_id=run_id, reason=f"the full report could not be built ({why})",
        errors_before_um=np.zeros(0), errors_after_um=np.zeros(0), summary=summary, created=run.created_utc,
        config_toml=run.config_toml, station_version=run.station_version, run_status=run.status,
        simulated=run.seed is not None, document_id=ident,
        progress=progress or f"The full report could not be built ({why}); this one holds the run's record only."))
    return write_report(Path(out_dir), data)
