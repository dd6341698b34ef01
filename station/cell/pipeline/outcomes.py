"""From an exception to an :class:`~station.errors.Outcome` and what the operator should do.

The one mapping, by type (``isinstance``), never by name. The CLI, ``--json``, the TUI and
``station check`` all classify through :func:`classify`. Order matters: the first matching
row wins, so the more specific driver errors come before their base classes.
"""

from __future__ import annotations

import traceback
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

from drivers.controller_errors import (
    ClaimNotGranted,
    CommandRejected,
    ControllerClaimed,
    ControllerConnectionError,
    ControllerLinkLost,
    DriveFault,
    EmergencyStop,
    HandshakeTimeout,
    MapVersionError,
    ModbusExceptionError,
    ModbusResponseError,
    MotionCollision,
    MotionTimeout,
    WordOrderError,
)
from drivers.controller_map import ControllerError
from drivers.correction_table import TableError, TableVerifyError
from drivers.probe_protocol import (
    ProbeDisconnected,
    ProbeError,
    ProbeFrameError,
    ProbeOutOfRange,
    ProbeTimeout,
)
from station.cell.correction.design import CorrectionRefused
from station.cell.records.summary import Failure, RunSummary
from station.cell.run.device_errors import ControllerHeld
from station.core.table.values import TableError as TableDataError
from station.errors import Outcome, RunAborted, StationError

#: the end of a hint; without a run to resume it becomes "then start again"
RESUME = "then continue with 'station calibrate CONFIG --resume RUN'"


@dataclass(frozen=True)
class _Row:
    types: tuple[type[BaseException], ...]
    outcome: Outcome
    hint: str
    #: the device whose error it is ("controller", "probe"), and whether the fault is its link (no
    #: answer, connection lost): the UI words its advice for a simulator, a serial line or TCP by these
    device: str = ""
    link: bool = False


_TABLE: tuple[_Row, ...] = (
    _Row((CorrectionRefused,), Outcome.CONFIG_ERROR,
         "nothing was measured: change [correction] (or the key the message names) as it says, then check with "
         "'station plan CONFIG' before starting again"),
    _Row((RunAborted,), Outcome.ABORTED, f"the robot stopped at a safe point; {RESUME}"),
    _Row((EmergencyStop,), Outcome.SAFETY_STOP, f"release the e-stop, check the cell, reset the controller, {RESUME}", device="controller"),
    _Row((DriveFault,), Outcome.SAFETY_STOP, f"clear the drive fault at the controller, {RESUME}", device="controller"),
    _Row((MotionCollision,), Outcome.UNREACHABLE,
         "nothing moved: the controller's collision check refused the motion (the message says which); check the "
         "plan with 'station plan CONFIG' against the cell's [[obstacle]] tables and the controller's cell model, "
         f"{RESUME}", device="controller"),
    _Row((TableVerifyError,), Outcome.UPLOAD_FAILED,
         "the table was NOT activated; check the link and the word order, then resume to upload again", device="controller"),
    _Row((TableError, TableDataError), Outcome.UPLOAD_FAILED,
         "the controller refused the table; check its capacity and map version, then resume", device="controller"),
    _Row((HandshakeTimeout,), Outcome.DEVICE_FAULT,
         f"the motion command was NOT re-sent; check the robot program, {RESUME}", device="controller", link=True),
    _Row((ControllerHeld, ControllerClaimed), Outcome.DEVICE_FAULT,
         "another station holds the controller (the message names it): let its run end or stop it there, then start "
         "again; a station that died frees the controller by the robot program's watchdog", device="controller"),
    _Row((ClaimNotGranted,), Outcome.DEVICE_FAULT,
         "the robot program does not keep the claim block as the map says: install the program from robot-programs/ "
         "and check it with 'station conformance CONFIG'", device="controller"),
    _Row((ControllerLinkLost,), Outcome.DEVICE_FAULT, f"check the network cable and the controller, {RESUME}", device="controller", link=True),
    _Row((ControllerConnectionError,), Outcome.DEVICE_FAULT,
         "check [devices].controller (host:port), that the robot program runs, and the network", device="controller", link=True),
    _Row((WordOrderError,), Outcome.CONFIG_ERROR, "set [devices].word_order as the message says, then run again", device="controller"),
    _Row((MapVersionError,), Outcome.DEVICE_FAULT,
         "the robot program implements another register map version: install the one the station supports, from "
         "robot-programs/ (docs/robot-program.md)", device="controller"),
    _Row((ModbusResponseError,), Outcome.DEVICE_FAULT,
         "the controller answered with the wrong function: check that the device at [devices].controller is "
         "the robot controller and device_id is right", device="controller"),
    _Row((ModbusExceptionError,), Outcome.DEVICE_FAULT,
         "check the register map version and [devices].word_order / device_id for this controller", device="controller"),
    _Row((MotionTimeout,), Outcome.DEVICE_FAULT,
         f"the motion did not finish in [devices].motion_timeout_s; check the robot, {RESUME}", device="controller", link=True),
    _Row((CommandRejected,), Outcome.DEVICE_FAULT, f"the controller refused a command; read its message, {RESUME}", device="controller"),
    _Row((ControllerError,), Outcome.DEVICE_FAULT, f"check the controller, {RESUME}", device="controller"),
    _Row((ProbeTimeout,), Outcome.DEVICE_FAULT, f"check the probe cable and [devices].baudrate, {RESUME}", device="probe", link=True),
    _Row((ProbeDisconnected,), Outcome.DEVICE_FAULT, f"reconnect the probe interface, {RESUME}", device="probe", link=True),
    _Row((ProbeOutOfRange,), Outcome.DEVICE_FAULT, f"check the probe named in the message, {RESUME}", device="probe"),
    _Row((ProbeFrameError,), Outcome.DEVICE_FAULT,
         f"the replies are garbled: check [devices].baudrate against the unit's setting and the cable, {RESUME}", device="probe", link=True),
    _Row((ProbeError,), Outcome.DEVICE_FAULT, f"check the probe interface and its cable, {RESUME}", device="probe"),
)


#: what to do about an outcome whose error has no row above (a station error's own message names the
#: key, file or value): never an empty hint, so that a script can always show one (issue 29)
_OUTCOME_HINTS: dict[Outcome, str] = {
    Outcome.INTERNAL_ERROR: "a bug in the station: report it with the log file the message names",
    Outcome.CONFIG_ERROR: "fix what the message names (the key, file or argument), then run the command again",
    Outcome.IDENTIFICATION_FAILED: "no correction was made; fix what the message names (measurements, robot file, "
                                   "[identification] or [correction]), then resume or run again",
    Outcome.UNREACHABLE: "nothing was moved; change what the message names (limits, body pose, set-up), then run again",
    Outcome.DATABASE_ERROR: "check the run database the message names (--db): the path, that it is a station run "
                            "database, and that its disk is writable; then run the command again",
    Outcome.ABORTED: f"the robot stopped at a safe point; {RESUME}",
    Outcome.DEVICE_FAULT: f"check the device the message names, its cable and its settings in [devices], {RESUME}",
    Outcome.SAFETY_STOP: f"make the cell safe, reset the controller ('station reset CONFIG'), {RESUME}",
    Outcome.UPLOAD_FAILED: "the table was NOT activated; check the controller and its link, then resume to upload again",
    Outcome.TARGET_MISSED: "read the report's acceptance table: check the robot, the set-up and [verification], then "
                           "calibrate again",
    Outcome.NOT_UPLOADED: "no correction is active: upload one with a run that is allowed to (no --no-upload)",
    Outcome.DRIFTED: "recalibrate the robot ('station calibrate CONFIG')",
    Outcome.RECHECK_UNTRUSTED: "check the probe head and the body, then run the recheck again",
}


def classify(exc: BaseException) -> Outcome:
    """The outcome a run that raised ``exc`` ends with; INTERNAL_ERROR for anything unknown."""
    for row in _TABLE:
        if isinstance(exc, row.types):
            return row.outcome
    if isinstance(exc, StationError):
        return exc.outcome
    return Outcome.INTERNAL_ERROR


def hint_for(exc: BaseException, run_id: int | None = None) -> str:
    """What the operator should do about ``exc`` (RUN replaced by the run number when known)."""
    text = ""
    own = getattr(exc, "hint", None)  # a station error that knows more than its class (ControllerHeld)
    for row in _TABLE:
        if isinstance(exc, row.types):
            text = row.hint
            break
    else:  # a station error's message says what to do; the hint says it in one line, never empty
        text = _OUTCOME_HINTS.get(classify(exc), _OUTCOME_HINTS[Outcome.INTERNAL_ERROR])
    if isinstance(own, str) and own:
        text = own
    if run_id is not None:
        return text.replace("RUN", str(run_id))
    # nothing was measured yet: there is no run to resume
    return text.replace(RESUME, "then start the run again").replace(", then resume to upload again", "")


def failure_summary(exc: BaseException, *, run_id: int | None, log_dir: str | Path,
                    cell: str = "", robot: str = "", db: str | None = None) -> RunSummary:
    """The summary of a run that ``exc`` stopped: outcome by type, what to do, and for an
    internal error its traceback written to a file in ``log_dir`` that the message names."""
    outcome = classify(exc)
    row = next((r for r in _TABLE if isinstance(exc, r.types)), None)
    message = str(exc) or type(exc).__name__
    log_file = None
    if outcome is Outcome.INTERNAL_ERROR:
        log_file = str(write_traceback(exc, log_dir))
        message = f"{type(exc).__name__}: {message} (traceback in {log_file})"
    return RunSummary(outcome=outcome, run_id=run_id, cell=cell, robot=robot, db=db,
                      failure=Failure(type(exc).__name__, message, hint_for(exc, run_id), log_file,
                                      device=row.device if row else "", link=bool(row and row.link)))


def write_traceback(exc: BaseException, directory: str | Path = ".") -> Path:
    """Write ``exc``'s traceback to ``station-error-<UTC time>.log`` in ``directory`` (the
    message of an internal error names this file); returns its path."""
    stamp = datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%S%fZ")
    path = Path(directory) / f"station-error-{stamp}.log"
    try:
        path.write_text("".join(traceback.format_exception(exc)), encoding="utf-8")
    except OSError:  # a read-only directory must not hide the error itself
        import tempfile

        path = Path(tempfile.gettempdir()) / path.name
        path.write_text("".join(traceback.format_exception(exc)), encoding="utf-8")
    return path
