"""``station tui``: the operator UI over the same session as ``station calibrate``.

The UI gets a ``start_run(emit, control, confirm=, resume=)`` callable; the session opens the
devices in the worker thread the UI runs it in, and its summary is the exit code.  With ``recheck=RecheckOptions(...)`` the
same UI runs a recheck (``station tui --recheck``, issue 13): its outcome and drift figures fill the
result panel, and only rechecks are offered to resume.  The run
database is read (the unfinished runs, a run's results) and the report written through callables
the UI runs in worker threads; the report goes into ``report-<db name>-run-N/`` next to the database.
"""

from __future__ import annotations

import dataclasses
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

from station.cell.recheck.measure import RecheckOptions, RecheckSummary
from station.cell.recheck.session import run_recheck_session
from station.cell.records.reading.run_list import RunInfo, list_runs
from station.cell.records.rundb import RunDB
from station.cell.records.summary import RunSummary
from station.cell.run.facts.events import Event
from station.cell.run.questions import Confirm
from station.cell.run.runcontrol import RunControl
from station.cell.session.calibrate import CellRequest, run_calibration_session
from station.ui.report.paths import report_dir
from station.ui.report.writer import ReportData
from station.ui.simulated_cell import load_cell
from station.ui.tui.app import StationApp
from station.ui.tui.result_panel import CellContext, device_kind

__all__ = ["launch", "make_app", "recheck_run_summary", "cell_context"]


def recheck_run_summary(s: RecheckSummary) -> RunSummary:
    """A recheck's end as the result panel shows it: its outcome and exit code, the baseline and
    the drift figures as notes (the lines ``station recheck`` prints)."""
    b, r = s.baseline, s.result
    notes = [f"against run {b.run_id} ({b.created_utc[:19]} UTC), baseline accuracy {b.accuracy_um:.1f} µm"]
    if r is not None:
        if r.rms_um is not None and r.max_um is not None:
            notes.append(f"drift over {r.n_valid}/{r.n_planned} poses: RMS {r.rms_um:.1f} µm "
                         f"(tolerance {r.tolerances.position_um:.1f}), max {r.max_um:.1f} µm")
        if r.rms_arcsec is not None and r.max_arcsec is not None:
            notes.append(f"angular drift: RMS {r.rms_arcsec:.1f}″, max {r.max_arcsec:.1f}″")
        if r.repeat_um is not None:
            notes.append(f"repeated first pose: {r.repeat_um:.1f} µm (at most {r.tolerances.repeat_um:.1f})")
        if r.moved:
            notes.append("parameters moved: " + ", ".join(r.moved))
        notes.extend(r.reasons)
    if s.warmup:
        notes.append(f"warm-up: {s.warmup.get('cycles')} cycles, "
                     f"{'converged' if s.warmup.get('converged') else 'NOT converged'}")
    if s.outcome.name == "DRIFTED":
        notes.append("what to do: recalibrate ('station calibrate CONFIG')")
    elif s.outcome.name == "RECHECK_UNTRUSTED":
        notes.append("what to do: check the probe head and the body, warm the robot up ([warmup]), and recheck")
    return RunSummary(outcome=s.outcome, run_id=s.run_id, cell=s.cell, robot=s.robot, db=s.db,
                      notes=(*notes, *s.notes))


def make_app(request: CellRequest, title: str | None = None, app_class: type[StationApp] = StationApp,
             recheck: RecheckOptions | None = None, **kwargs: object) -> StationApp:
    """The operator UI wired to ``request``'s cell and run database; with ``recheck`` it runs a
    recheck against the baseline calibration instead of a calibration."""
    cell = cell_context(request, recheck is not None)
    db = request.db

    def start_run(emit: Callable[[Event], None], control: RunControl, confirm: Confirm | None = None,
                  resume: int | None = None) -> RunSummary:
        req = dataclasses.replace(request, resume=resume) if resume is not None else request
        if recheck is None:
            return run_calibration_session(req, emit, control, confirm, load=load_cell)
        summary = run_recheck_session(req, emit, control, recheck, load=load_cell)
        return summary if isinstance(summary, RunSummary) else recheck_run_summary(summary)

    def runs() -> list[RunInfo]:
        if not Path(db).exists():
            return []
        with RunDB(db) as rdb:
            found = list_runs(rdb)
        return [r for r in found if r.kind == "recheck"] if recheck is not None else found

    def load_results(run_id: int) -> ReportData:
        from station.ui.report.run import report_data_for_run

        with RunDB(db) as rdb:
            return report_data_for_run(rdb, run_id)

    def write_report(run_id: int) -> Path:
        from station.ui.report.run import report_for_run

        return Path(report_for_run(db, run_id, report_dir(db, run_id)))

    # The session writes its tracebacks next to the database; an escaping one goes there too.
    # A recheck has no calibration report: its figures are in the result panel and the database.
    app = app_class(start_run, log_dir=Path(db).resolve().parent, list_runs=runs,
                    load_results=load_results, write_report=write_report if recheck is None else None,
                    db_label=str(db), cell=cell,
                    **kwargs)  # type: ignore[arg-type]
    if title is not None:
        app.title = title
    return app


def cell_context(request: CellRequest, recheck: bool = False) -> CellContext:
    """The cell as the UI names it and advises on it: its ``[cell] name``, the command line's
    arguments, and each device's kind (a simulator; a serial or TCP probe interface). Read from
    the configuration's text without validating it: the session validates it when a run starts
    (and the title takes the name the session read)."""
    table: dict[str, Any] = {}
    if request.config:
        try:
            table = tomllib.loads(Path(request.config).read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
            table = {}
    section = table.get("cell")
    name = section.get("name") if isinstance(section, dict) else None
    if not isinstance(name, str) or not name:
        # the built-in cell's configuration is written by the simulators when a run starts: the title
        # names it as such rather than change to that file's name mid-run
        builtin = "built-in simulated cell" + (f" ({request.robot})" if request.robot else "")
        name = builtin if request.simulated and not request.config else Path(request.config or "cell").name
    devices = table.get("devices")
    port = devices.get("probe_head") if isinstance(devices, dict) else None
    return CellContext(name=name, config=request.config, simulated=request.simulated, seed=request.seed,
                       robot=request.robot, db=request.db, verb="recheck" if recheck else "calibrate",
                       probe="simulator" if request.simulated else device_kind(str(port or "")),
                       controller="simulator" if request.simulated else "tcp")


def launch(request: CellRequest, title: str | None = None, recheck: RecheckOptions | None = None) -> int:
    """Run the operator UI on ``request``'s cell until the operator quits; returns the exit
    code of the last run (0 when none was started).  ``recheck``: run rechecks, not calibrations."""
    app = make_app(request, title, StationApp, recheck=recheck)
    app.run()
    return int(app.return_code or 0)
