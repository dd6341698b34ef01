"""Running ``station recheck`` on a cell: what :mod:`station.cell.session.calibrate` does for
``calibrate``, for a recheck.

The cell is loaded like a calibration's (``load``; simulated: ``station.ui.simulated_cell``
composes the same cells as for ``calibrate``, the rehearsal or the built-in one, with the
``[simulation]``, ``[recheck]`` and ``[warmup]`` of a CONFIG given with it).
"""

from __future__ import annotations

from collections.abc import Callable
from contextlib import ExitStack
from pathlib import Path

from station.cell.pipeline.outcomes import failure_summary
from station.cell.publication.subscriber import FleetOutbox
from station.cell.recheck.measure import RecheckOptions, RecheckSummary, run_recheck
from station.cell.records.rundb import RunDB
from station.cell.records.summary import RunSummary
from station.cell.run.facts.events import Event, PhaseChanged, RunFailed
from station.cell.run.facts.stream import RunStream
from station.cell.run.runcontrol import RunControl
from station.cell.session.calibrate import (
    CellLoader,
    CellRequest,
    FailureRecorder,
    LoadedCell,
    RunTracker,
    describe_devices,
    load_cell,
    open_cell,
)


def run_recheck_session(request: CellRequest, emit: Callable[[Event], None], control: RunControl | None = None,
                        options: RecheckOptions | None = None,
                        on_cell: Callable[[LoadedCell], None] | None = None,
                        load: CellLoader | None = None) -> RecheckSummary | RunSummary:
    """Load the cell (``load``, default :func:`~station.cell.session.calibrate.load_cell`), open its devices
    and run (or resume) a recheck. Never raises: a failure is classified, emitted as
    ``RunFailed`` and returned as a :class:`RunSummary`.
    ``on_cell``: called with the loaded cell (a test reaches the simulator's state through it)."""
    stream = RunStream(emit)  # the caller's views first, then the fleet outbox (a recheck's end is published)
    stream.subscribe(FailureRecorder(request.db, "recheck"), RunFailed, first=True)  # stored before it is told
    tracker = RunTracker(stream)
    cell_name = robot = ""

    try:
        with ExitStack() as stack:
            loaded = (load or load_cell)(request, stack)  # simulated: the same cells as calibrate
            if on_cell is not None:
                on_cell(loaded)
            cfg = loaded.cfg
            cell_name, robot = cfg.name, cfg.model.name
            FleetOutbox.subscribe(stream, request.db, cfg)
            db = stack.enter_context(RunDB(request.db, lock_new_runs=True))  # one process per run
            if request.resume is not None:  # refused here, before any device is connected
                stack.enter_context(db.lock_run(request.resume))
            emit(PhaseChanged("connect", "connecting the probe head and the controller"))
            devices = open_cell(cfg, stack)
            summary = run_recheck(cfg, devices.probe, devices.controller, db, tracker, control,
                                  options or RecheckOptions(),
                                  resume_run=request.resume,
                                  seed=loaded.endpoints.get("seed", request.seed) if request.simulated else None,
                                  devices_info=describe_devices(devices))
        return summary.replace(db=request.db)
    except Exception as exc:  # every failure becomes an outcome; nothing escapes as a traceback
        failed = failure_summary(exc, run_id=tracker.run_id, log_dir=Path(request.db).resolve().parent,
                                 cell=cell_name, robot=robot, db=request.db)
        if failed.failure is not None and tracker.run_id is not None:
            failed = failed.replace(failure=failed.failure.__class__(
                failed.failure.error_type, failed.failure.message,
                failed.failure.hint.replace("station calibrate", "station recheck"), failed.failure.log_file))
        stream(RunFailed(failed))  # stored first (FailureRecorder): the fleet outbox publishes it as stored
        return failed
