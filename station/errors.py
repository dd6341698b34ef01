"""Outcomes and typed errors of the station: the one definition of the exit codes.

Every layer imports this module (it imports nothing). An error class names its
:class:`Outcome`; ``station.cell.pipeline.outcomes`` maps every other exception (driver errors,
operating-system errors) to an outcome by type, and the CLI, ``--json``, the TUI and ``station
check`` all read the exit code from there. Every message says what to do about the error.
"""

from __future__ import annotations

import enum
from typing import ClassVar


class Outcome(enum.IntEnum):
    """How a station command ended; the value is its exit code (README's table is checked
    against this enum by a test)."""

    SUCCESS = 0
    INTERNAL_ERROR = 1
    CONFIG_ERROR = 2
    IDENTIFICATION_FAILED = 3
    UNREACHABLE = 4
    DATABASE_ERROR = 5
    ABORTED = 6
    DEVICE_FAULT = 7
    SAFETY_STOP = 8
    UPLOAD_FAILED = 9
    TARGET_MISSED = 10
    NOT_UPLOADED = 11
    DRIFTED = 12
    RECHECK_UNTRUSTED = 13

    @property
    def description(self) -> str:
        return _DESCRIPTIONS[self]


_DESCRIPTIONS = {
    Outcome.SUCCESS: "corrected, verified, gain ≥ 20×",
    Outcome.INTERNAL_ERROR: "a bug: the message names a log file with the traceback",
    Outcome.CONFIG_ERROR: "configuration or usage error (the message names the key and the fix)",
    Outcome.IDENTIFICATION_FAILED: "identification failed (rank deficiency, divergence, too few valid measurements)",
    Outcome.UNREACHABLE: "a motion would leave the soft limits or the reach — it was not commanded",
    Outcome.DATABASE_ERROR: "run database error",
    Outcome.ABORTED: "aborted by the operator at a safe point",
    Outcome.DEVICE_FAULT: "device fault (probe head or controller: missing, timeout, link lost, Modbus exception)",
    Outcome.SAFETY_STOP: "safety stop (emergency stop, drive fault)",
    Outcome.UPLOAD_FAILED: "correction table upload failed verification — it was not activated",
    Outcome.TARGET_MISSED: "verification showed less than the required gain, or a pose beyond [verification] max_ap_um / max_rp_um",
    Outcome.NOT_UPLOADED: "identified, but no correction is active: --no-upload, the operator declined or rolled it back, or no table within the controller's capacity meets correction.max_interpolation_um (JSON not_uploaded_reason correction_bound; the measurements are kept: resume with a looser bound or a smaller region)",
    Outcome.DRIFTED: "recheck: the robot drifted beyond the tolerance since its baseline calibration — recalibrate",
    Outcome.RECHECK_UNTRUSTED: "recheck: the measurement is not trustworthy (invalid readings, or the repeated pose moved) — no verdict",
}


class StationError(Exception):
    """Base of all station errors; the CLI turns these into a message and an exit code."""

    outcome: ClassVar[Outcome] = Outcome.CONFIG_ERROR

    @property
    def exit_code(self) -> int:
        return int(self.outcome)


class ConfigError(StationError, ValueError):
    """A robot file, cell configuration, measurement file or argument is not usable."""

    outcome = Outcome.CONFIG_ERROR


class IdentificationError(StationError):
    """The identification cannot give a trustworthy result (rank deficiency, divergence)."""

    outcome = Outcome.IDENTIFICATION_FAILED


class UnreachableError(StationError, ValueError):
    """A pose the robot cannot reach with the given configuration and limits."""

    outcome = Outcome.UNREACHABLE


class RunAborted(StationError):
    """The operator aborted the run; the robot was stopped at a safe point. Resume to continue."""

    outcome = Outcome.ABORTED


class MeasurementFault(StationError):
    """Readings failed repeatedly with the same cause (one probe out of range, a stuck channel):
    the run stopped at a safe point rather than measure garbage. The message names the probe."""

    outcome = Outcome.DEVICE_FAULT
