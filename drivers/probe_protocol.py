"""Probe-head serial protocol: the single source of truth for driver and simulator.

The protocol is modelled on the Keyence DL-RS1A family (brief §9); the full frame-by-frame
description is ``docs/protocols.md``, section "Probe-head serial protocol". In short:

* ASCII. A request ends with CR (``\\r``) or CR LF; a reply always ends with CR LF.
* Fields are separated by commas; the first field of a reply echoes the command name.
* A reading is ``sign + 3 digits + '.' + 4 digits`` in millimetres (0.1 µm resolution), e.g.
  ``+012.3456``, or one of three markers: ``+FFFFFFF`` over range, ``-FFFFFFF`` under range,
  ``XXXXXXXX`` invalid (no target, sensor fault, not ready).
* An error is ``ER,<command>,<code>`` with a two-digit code from :data:`ERROR_CODES`.
* Channels are numbered ``00`` .. ``14`` on the wire, the same 0-based index the driver uses.

Everything here is pure: ``format_*`` build frames, ``parse_*`` check and decode them and raise
only :class:`ProbeError` subclasses, for any input whatsoever (the tests fuzz them). The probe
error types live here too, because the parsers raise them and the driver re-exports them.
"""

from __future__ import annotations

import enum
import math
import re
from dataclasses import dataclass

import numpy as np

__all__ = [
    "ProbeError",
    "ProbeTimeout",
    "ProbeFrameError",
    "ProbeDeviceError",
    "ProbeSpreadError",
    "ProbeDisconnected",
    "ProbeOutOfRange",
    "ProbeConfigError",
    "ProbeLineSettingsError",
    "ProbeDialectMismatch",
    "ProbeLineGarbled",
    "ProbeUnsettled",
    "ErrorAction",
    "ChannelStatus",
    "Field",
    "CommandSpec",
    "COMMANDS",
    "ErrorCode",
    "ERROR_CODES",
    "ERR_UNKNOWN_COMMAND",
    "ERR_BAD_PARAMETER",
    "ERR_OUT_OF_RANGE",
    "ERR_NO_CHANNEL",
    "ERR_NOT_MEASURING",
    "ERR_BUSY",
    "MARKERS",
    "MAX_CHANNELS",
    "MAX_REQUEST_BYTES",
    "REPLY_TERMINATOR",
    "VALUE_LIMIT_MM",
    "Request",
    "DeviceInfo",
    "format_value",
    "format_fixed_value",
    "parse_value",
    "format_request",
    "parse_request",
    "format_reply",
    "format_error",
    "parse_reply",
    "parse_m0",
    "parse_ms",
    "parse_id",
    "parse_ack",
    "reply_names",
    "RESYNC_COMMAND",
]

# --------------------------------------------------------------------------------------------
# Errors (one place for the whole probe stack; the driver re-exports them)
# --------------------------------------------------------------------------------------------


class ProbeError(Exception):
    """Base of every probe-head error."""


class ProbeTimeout(ProbeError):
    """No complete reply (CR LF) arrived within the timeout."""


class ProbeFrameError(ProbeError):
    """A reply was malformed, garbled, truncated or did not answer the request sent."""


class ErrorAction(enum.Enum):
    """What the driver does with an error reply (each dialect's error table names one)."""

    RETRY = "repeat a read-only request at once"
    RETRY_AFTER_WAIT = "repeat a read-only request after the dialect's wait (unit starting up, busy)"
    DEVICE_FAULT = "stop: the unit or its sensors need attention"
    CONFIG_ERROR = "stop: the configuration (line settings, channels, dialect) does not match the unit"
    DRIVER_ERROR = "stop: the request was malformed (a driver bug or another dialect)"


class ProbeDeviceError(ProbeError):
    """The unit answered with an error reply (``ER,<command>,<code>`` in the ASCII dialects).

    ``errors``: the dialect's error table (default: station-ascii's :data:`ERROR_CODES`);
    ``dialect``: its name, for the message. A code the table lacks is not retried."""

    def __init__(self, command: str, code: int, detail: str = "", errors: "dict[int, ErrorCode] | None" = None,
                 dialect: str = "station-ascii") -> None:
        self.command = command
        self.code = code
        self.dialect = dialect
        spec = (ERROR_CODES if errors is None else errors).get(code)
        self.meaning = spec.meaning if spec else "unknown error code"
        self.retryable = spec.retryable if spec else False
        self.action = spec.effective_action if spec else ErrorAction.DEVICE_FAULT
        advice = spec.advice if spec else f"the {dialect} table has no code {code:02d}; consult the unit's manual"
        msg = f"probe unit refused {command!r}: error {code:02d} ({self.meaning}); {advice}"
        if detail:
            msg += f" [{detail}]"
        super().__init__(msg)


class ProbeSpreadError(ProbeError):
    """Averaged readings of a channel scattered more than the allowed peak-to-peak bound."""

    def __init__(self, channel: int, spread_mm: float, bound_mm: float) -> None:
        self.channel = channel
        self.spread_mm = spread_mm
        self.bound_mm = bound_mm
        super().__init__(
            f"channel {channel:02d} scattered {spread_mm * 1000:.2f} µm peak-to-peak over the "
            f"averaged snapshots (bound {bound_mm * 1000:.2f} µm): the head or robot is still "
            "moving or vibrating; let it settle and measure again, or check the probe's mounting"
        )


class ProbeDisconnected(ProbeError):
    """The serial port went away or could not be opened."""


class ProbeOutOfRange(ProbeError):
    """One or more channels are not inside their measuring range (raised by the station)."""

    def __init__(self, statuses: dict[int, "ChannelStatus"]) -> None:
        self.statuses = dict(statuses)
        listing = ", ".join(f"{ch:02d}: {st.name}" for ch, st in sorted(self.statuses.items()))
        super().__init__(
            f"probe channels not in range ({listing}): the cube is not where the head expects "
            "it; check the measuring point's nominal position and the robot's approach pose"
        )


class ProbeConfigError(ProbeError):
    """The station's probe configuration cannot work with the named dialect (unknown dialect,
    line settings the unit does not offer). The lead maps it to a configuration error (exit 2)."""


class ProbeLineSettingsError(ProbeConfigError):
    """``baudrate`` / ``probe_bytesize`` / ``probe_parity`` / stop bits not offered by the dialect."""


class ProbeDialectMismatch(ProbeError):
    """The unit answered in another dialect than the configured one (e.g. ``ER,ID,00``)."""


class ProbeLineGarbled(ProbeFrameError):
    """Bytes arrived that no ASCII dialect sends (top bit set, control characters): the line
    settings of station and unit differ (baud rate, data bits, parity) or the line is noisy."""


class ProbeUnsettled(ProbeError):
    """Consecutive buffered readings did not agree within the tolerance (no fresh, settled data)."""

    def __init__(self, channel: int, diff_mm: float, tolerance_mm: float, attempts: int) -> None:
        self.channel = channel
        self.diff_mm = diff_mm
        self.tolerance_mm = tolerance_mm
        super().__init__(
            f"channel {channel:02d}: {attempts} pairs of consecutive readings differed by up to "
            f"{diff_mm * 1000:.2f} µm (tolerance {tolerance_mm * 1000:.2f} µm): the amplifier's data is "
            "still changing (robot not settled, or a long response-time filter); let it settle longer"
        )


# --------------------------------------------------------------------------------------------
# The declarative table
# --------------------------------------------------------------------------------------------


class ChannelStatus(enum.Enum):
    OK = "ok"
    OVER_RANGE = "over_range"
    UNDER_RANGE = "under_range"
    INVALID = "invalid"


#: Marker strings on the wire. Eight characters each; a number is nine, so no marker can be
#: confused with a value even when the parser is lenient about width.
MARKERS: dict[ChannelStatus, bytes] = {
    ChannelStatus.OVER_RANGE: b"+FFFFFFF",
    ChannelStatus.UNDER_RANGE: b"-FFFFFFF",
    ChannelStatus.INVALID: b"XXXXXXXX",
}
_MARKER_STATUS = {v: k for k, v in MARKERS.items()}

MAX_CHANNELS = 15
#: Largest representable reading; anything beyond is sent as an over/under-range marker.
VALUE_LIMIT_MM = 999.9999
#: The unit discards a request line longer than this (answers ER,??,01).
MAX_REQUEST_BYTES = 64
REPLY_TERMINATOR = b"\r\n"
#: The request a driver sends to resynchronise the line after a timeout (docs/protocols.md,
#: "Sequence rule"): read-only, its reply is static and cannot be taken for a reading.
RESYNC_COMMAND = "ID"


class Field(enum.Enum):
    """Kinds of comma-separated fields and their wire form."""

    CHANNEL = "two decimal digits 00..14"
    VALUE = "+DDD.DDDD / -DDD.DDDD or a marker"
    TEXT = "1..16 characters of A-Z a-z 0-9 . _ -"
    COUNT = "two decimal digits 01..15"


@dataclass(frozen=True)
class CommandSpec:
    name: str
    params: tuple[Field, ...]
    reply: tuple[Field, ...]
    #: the last reply field repeats once per channel (M0)
    reply_repeats: bool
    #: True if the command only reads; only such commands may be retried by a driver
    read_only: bool
    summary: str


COMMANDS: dict[str, CommandSpec] = {
    spec.name: spec
    for spec in (
        CommandSpec("M0", (), (Field.VALUE,), True, True,
                    "all channels, one consistent snapshot latched on receipt of the request"),
        CommandSpec("MS", (Field.CHANNEL,), (Field.CHANNEL, Field.VALUE), False, True,
                    "one channel"),
        CommandSpec("ID", (), (Field.TEXT, Field.TEXT, Field.COUNT), False, True,
                    "identification: model, firmware, number of channels"),
        CommandSpec("ZS", (Field.CHANNEL,), (Field.CHANNEL,), False, False,
                    "zero set: the channel's present reading becomes +000.0000"),
        CommandSpec("PS", (Field.CHANNEL, Field.VALUE), (Field.CHANNEL, Field.VALUE), False, False,
                    "preset set: the channel's present reading becomes the given value"),
        CommandSpec("ZC", (Field.CHANNEL,), (Field.CHANNEL,), False, False,
                    "zero/preset clear: the channel reads its raw value again"),
    )
}


@dataclass(frozen=True)
class ErrorCode:
    code: int
    meaning: str
    advice: str
    retryable: bool
    #: what the driver does; None: RETRY if ``retryable`` else DEVICE_FAULT
    action: ErrorAction | None = None

    @property
    def effective_action(self) -> ErrorAction:
        if self.action is not None:
            return self.action
        return ErrorAction.RETRY if self.retryable else ErrorAction.DEVICE_FAULT


ERR_UNKNOWN_COMMAND = 0
ERR_BAD_PARAMETER = 1
ERR_OUT_OF_RANGE = 2
ERR_NO_CHANNEL = 3
ERR_NOT_MEASURING = 4
ERR_BUSY = 5

ERROR_CODES: dict[int, ErrorCode] = {
    e.code: e
    for e in (
        ErrorCode(ERR_UNKNOWN_COMMAND, "command not recognised",
                  f"the unit accepts {', '.join(COMMANDS)}; check the driver and unit model",
                  False),
        ErrorCode(ERR_BAD_PARAMETER, "wrong number or format of parameters",
                  "check the request frame against docs/protocols.md (probe-head commands)", False),
        ErrorCode(ERR_OUT_OF_RANGE, "parameter out of range",
                  "preset values must be numbers within +-999.9999 mm", False),
        ErrorCode(ERR_NO_CHANNEL, "channel not present",
                  "compare the channel number with the count ID reports and check the sensor "
                  "cabling", False),
        ErrorCode(ERR_NOT_MEASURING, "channel not measuring",
                  "zero/preset needs a valid reading: bring the probe into its range first",
                  False),
        ErrorCode(ERR_BUSY, "unit busy", "repeat the request after a short pause", True),
    )
}


@dataclass(frozen=True)
class Request:
    """A parsed request: command name and decoded parameters (int channel, float value)."""

    name: str
    args: tuple


@dataclass(frozen=True)
class DeviceInfo:
    model: str
    firmware: str
    channels: int


# --------------------------------------------------------------------------------------------
# Field codecs
# --------------------------------------------------------------------------------------------

# bytes patterns: a str pattern's \d would also accept non-ASCII digits.
_VALUE_RE = re.compile(rb"[+-][0-9]{3}\.[0-9]{4}")
_CHANNEL_RE = re.compile(rb"[0-9]{2}")
_TEXT_RE = re.compile(rb"[A-Za-z0-9._-]{1,16}")
_NAME_RE = re.compile(rb"[A-Z0-9]{2}")


def format_fixed_value(value_mm: float, limit_mm: float, specials: dict[ChannelStatus, bytes]) -> bytes:
    """Reading [mm] -> ``±DDD.DDDD`` (the field of the DL-RS1A family); NaN, ±inf and magnitudes
    beyond ``limit_mm`` give the dialect's ``specials`` for INVALID, OVER_RANGE, UNDER_RANGE."""
    v = float(value_mm)
    if math.isnan(v):
        return specials[ChannelStatus.INVALID]
    rounded = round(v, 4)
    if rounded > limit_mm:
        return specials[ChannelStatus.OVER_RANGE]
    if rounded < -limit_mm:
        return specials[ChannelStatus.UNDER_RANGE]
    if rounded == 0.0:
        rounded = 0.0  # never send "-000.0000"
    return f"{rounded:+09.4f}".encode("ascii")


def format_value(value_mm: float) -> bytes:
    """Reading [mm] -> wire field. +inf/-inf/NaN and magnitudes beyond ±999.9999 give markers."""
    return format_fixed_value(value_mm, VALUE_LIMIT_MM, MARKERS)


def parse_value(field: bytes) -> tuple[float, ChannelStatus]:
    """Wire field -> ``(value_mm, status)``; value is NaN unless status is OK."""
    field = _as_bytes(field)
    status = _MARKER_STATUS.get(field)
    if status is not None:
        return math.nan, status
    if _VALUE_RE.fullmatch(field) is None:
        raise ProbeFrameError(
            f"reading field {field[:20]!r} is neither a +DDD.DDDD value nor a marker: the line "
            "is garbled; check the cable, baud rate and that only one program uses the port"
        )
    return float(field), ChannelStatus.OK


def _format_field(kind: Field, value) -> bytes:
    if kind is Field.CHANNEL:
        ch = int(value)
        if not 0 <= ch < MAX_CHANNELS:
            raise ValueError(f"channel {ch} outside 0..{MAX_CHANNELS - 1}")
        return b"%02d" % ch
    if kind is Field.COUNT:
        n = int(value)
        if not 1 <= n <= MAX_CHANNELS:
            raise ValueError(f"channel count {n} outside 1..{MAX_CHANNELS}")
        return b"%02d" % n
    if kind is Field.VALUE:
        return format_value(value)
    text = str(value).encode("ascii", errors="strict")
    if _TEXT_RE.fullmatch(text) is None:
        raise ValueError(f"text field {value!r} must be 1..16 characters of A-Z a-z 0-9 . _ -")
    return text


def _parse_field(kind: Field, field: bytes, what: str):
    """Decode one reply field; raise ProbeFrameError on anything malformed."""
    if kind is Field.VALUE:
        return parse_value(field)
    if kind is Field.TEXT:
        if _TEXT_RE.fullmatch(field) is None:
            raise ProbeFrameError(f"{what}: text field {field[:20]!r} is malformed")
        return field.decode("ascii")
    if _CHANNEL_RE.fullmatch(field) is None:
        raise ProbeFrameError(f"{what}: expected two digits, got {field[:20]!r}")
    n = int(field)
    if kind is Field.CHANNEL and not n < MAX_CHANNELS:
        raise ProbeFrameError(f"{what}: channel {n} outside 00..{MAX_CHANNELS - 1}")
    if kind is Field.COUNT and not 1 <= n <= MAX_CHANNELS:
        raise ProbeFrameError(f"{what}: channel count {n} outside 01..{MAX_CHANNELS}")
    return n


def _as_bytes(data) -> bytes:
    if isinstance(data, (bytes, bytearray, memoryview)):
        return bytes(data)
    raise ProbeFrameError(f"expected bytes from the port, got {type(data).__name__}")


# --------------------------------------------------------------------------------------------
# Requests (the unit's side parses, the driver's side formats)
# --------------------------------------------------------------------------------------------


def format_request(name: str, *args) -> bytes:
    """Build a request frame, terminated by CR. ``ValueError`` for arguments the table forbids
    (a programming error in the caller, not a wire condition)."""
    spec = COMMANDS.get(name)
    if spec is None:
        raise ValueError(f"unknown probe command {name!r}; known: {', '.join(COMMANDS)}")
    if len(args) != len(spec.params):
        raise ValueError(f"{name} takes {len(spec.params)} parameter(s), got {len(args)}")
    fields = [name.encode("ascii")]
    for kind, value in zip(spec.params, args):
        if kind is Field.VALUE and not math.isfinite(float(value)):
            raise ValueError(f"{name}: parameter must be a finite number, got {value!r}")
        fields.append(_format_field(kind, value))
    return b",".join(fields) + b"\r"


def parse_request(line: bytes) -> Request:
    """Decode one request line (terminator already removed or still present).

    Raises :class:`ProbeDeviceError` carrying the code the unit must answer with; the
    simulator turns it into ``ER,<command>,<code>`` via :func:`format_error`.
    """
    line = _as_bytes(line)
    body = line[:-2] if line.endswith(b"\r\n") else line[:-1] if line.endswith(b"\r") else line
    parts = body.split(b",")
    raw_name = parts[0]
    echo = raw_name.decode("ascii") if _NAME_RE.fullmatch(raw_name) else "??"
    if len(body) > MAX_REQUEST_BYTES:  # an overrun input buffer: refuse it whatever it is
        raise ProbeDeviceError(echo, ERR_BAD_PARAMETER)
    spec = COMMANDS.get(echo)
    if spec is None:
        raise ProbeDeviceError(echo, ERR_UNKNOWN_COMMAND)
    params = parts[1:]
    if len(params) != len(spec.params):
        raise ProbeDeviceError(echo, ERR_BAD_PARAMETER)
    args: list[int | float] = []
    for kind, field in zip(spec.params, params):
        if kind is Field.CHANNEL:
            if _CHANNEL_RE.fullmatch(field) is None:
                raise ProbeDeviceError(echo, ERR_BAD_PARAMETER)
            args.append(int(field))  # presence of the channel is the unit's business
        elif kind is Field.VALUE:
            if field in _MARKER_STATUS:
                raise ProbeDeviceError(echo, ERR_OUT_OF_RANGE)
            if _VALUE_RE.fullmatch(field) is None:
                raise ProbeDeviceError(echo, ERR_BAD_PARAMETER)
            args.append(float(field))
        else:  # no request takes text or counts today; the table would have to say so
            raise ProbeDeviceError(echo, ERR_BAD_PARAMETER)
    return Request(echo, tuple(args))


# --------------------------------------------------------------------------------------------
# Replies (the unit's side formats, the driver's side parses)
# --------------------------------------------------------------------------------------------


def format_reply(name: str, *fields) -> bytes:
    """Build a reply frame (CR LF terminated) from decoded field values."""
    spec = COMMANDS[name]
    kinds = _reply_kinds(spec, len(fields))
    if kinds is None:
        raise ValueError(f"{name} reply has {len(spec.reply)} field(s), got {len(fields)}")
    out = [name.encode("ascii")] + [_format_field(k, v) for k, v in zip(kinds, fields)]
    return b",".join(out) + REPLY_TERMINATOR


def format_error(command: str, code: int) -> bytes:
    """``ER,<command>,<code>`` CR LF; ``command`` is the echoed name or ``??``."""
    return b"ER,%s,%02d\r\n" % (command.encode("ascii"), code)


def _reply_kinds(spec: CommandSpec, n: int) -> tuple[Field, ...] | None:
    if spec.reply_repeats:
        fixed = len(spec.reply) - 1
        if n < fixed + 1 or n > fixed + MAX_CHANNELS:
            return None
        return spec.reply[:-1] + (spec.reply[-1],) * (n - fixed)
    return spec.reply if n == len(spec.reply) else None


def reply_names(line: bytes, name: str) -> bool:
    """True if the complete line ``line`` presents itself as the answer to command ``name``:
    it echoes ``name`` (``NAME,...`` or ``NAME`` CR LF), or is an error reply for ``name`` or for
    an unreadable request (``ER,<name>,..``, ``ER,??,..``). Anything else on the line while a
    driver waits for ``name``'s reply is a stale or unsolicited frame, to be discarded. Pure;
    never raises for bytes input."""
    if not isinstance(line, (bytes, bytearray, memoryview)):
        return False
    body = bytes(line)
    if body.endswith(REPLY_TERMINATOR):
        body = body[:-2]
    parts = body.split(b",", 2)
    echo = name.encode("ascii")
    if parts[0] == echo:
        return True
    return parts[0] == b"ER" and len(parts) > 1 and parts[1] in (echo, b"??")


def parse_reply(line: bytes, name: str) -> tuple:
    """Check and decode a reply to command ``name``; returns the decoded fields.

    ``ER`` replies raise :class:`ProbeDeviceError`; anything malformed, truncated or answering
    another command raises :class:`ProbeFrameError`.
    """
    line = _as_bytes(line)
    spec = COMMANDS.get(name)
    if spec is None:
        raise ValueError(f"unknown probe command {name!r}")
    if not line.endswith(REPLY_TERMINATOR):
        raise ProbeFrameError(
            f"reply to {name} {line[:40]!r} is not terminated by CR LF (truncated): check the "
            "cable and that the baud rate matches the unit"
        )
    body = line[:-2]
    if b"\r" in body or b"\n" in body:
        raise ProbeFrameError(
            f"reply to {name} contains a stray line break ({line[:40]!r}): two frames ran "
            "together; the port carried stale or foreign data"
        )
    parts = body.split(b",")
    if parts[0] == b"ER":
        if len(parts) != 3 or _CHANNEL_RE.fullmatch(parts[2]) is None:
            raise ProbeFrameError(f"malformed error reply {line[:40]!r}")
        if parts[1] != name.encode("ascii"):
            raise ProbeFrameError(
                f"error reply {line[:40]!r} does not answer {name}: stale data on the port"
            )
        raise ProbeDeviceError(name, int(parts[2]))
    if parts[0] != name.encode("ascii"):
        raise ProbeFrameError(
            f"reply {line[:40]!r} does not answer {name}: garbled or stale data on the port; "
            "check the cable and baud rate"
        )
    kinds = _reply_kinds(spec, len(parts) - 1)
    if kinds is None:
        raise ProbeFrameError(
            f"reply to {name} has {len(parts) - 1} field(s), which the protocol does not allow "
            f"({line[:60]!r}): garbled frame"
        )
    return tuple(_parse_field(k, f, f"reply to {name}") for k, f in zip(kinds, parts[1:]))


def parse_m0(line: bytes, channels: int | None = None) -> tuple[np.ndarray, tuple[ChannelStatus, ...]]:
    """``M0`` reply -> ``(values_mm (n,), statuses)``; NaN where not OK.

    ``channels``: the count the unit reported with ``ID``; a different count is a frame error.
    """
    fields = parse_reply(line, "M0")
    if channels is not None and len(fields) != channels:
        raise ProbeFrameError(
            f"M0 reply carries {len(fields)} channel(s), the unit reported {channels}: garbled "
            "frame or the unit was reconfigured; re-identify it"
        )
    values = np.array([v for v, _ in fields], dtype=float)
    return values, tuple(s for _, s in fields)


def parse_ms(line: bytes, channel: int) -> tuple[float, ChannelStatus]:
    """``MS,nn`` reply -> ``(value_mm, status)``; checks the echoed channel."""
    ch, (value, status) = parse_reply(line, "MS")
    if ch != channel:
        raise ProbeFrameError(f"MS reply for channel {ch:02d}, requested {channel:02d}: stale data")
    return value, status


def parse_id(line: bytes) -> DeviceInfo:
    model, firmware, count = parse_reply(line, "ID")
    return DeviceInfo(model, firmware, count)


def parse_ack(line: bytes, name: str, channel: int) -> tuple:
    """Acknowledgement of ZS / ZC / PS; checks the echoed channel, returns the fields."""
    fields = parse_reply(line, name)
    if fields[0] != channel:
        raise ProbeFrameError(
            f"{name} acknowledged channel {fields[0]:02d}, requested {channel:02d}: stale data"
        )
    return fields
