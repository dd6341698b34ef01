"""Opening a cell and running a session on it: the one place that builds devices from a
configuration, for ``calibrate``, ``tui``, ``check`` and the tests.

:func:`open_cell` connects the probe head and the controller the configuration names (word
order, device id, timeouts included). :func:`load_cell` reads the configuration; a simulated
cell is composed above the cell (``station.ui.simulated_cell``, which starts the simulators) and
handed in as the session's ``load``: the cell layer never imports the simulators.
:func:`run_calibration_session` is what the CLI and the TUI call: it never raises for a run that
ends badly; it returns the :class:`~station.cell.records.summary.RunSummary` of whatever ended it, and
emits ``RunFailed``.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from drivers.controller import ModbusController
from drivers.controller_errors import ControllerClaimed
from drivers.controller_map import WordOrder
from drivers.probe_head import ProbeHead as SerialProbeHead
from station.cell.config.cell_config import CellConfig, load_config
from station.cell.pipeline.calibration import Options, run_calibration
from station.cell.pipeline.outcomes import classify, failure_summary, hint_for
from station.cell.publication.subscriber import FleetOutbox
from station.cell.records.judge import RunJudge
from station.cell.records.rundb import RunDB
from station.cell.records.summary import RunSummary
from station.cell.run.device_check import controller_lines, probe_lines, wired_channels_invalid
from station.cell.run.device_errors import ControllerHeld
from station.cell.run.devices import CellController, ProbeHead
from station.cell.run.facts.events import Event, Notice, PhaseChanged, RunFailed, RunStarted
from station.cell.run.facts.stream import RunStream
from station.cell.run.questions import Confirm
from station.cell.run.runcontrol import RunControl
from station.errors import ConfigError, Outcome, RunAborted
from station.io.robot_program import ur_program_needs

log = logging.getLogger(__name__)

__all__ = ["CellRequest", "CellLoader", "Devices", "LoadedCell", "open_cell", "open_probe", "open_controller", "load_cell", "check_cell", "CheckReport",
           "run_calibration_session", "reset_controller", "RunTracker", "store_failure", "FailureRecorder"]


@dataclass(frozen=True)
class CellRequest:
    """Which cell a command works on and how (the CLI's and the TUI's common arguments)."""

    config: str | None = None
    simulated: bool = False
    seed: int | None = None  # simulated: given, it overrides [simulation].seed; None: that seed, else 1
    time_scale: float = 0.0
    db: str = "runs.sqlite"
    resume: int | None = None
    upload: bool = True
    robot: str | None = None  # with simulated: the built-in simulated cell of this robot (sr800, irb2600)


@dataclass(frozen=True)
class Devices:
    probe: ProbeHead
    controller: CellController


@dataclass(frozen=True)
class LoadedCell:
    """A validated configuration; in simulation also the cell's judge (station/cell/records/judge.py)."""

    cfg: CellConfig
    judge: RunJudge | None = None
    endpoints: dict[str, Any] = field(default_factory=dict)


def check_probe_url(url: str) -> None:
    """A URL pyserial cannot use (``socket://`` without host and port, an unknown protocol) is a
    :class:`ConfigError` naming ``[devices] probe_head``, before anything is opened: pyserial's
    own failure names no key and may read like a Python error. A device path is left to opening."""
    if "://" not in url:
        return
    import serial

    why = ""
    try:
        port = serial.serial_for_url(url, do_not_open=True)
        from_url = getattr(port, "from_url", None)
        if callable(from_url):
            from_url(url)  # socket://, rfc2217://, loop://: their host, port and options
        return
    except (ValueError, serial.SerialException) as exc:
        why = f" ({str(exc).splitlines()[0][:160]})" if str(exc) else ""
    except Exception:  # noqa: BLE001 - pyserial's own slips (TypeError for 'socket://', KeyError for a bad port): not shown
        why = ""  # the ConfigError below names the key and the forms that work
    raise ConfigError(f"[devices] probe_head = {url!r}: not a serial port pyserial can open{why}; write a device "
                      f"such as /dev/ttyUSB0 or COM3, or a URL socket://HOST:PORT or rfc2217://HOST:PORT")


def open_probe(cfg: CellConfig, stack: ExitStack) -> ProbeHead:
    """The probe head interface named in ``cfg`` (closed when ``stack`` closes)."""
    d = cfg.devices
    check_probe_url(d.probe_head)
    probe: ProbeHead = stack.enter_context(SerialProbeHead(
        d.probe_head, baudrate=d.baudrate, timeout=d.probe_timeout_s, dialect=d.probe_protocol,
        bytesize=d.probe_bytesize, parity=d.probe_parity, refresh_s=d.probe_refresh_s))
    return probe


def open_controller(cfg: CellConfig, stack: ExitStack) -> CellController:
    """The controller named in ``cfg``, connected with its word order and device id (closed
    when ``stack`` closes)."""
    d = cfg.devices
    driver = ModbusController(d.controller_host, d.controller_port, device_id=d.device_id,
                              word_order=WordOrder.BIG if d.word_order == "big" else WordOrder.LITTLE,
                              timeout=d.controller_timeout_s, register_base=d.controller_register_base,
                              link_timeout=d.controller_link_timeout_s)
    try:
        driver.connect()
    except ControllerClaimed as exc:  # one station per controller: refused before any command
        raise ControllerHeld(
            f"controller {d.controller_host}:{d.controller_port}: {exc}",
            f"another station runs on this controller ({exc.holder.describe()}): let its run end or stop it "
            f"there, then start again; a station that died frees the controller by the robot program's "
            f"watchdog, nothing to clear by hand") from exc
    stack.callback(driver.close)
    controller: CellController = driver
    return controller


def open_cell(cfg: CellConfig, stack: ExitStack) -> Devices:
    """Connect the controller and the probe head named in ``cfg``; both are closed when ``stack``
    closes. The controller first: its claim is what refuses a second station, and a refused
    station must not have opened the probe head the holder's run reads either - except a probe
    device path that does not exist, which is reported as the probe's fault (nobody reads it)."""
    probe_path = cfg.devices.probe_head
    if probe_path.startswith("/") and not Path(probe_path).exists():
        open_probe(cfg, stack)  # raises the probe's own error: not plugged in, or the wrong path
    controller = open_controller(cfg, stack)
    return Devices(open_probe(cfg, stack), controller)


def describe_devices(devices: Devices) -> dict[str, str]:
    """What the report names as the devices: the probe interface's identification and the
    controller's register-map version."""
    info = {}
    try:
        ident = devices.probe.identify()
        fields = [f"{k} {getattr(ident, k)}" for k in ("model", "firmware", "channels") if hasattr(ident, k)]
        info["probe_interface"] = ", ".join(fields) if fields else str(ident)
    except Exception as exc:  # noqa: BLE001 - a missing identification must not stop a run
        info["probe_interface"] = f"not identified ({exc})"
    version = getattr(devices.controller, "map_version", None)
    info["controller_map_version"] = "unknown" if version is None else str(version)
    info["controller_correction"] = controller_correction(devices.controller)
    return info


#: what the robot program reports in correction_state (drivers.controller_map.CorrectionState),
#: as the run record names it
_CORRECTION_NAMES = {0: "none", 1: "vendor"}


def controller_correction(controller: object) -> str:
    """The controller's own kinematic correction as its robot program reports it: ``none``,
    ``vendor`` (a factory or absolute-accuracy correction is on) or ``unknown``."""
    state = getattr(controller, "correction_state", None)  # read by the driver on connect
    if state is None:  # a device that reports none (a test double): nothing to correct on top of
        return "none"
    return _CORRECTION_NAMES.get(int(state), "unknown")


def check_controller_correction(controller: object) -> str:
    """Refuse (ConfigError, before anything moves) a controller whose own correction state is
    unknown: the station identifies the robot as the controller drives it, so a table made on top
    of a correction that may be switched on or off later corrects the wrong robot."""
    state = controller_correction(controller)
    if state == "unknown":
        raise ConfigError("the robot program reports that the controller's own kinematic correction is in an unknown "
                          "state (correction_state): find out whether a vendor factory or absolute-accuracy "
                          "correction is on, and have the program report 0 (none) or 1 (vendor correction on) "
                          "(docs/robot-program.md)")
    return state


#: what builds the cell a request names (``station.ui.simulated_cell.load_cell`` composes the
#: simulated ones; :func:`load_cell` reads a real cell's configuration)
CellLoader = Callable[[CellRequest, ExitStack], LoadedCell]


def load_cell(request: CellRequest, stack: ExitStack) -> LoadedCell:
    """The request's configuration file. A simulated cell is composed above the cell layer (the
    cell never imports the simulators): the UI passes ``station.ui.simulated_cell.load_cell`` to
    the session functions as their ``load``."""
    if request.simulated:
        raise ConfigError("a simulated cell is started by the command that asks for it: pass "
                          "load=station.ui.simulated_cell.load_cell to the session")
    if not request.config:
        raise ConfigError("give a configuration file, or --simulated for the built-in simulated cell")
    return LoadedCell(load_config(request.config))


class RunTracker:
    """Forwards events and remembers the run they belong to (a failure summary names it)."""

    def __init__(self, emit: Callable[[Event], None]) -> None:
        self._emit = emit
        self.run_id: int | None = None

    def __call__(self, event: Event) -> None:
        if isinstance(event, RunStarted):
            self.run_id = event.run_id
        self._emit(event)


def run_calibration_session(request: CellRequest, emit: Callable[[Event], None],
                            control: RunControl | None = None, confirm: Confirm | None = None,
                            load: CellLoader | None = None) -> RunSummary:
    """Load the cell (``load``: :func:`load_cell` when not given; a simulated cell's loader is
    ``station.ui.simulated_cell.load_cell``), open its devices and run (or resume) a calibration.

    Returns the run's summary whatever happened; a failure is classified by type
    (:func:`station.cell.pipeline.outcomes.classify`), emitted as ``RunFailed`` and returned with its
    hint. An internal error (a bug) writes its traceback to a log file the message names.
    The run's events go to ``emit`` and to the fleet outbox, a subscriber of the session's stream
    once the cell is loaded (:class:`~station.cell.publication.subscriber.FleetOutbox`).
    """
    stream = RunStream(emit)  # the caller's views first, then the fleet outbox
    stream.subscribe(FailureRecorder(request.db), RunFailed, first=True)  # a failure stored before it is told
    tracker = RunTracker(stream)
    cell_name = robot = ""

    try:
        with ExitStack() as stack:
            loaded = (load or load_cell)(request, stack)  # the module's load_cell at call time
            cfg = loaded.cfg
            cell_name, robot = cfg.name, cfg.model.name
            FleetOutbox.subscribe(stream, request.db, cfg)  # a run that ends, finished or failed, is published
            db = stack.enter_context(RunDB(request.db, lock_new_runs=True))  # one process per run
            if request.resume is not None:  # refused here, before any device is connected
                stack.enter_context(db.lock_run(request.resume))
            emit(PhaseChanged("connect", "connecting the probe head and the controller"))
            if request.simulated:  # the simulators share this machine's CPU with the station
                d = cfg.devices
                emit(Notice("info", f"simulated cell: device deadlines allow for a loaded machine (probe reply "
                                    f"{d.probe_timeout_s:g} s, controller reply {d.controller_timeout_s:g} s, "
                                    f"controller heartbeat {d.controller_link_timeout_s:g} s)"))
            devices = open_cell(cfg, stack)
            check_head_channels(cfg, probe_channel_count(devices.probe))  # before anything moves
            check_controller_correction(devices.controller)
            seed = loaded.endpoints.get("seed", request.seed) if request.simulated else None
            summary = run_calibration(cfg, devices.probe, devices.controller, db, tracker, control,
                                      Options(upload=request.upload, judge=loaded.judge, confirm=confirm),
                                      resume_run=request.resume, seed=seed,
                                      devices_info=describe_devices(devices))
        return summary.replace(db=request.db)
    except Exception as exc:  # every failure becomes an outcome; nothing escapes as a traceback
        summary = failure_summary(exc, run_id=tracker.run_id, log_dir=Path(request.db).resolve().parent,
                                  cell=cell_name, robot=robot, db=request.db)
        stream(RunFailed(summary))  # stored first (FailureRecorder): the fleet outbox publishes it as stored
        return summary


def store_failure(db_path: str, run_id: int, record: dict[str, Any]) -> None:
    """Store a failed run's summary so that 'station runs' shows why it stopped. A database that
    cannot take it (the very error may be the database's) is logged, not raised: the failure
    itself is what must reach the operator."""
    try:
        with RunDB(db_path) as db:
            db.save_result(run_id, "summary", record)
    except Exception as exc:  # noqa: BLE001 - see above
        log.warning("run %s: the failure summary could not be stored in %s: %s", run_id, db_path, exc)


class FailureRecorder:
    """The run database's writer of a failed run's end, a subscriber of the session's stream (issue
    42): the :class:`RunFailed` summary of a run that has a number is stored (:func:`store_failure`,
    ``kind``: the record's ``kind`` where it is not a calibration's), so that 'station runs' shows
    why it stopped. Subscribed first, it stores before the views and the fleet outbox hear of it."""

    def __init__(self, db_path: str, kind: str | None = None) -> None:
        self.db_path, self.kind = db_path, kind

    def __call__(self, e: RunFailed) -> None:
        if e.summary.run_id is not None:
            kind = {"kind": self.kind} if self.kind else {}
            store_failure(self.db_path, e.summary.run_id, {**e.summary.to_json(), **kind})


def reset_controller(cfg: CellConfig, confirm: Callable[[str], bool]) -> tuple[str, ...]:
    """The documented recovery after an e-stop or a drive fault: show the controller's latched
    error, ask ``confirm(question)`` (the operator must have checked the cell), and only then
    send RESET. Motion commands are never retried by this; the run is continued with
    ``--resume``. Returns the lines to show; a controller that cannot be reached or fails on the
    way is :class:`~station.cell.run.device_errors.DeviceUnavailable` (exit 7) saying what to check."""
    from station.cell.run.device_errors import DeviceUnavailable
    from station.errors import StationError

    where = f"{cfg.devices.controller_host}:{cfg.devices.controller_port}"
    check = (f"check that the controller is powered and on the network, that [devices].controller ({where}) is "
             "its address and port, and that the robot program is running; then run 'station reset CONFIG' again")
    sent = False

    def device(call: Callable[[], Any]) -> Any:
        try:
            return call()
        except Exception as exc:  # a driver's error: only the device kinds are the operator's to fix
            if isinstance(exc, StationError) or classify(exc) is not Outcome.DEVICE_FAULT:
                raise
            what = ("the RESET may not have reached it: run 'station reset CONFIG' again to see its state"
                    if sent else "nothing was sent to it")
            raise DeviceUnavailable(f"the controller at {where} cannot be used ({exc}); {what}. "
                                    f"{check[0].upper()}{check[1:]}") from None

    with ExitStack() as stack:
        controller = device(lambda: open_controller(cfg, stack))
        st = device(controller.status)
        if not (st.error or st.estop):
            return (f"controller {where}: no latched error; nothing to reset",)
        what = "emergency stop" if st.estop else st.error_message
        question = (f"The controller reports: {what}. Is the e-stop released and the cell clear, and shall the "
                    f"controller's error be reset?")
        if not confirm(question):
            raise RunAborted("reset declined by the operator; nothing was sent to the controller")
        sent = True
        device(controller.reset_error)
        after = device(controller.status)
        if after.error or after.estop:
            raise ConfigError(f"the controller still reports {'an emergency stop' if after.estop else after.error_message} "
                              f"after RESET: release the e-stop or clear the fault at the controller first")
        return (f"reset sent; the controller reports ready={after.ready}", "continue with 'station calibrate CONFIG "
                "--resume RUN'")


@dataclass(frozen=True)
class CheckReport:
    """``station check``: one line per device, and the outcome (7 when a device failed)."""

    lines: tuple[str, ...]
    outcome: Outcome


def check_head_channels(cfg: CellConfig, n_channels: int) -> None:
    """Refuse (ConfigError) a probe interface with fewer channels than the head file wires, before
    the first motion: otherwise the first touch would find a probe without a reading."""
    head = cfg.head
    if head is None or n_channels <= 0:
        return
    channels = np.asarray(head.probe_channels, dtype=int)
    missing = [(head.probe_ids[i], int(c)) for i, c in enumerate(channels) if c > n_channels]
    if missing:
        named = ", ".join(f"{label} on channel {c}" for label, c in missing)
        raise ConfigError(f"the probe interface at {cfg.devices.probe_head} has {n_channels} channels, but the head "
                          f"file wires {named}: check the channel numbers in the head file ([head] file) and the "
                          f"interface unit's channel count")


def probe_channel_count(probe: ProbeHead) -> int:
    """Channels of the probe interface: from its identification, else from one snapshot."""
    n = getattr(probe.identify(), "channels", None)
    return int(n) if isinstance(n, int) else len(probe.read_all().status)


def check_cell(cfg: CellConfig) -> CheckReport:
    """Connect to every device of ``cfg``, read its identification and state, and compare the
    controller's soft limits with the configured ones. Every device is tried; the first
    failure decides the outcome."""
    lines: list[str] = []
    outcome = Outcome.SUCCESS
    d = cfg.devices
    with ExitStack() as stack:
        try:
            probe = open_probe(cfg, stack)
            info = probe.identify()
            snap = probe.read_all()
            lines.extend(probe_lines(d.probe_head, info, snap.status, cfg.head))
            check_head_channels(cfg, len(snap.status))
            if (invalid := wired_channels_invalid(snap.status, cfg.head)) is not None:
                raise invalid
        except Exception as exc:  # report every device, then fail
            outcome = classify(exc) if outcome is Outcome.SUCCESS else outcome
            lines.append(f"probe head {d.probe_head}: FAILED: {exc}")
            if hint := hint_for(exc):
                lines.append(f"  what to do: {hint}")
    with ExitStack() as stack:
        where = f"{d.controller_host}:{d.controller_port}"
        try:
            controller = open_controller(cfg, stack)
            st = controller.status()
            q = controller.read_joints()
            lim = controller.soft_limits()
            lines.extend(controller_lines(where, st, q.tolist(), cfg.model.joint_types, getattr(controller, "map_version", "?"),
                                          d.controller_register_base))
            state = check_controller_correction(controller)
            lines.append(f"  the controller's own correction: {state}"
                         + ("; the station's correction is identified and applied on top of it: keep it on"
                            if state == "vendor" else ""))
            tol = 1e-6 * np.maximum(1.0, np.abs(lim))  # the registers hold scaled i32 (1e-6): limits read back rounded
            wide = (cfg.soft_limits[:, 0] < lim[:, 0] - tol[:, 0]) | (cfg.soft_limits[:, 1] > lim[:, 1] + tol[:, 1])
            if np.any(wide):
                lines.append(f"  warning: [limits] are wider than the controller's soft limits for joints "
                             f"{[int(j) for j in np.nonzero(wide)[0] + 1]}")
        except Exception as exc:
            outcome = classify(exc) if outcome is Outcome.SUCCESS else outcome
            lines.append(f"controller {where}: FAILED: {exc}")
            if hint := hint_for(exc):
                lines.append(f"  what to do: {hint}")
    ur = ur_program_needs()
    # the UR program's cell: a six-axis arm whose map window is the program's (UR's general-purpose registers)
    if ur is not None and d.controller_register_base == ur.register_base and cfg.model.n_joints == 6 \
            and not cfg.model.is_scara:
        lines.append(f"  robot program (UR, window at register {ur.register_base}): robot-programs/ur/{ur.line()}")
    return CheckReport(tuple(lines), outcome)
