"""Opening a cell for ``station recheck`` (and the simulated cell with drift): what
:mod:`station.cell.session` does for ``calibrate``, for a recheck.

``--simulated [CONFIG]``: the built-in simulated cell; from CONFIG (when given) its
``[simulation]`` table (seed, thermal model, step change: ``simulators/thermal.py``) starts the
simulator, and its ``[recheck]`` and ``[warmup]`` tables are added to the simulated cell's
configuration.
"""

from __future__ import annotations

import tomllib
from collections.abc import Callable
from contextlib import ExitStack
from pathlib import Path
from typing import Any

from station.cell.config import MAX_CONFIG_BYTES, parse_text, simulation_settings
from station.cell.events import Event, PhaseChanged, RunFailed
from station.cell.outcomes import failure_summary
from station.cell.recheck import RecheckOptions, RecheckSummary, run_recheck
from station.cell.runcontrol import RunControl
from station.cell.rundb import RunDB
from station.cell.session import (
    CellRequest,
    LoadedCell,
    RunTracker,
    describe_devices,
    load_cell,
    open_cell,
    store_failure,
)
from station.cell.summary import RunSummary
from station.io.robot_files import read_user_text

#: the tables of a CONFIG given with --simulated that the simulated cell's configuration takes over
_TAKEN = ("recheck", "warmup")


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {v!r} as TOML")


def load_simulated(config: str | None, seed: int, time_scale: float, stack: ExitStack) -> LoadedCell:
    """The built-in simulated cell, with the drift, recheck and warm-up settings of ``config``."""
    from simulators import start_simulated_cell
    from simulators.reference_cell import cell_config_text

    data: dict[str, Any] = {}
    sim: dict[str, Any] = {}
    if config:
        text = read_user_text(Path(config), MAX_CONFIG_BYTES, "configuration file",
                              missing=f"no such configuration file: {config}")
        sim = simulation_settings(text, config)
        data = tomllib.loads(text)
    given = sim.pop("seed", None)
    seed = seed if given is None else int(given)
    servers = start_simulated_cell(seed=seed, time_scale=time_scale, **sim)
    stack.callback(servers.stop)
    text = cell_config_text(servers, seed)
    for table in _TAKEN:
        if isinstance(data.get(table), dict):
            text += f"\n[{table}]\n" + "".join(f"{k} = {_toml_value(v)}\n" for k, v in data[table].items())
    cfg = parse_text(text, f"<simulated cell{' with ' + config if config else ''}>")
    return LoadedCell(cfg, servers.cell.truth, servers.endpoints())


def run_recheck_session(request: CellRequest, emit: Callable[[Event], None], control: RunControl | None = None,
                        options: RecheckOptions | None = None,
                        on_cell: Callable[[LoadedCell], None] | None = None) -> RecheckSummary | RunSummary:
    """Load the cell, open its devices and run (or resume) a recheck. Never raises: a failure
    is classified, emitted as ``RunFailed`` and returned as a :class:`RunSummary`.
    ``on_cell``: called with the loaded cell (a test reaches the simulator's state through it)."""
    tracker = RunTracker(emit)
    cell_name = robot = ""

    try:
        with ExitStack() as stack:
            loaded = load_cell(request, stack)  # simulated: the same cells as calibrate (rehearsal or built-in)
            if on_cell is not None:
                on_cell(loaded)
            cfg = loaded.cfg
            cell_name, robot = cfg.name, cfg.model.name
            db = stack.enter_context(RunDB(request.db))
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
        if tracker.run_id is not None:
            store_failure(request.db, tracker.run_id, {**failed.to_json(), "kind": "recheck"})
        emit(RunFailed(failed))
        return failed
