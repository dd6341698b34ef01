"""Errors of the robot-controller driver, and how a reported error code becomes one.

The error codes and their messages are part of the register map (:mod:`drivers.controller_map`,
``docs/protocols.md``); the table errors live with the table data in
:mod:`drivers.correction_table`. :mod:`drivers.controller` re-exports all of them. This module
depends on the map and the table data only, never on the driver or its status objects: what
:func:`error_for` needs of a status is the structural :class:`ReportedError`.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime, timezone
from typing import Any, Protocol

import numpy as np

from .controller_map import (
    ERROR_MESSAGES,
    INFO_PAGES,
    MODBUS_EXCEPTION_MEANINGS,
    ORDER_CHECK_VALUE,
    Command,
    ControllerError,
    ErrorCode,
    RegisterDecodeError,
    WordOrder,
    decode,
    implausible_limits,
)
from .correction_table import TableError


class ReportedError(Protocol):
    """What the controller reported about a failed command (a status snapshot has these)."""

    @property
    def error_code(self) -> int: ...

    @property
    def error_joint(self) -> int: ...

    @property
    def error_bound(self) -> int: ...

__all__ = [
    "ModbusExceptionError",
    "RegisterWindowError",
    "ModbusResponseError",
    "MapVersionError",
    "WordOrderError",
    "ControllerConnectionError",
    "ControllerLinkLost",
    "CommandRejected",
    "MotionRejected",
    "MotionCollision",
    "MotionAborted",
    "EmergencyStop",
    "DriveFault",
    "SequenceError",
    "HandshakeTimeout",
    "MotionTimeout",
    "ClaimIdentity",
    "ControllerClaimed",
    "ClaimNotGranted",
    "error_message",
    "error_for",
    "word_order_problem",
    "checked_soft_limits",
]


class ModbusExceptionError(ControllerError):
    """The controller answered a request with a Modbus exception response."""

    def __init__(self, code: int, function_code: int, address: int, count: int):
        self.code = int(code)
        self.function_code = int(function_code)
        self.address = int(address)
        self.count = int(count)
        self.meaning = MODBUS_EXCEPTION_MEANINGS.get(self.code, "unknown exception code")
        super().__init__(
            f"Modbus exception {self.code} ({self.meaning}) for function {self.function_code} at "
            f"register {self.address} (count {self.count}): check the register map version and "
            f"word order configured for this controller; the request may be repeated once the "
            f"cause is fixed"
        )


class RegisterWindowError(ModbusExceptionError):
    """The controller refused an address of the map's window (exception 2): the window starts
    elsewhere, or is smaller than the map."""

    def __init__(self, code: int, function_code: int, address: int, count: int, base: int, size: int,
                 detail: str = ""):
        super().__init__(code, function_code, address, count)
        self.base = int(base)
        self.size = int(size)
        Exception.__init__(
            self,
            f"the controller refused register {self.address} (count {self.count}, function "
            f"{self.function_code}) with Modbus exception {self.code} ({self.meaning}){detail}: the "
            f"station expects map {self.size} registers at {self.base}..{self.base + self.size - 1}. Set "
            f"[devices] controller_register_base to the first register the robot program hosts "
            f"(128 for a Universal Robots controller's general-purpose registers) and make sure the "
            f"controller offers all {self.size} registers from there; nothing was commanded")


class ModbusResponseError(ControllerError):
    """The controller answered a request with a response that does not belong to it (another
    function code). The response is not used; requests are not repeated automatically."""

    def __init__(self, expected_fc: int, got_fc: int, address: int, count: int):
        self.expected_fc = int(expected_fc)
        self.got_fc = int(got_fc)
        self.address = int(address)
        self.count = int(count)
        super().__init__(
            f"the controller answered function {self.expected_fc} at register {self.address} "
            f"(count {self.count}) with function {self.got_fc} ({self.got_fc:#04x}): the response "
            f"does not belong to the request and was not used; check that only the robot "
            f"program answers on this address and port (gateway, second server, unit id)")


class MapVersionError(ControllerError):
    """The controller reports a register-map version this driver does not know."""

    def __init__(self, found: int, supported: tuple[int, ...], base: int = 0):
        self.found = int(found)
        self.supported = tuple(int(v) for v in supported)
        self.base = int(base)
        known = ", ".join(str(v) for v in self.supported)
        super().__init__(
            f"the controller reports register map version {self.found} (register {self.base + 2}); "
            f"this driver expects version {known}: nothing was commanded. Install the robot program "
            f"that speaks map version {known} (robot-programs/, docs/robot-program.md), or check "
            f"that [devices] controller_register_base = {self.base} is where the program hosts the map")


class WordOrderError(ControllerError):
    """The controller's 32-bit values decode plausibly only in the other word order."""

    def __init__(self, configured: Any, detected: Any, detail: str):
        self.configured = configured
        self.detected = detected
        super().__init__(
            f"word order mismatch: with the configured word order {configured.name} the "
            f"controller's soft limits decode as implausible values ({detail}); with "
            f"{detected.name} they are plausible. Set the link's word order to {detected.name} "
            f"([devices].word_order = \"{detected.value}\"); nothing was commanded")


class ControllerConnectionError(ControllerError):
    """No TCP connection, or no response to a request within the timeout."""


class ControllerLinkLost(ControllerError):
    """The heartbeat stopped (either side). Reconnect with connect() after checking the robot."""


class CommandRejected(ControllerError):
    """The controller refused a command (error reported with the command's sequence number)."""

    def __init__(self, message: str, code: int = 0, seq: int = 0):
        self.code = int(code)
        self.seq = int(seq)
        super().__init__(message)


class MotionRejected(CommandRejected):
    """A motion target was refused: soft limit, unreachable, outside the table, or not ready."""


class MotionCollision(MotionRejected):
    """The controller's own collision check refused a motion (error COLLISION): its target or the
    joint-space path to it collides in the controller's cell model. Nothing moved."""


class MotionAborted(CommandRejected):
    """The motion was aborted by a STOP command."""


class EmergencyStop(CommandRejected):
    """Emergency stop during (or before) the motion."""


class DriveFault(CommandRejected):
    """A drive reported a fault during the motion."""


class SequenceError(CommandRejected):
    """The controller did not accept the sequence number (not previous+1)."""


class HandshakeTimeout(ControllerError):
    """The controller did not acknowledge a command in time. The command was NOT re-sent."""


class MotionTimeout(ControllerError):
    """A motion did not complete within the caller's timeout (it may still be running)."""


@dataclass(frozen=True)
class ClaimIdentity:
    """Who holds the controller, as the holder wrote it into the claim block (map 3)."""

    host: str  # IPv4 address of the holder's socket to the controller ("0.0.0.0": not known)
    pid: int
    since: float  # UTC seconds since 1970 (0: not written yet)

    def describe(self) -> str:
        if not self.since:
            return "a station that has not named itself yet (host, PID and since still 0)"
        when = datetime.fromtimestamp(self.since, timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")
        host = self.host if self.host != "0.0.0.0" else "unknown (its link is not IPv4)"
        return f"host {host}, PID {self.pid}, since {when}"


class ControllerClaimed(ControllerError):
    """Another station holds the controller (map 3's claim): this one sent no command."""

    def __init__(self, holder: ClaimIdentity, owner_token: int, watchdog_ms: int = 0):
        self.holder = holder
        self.owner_token = int(owner_token)
        self.watchdog_ms = int(watchdog_ms)
        wd = f" ({self.watchdog_ms} ms without its heartbeat)" if self.watchdog_ms else ""
        super().__init__(
            f"the controller is held by another station: {holder.describe()}; nothing was commanded. One station "
            f"per controller: wait until that station's run ends, or stop it there; a station that died frees the "
            f"controller by the robot program's watchdog{wd}, nothing to clear by hand")


class ClaimNotGranted(ControllerError):
    """The program made another token the owner right after this station asked, and nobody named
    itself: the program takes ``claim_request`` wrongly (signed words, word order)."""

    def __init__(self, owner: int, token: int, waited: float):
        self.owner, self.token = int(owner), int(token)
        super().__init__(
            f"the robot program made {self.owner:#010x} the owner of the controller right after this station asked "
            f"with {self.token:#010x}, and no station named itself within {waited:.3g} s: the program does not take "
            f"claim_request as the map's u32 in the link's word order (signed 16-bit words, docs/robot-program.md); "
            f"nothing was commanded")


def error_message(code: int) -> str:
    try:
        return ERROR_MESSAGES[ErrorCode(code)]
    except ValueError:
        return f"unknown error code {code}: check the controller program's map version"


def error_for(st: ReportedError, seq: int, command: Command, target: Any,
              soft_limits: np.ndarray | None) -> ControllerError:
    """The typed error for command ``seq`` that the controller reported failed in ``st``.

    ``soft_limits`` (as read at connect, or None) and the command's ``target`` only enrich the
    message of a soft-limit violation.
    """
    code = st.error_code
    msg = f"{command.name} seq {seq}: {error_message(code)}"
    try:
        ec = ErrorCode(code)
    except ValueError:
        return CommandRejected(msg, code, seq)
    if ec is ErrorCode.SOFT_LIMIT:
        j = st.error_joint
        side = {-1: "lower", 1: "upper"}.get(st.error_bound, "a")
        detail = f"joint {j} violates its {side} soft limit"
        if soft_limits is not None and 1 <= j <= len(soft_limits) and st.error_bound in (-1, 1):
            lim = soft_limits[j - 1, 0 if st.error_bound < 0 else 1]
            detail += f" {lim:.6g}"
            if command is Command.MOVE_JOINTS and target is not None and j <= len(target):
                detail += f" (target {float(target[j - 1]):.6g})"
        return MotionRejected(f"{command.name} seq {seq}: {detail}: choose a target inside the limits",
                              code, seq)
    if ec is ErrorCode.BAD_COMMAND and command in (Command.MOVE_JOINTS, Command.MOVE_CARTESIAN) \
            and st.error_joint > 0:
        return MotionRejected(f"{msg} (joint {st.error_joint})", code, seq)
    if ec is ErrorCode.COLLISION:
        return MotionCollision(msg, code, seq)
    if ec in (ErrorCode.UNREACHABLE, ErrorCode.TARGET_OUTSIDE_TABLE, ErrorCode.NOT_READY,
              ErrorCode.BAD_COMMAND):
        return MotionRejected(msg, code, seq)
    if ec is ErrorCode.ESTOP:
        return EmergencyStop(msg, code, seq)
    if ec is ErrorCode.DRIVE_FAULT:
        return DriveFault(f"{msg} (axis {st.error_joint})", code, seq)
    if ec is ErrorCode.MOTION_ABORTED:
        return MotionAborted(msg, code, seq)
    if ec is ErrorCode.SEQUENCE_ERROR:
        return SequenceError(msg + "; reconnect to resynchronise (start the run again)", code, seq)
    if ec is ErrorCode.WATCHDOG_TIMEOUT:
        return ControllerLinkLost(msg)
    if ec in (ErrorCode.TABLE_CRC_MISMATCH, ErrorCode.TABLE_NOT_STAGED, ErrorCode.TABLE_SHAPE_INVALID,
              ErrorCode.NO_PREVIOUS_TABLE):
        return TableError(msg)
    return CommandRejected(msg, code, seq)


def word_order_problem(value: int, configured: WordOrder) -> ControllerError | None:
    """The error ``order_check`` = ``value`` means in the ``configured`` word order, or None:
    it holds 1 in the link's word order; 65536 means the other order."""
    if value == ORDER_CHECK_VALUE:
        return None
    other = WordOrder.LITTLE if configured is WordOrder.BIG else WordOrder.BIG
    if value == ORDER_CHECK_VALUE << 16:
        return WordOrderError(configured, other, f"order_check reads {value}, not {ORDER_CHECK_VALUE}")
    return RegisterDecodeError(
        f"order_check reads {value:#010x}, expected {ORDER_CHECK_VALUE} in either word order: the robot "
        f"program does not fill the register map as documented; check it")


def checked_soft_limits(raw: list[int], g: int, configured: WordOrder) -> np.ndarray:
    """Soft limits ``(g, 2)`` from the raw registers of info entry ``soft_limits``, decoded in
    the ``configured`` word order; if they are implausible there but plausible in the other
    order, the link's word order is wrong (:class:`WordOrderError`), else the map does not fit
    (:class:`RegisterDecodeError`)."""
    r = INFO_PAGES["soft_limits"][1]
    lim = np.asarray(decode(r, raw, configured), dtype=float)[:2 * g]
    problem = implausible_limits(lim, g)
    if problem is not None:
        other = WordOrder.LITTLE if configured is WordOrder.BIG else WordOrder.BIG
        if implausible_limits(decode(r, raw, other), g) is None:
            raise WordOrderError(configured, other, problem)
        raise RegisterDecodeError(
            f"the controller's soft limits are implausible in either word order ({problem}): "
            f"the robot program does not fill the register map as documented; check it")
    return lim.reshape(g, 2)
