"""The simulated probe units' own wire encoding: frames built and requests read by the unit's side.

One section per dialect, each written from its document, with the page or section beside each
function ([M] the document says it, [?] not confirmed from a readable copy):

* station-ascii: ``docs/protocols.md``, "Probe-head serial protocol", "station-ascii";
* keyence-dl-rs1a: KEYENCE "RS-232C Communication Unit DL-RS1A User's Manual (GT2 Edition)"
  (96078E), printed page numbers;
* mitutoyo-ga: Mitutoyo "ID-H0530/0560 Digimatic Indicator User's Manual" (No. 99MAH016B),
  section 4.2.4 "Communication command (I/O format)".

This module deliberately does **not** import the drivers' codecs (``format_value``,
``parse_value``, ``parse_request``, ``format_reply``, ``format_error`` and the like): a
simulator that encodes with the driver's own functions shares the driver's encoding errors, and
no test of the two against each other could find them. ``tests/simulators/test_probe_wire.py``
checks the two independent implementations against each other and against the documents'
examples. What it does import are the declarative *tables* the driver, the simulator and the
tests share by design (command lists, error-code tables, markers and special values, value
limits): a table is data the document states once, not code that could encode it wrongly.

Every ``*_request`` function takes one request line (its terminator stripped or not) and returns
the decoded request, or raises :class:`Refusal` carrying the error code the unit answers with;
every other function builds one complete frame (or, ``*_value``, one field) as bytes.
"""

from __future__ import annotations

import math

from drivers.probe_dialects.keyence_dl_rs1a import COMMANDS as KEYENCE_COMMANDS
from drivers.probe_dialects.keyence_dl_rs1a import MAX_AMPLIFIERS as KEYENCE_MAX_AMPLIFIERS
from drivers.probe_dialects.keyence_dl_rs1a import SPECIAL_VALUES as KEYENCE_SPECIAL_VALUES
from drivers.probe_dialects.keyence_dl_rs1a import VALUE_LIMIT_MM as KEYENCE_VALUE_LIMIT_MM
from drivers.probe_dialects.mitutoyo_ga import COMMANDS as MITUTOYO_COMMANDS
from drivers.probe_dialects.mitutoyo_ga import MODES as MITUTOYO_MODES
from drivers.probe_dialects.mitutoyo_ga import VALUE_LIMIT_MM as MITUTOYO_VALUE_LIMIT_MM
from drivers.probe_protocol import COMMANDS as STATION_COMMANDS
from drivers.probe_protocol import (
    ERR_BAD_PARAMETER,
    ERR_OUT_OF_RANGE,
    ERR_UNKNOWN_COMMAND,
    MARKERS,
    MAX_CHANNELS,
    MAX_REQUEST_BYTES,
    ChannelStatus,
    Field,
)
from drivers.probe_protocol import VALUE_LIMIT_MM as STATION_VALUE_LIMIT_MM

__all__ = [
    "Refusal",
    "CRLF",
    "busy_echo",
    # station-ascii
    "station_value",
    "station_parse_value",
    "station_request",
    "station_m0",
    "station_ms",
    "station_id",
    "station_ack",
    "station_ps",
    "station_error",
    # keyence-dl-rs1a
    "KEYENCE_INVALID_COMMAND",
    "KEYENCE_PARAMETER_COUNT",
    "KEYENCE_PARAMETER",
    "KEYENCE_ID_NUMBER",
    "KEYENCE_WRITE_CONTROL",
    "keyence_value",
    "keyence_request",
    "keyence_m0",
    "keyence_ms",
    "keyence_sr",
    "keyence_sw",
    "keyence_aw",
    "keyence_error",
    # mitutoyo-ga
    "mitutoyo_value",
    "mitutoyo_parse_value",
    "mitutoyo_request",
    "mitutoyo_data",
    "mitutoyo_ack",
]

CRLF = b"\r\n"
_CR = b"\r"
_UPPER_OR_DIGIT = frozenset(b"ABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789")
_DIGITS = frozenset(b"0123456789")
_TEXT_CHARS = frozenset(b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789._-")
#: one unit of the last decimal place of every dialect's value field: 0.0001 mm (0.1 um)
_UNITS_PER_MM = 10_000


class Refusal(Exception):
    """The unit refuses a request: it answers ``ER,<command>,<code>`` (the ASCII dialects)."""

    def __init__(self, command: str, code: int) -> None:
        self.command = command
        self.code = code
        super().__init__(f"ER,{command},{code:02d}")


# --------------------------------------------------------------------------------------------
# Helpers common to the fixed-point value fields of all three dialects
# --------------------------------------------------------------------------------------------


def _limit_units(limit_mm: float) -> int:
    """A table's limit [mm] (e.g. 199.9999) as a count of 0.0001 mm."""
    return int(round(limit_mm * _UNITS_PER_MM))


def _fixed_field(value_mm: float, int_digits: int, limit_mm: float,
                 specials: dict[ChannelStatus, bytes] | None) -> bytes:
    """``sign``, ``int_digits`` digits, ``.``, four digits: the reading rounded to 0.0001 mm.

    NaN gives ``specials[INVALID]``; +-inf and a rounded magnitude beyond ``limit_mm`` give
    ``specials[OVER_RANGE]`` / ``specials[UNDER_RANGE]``; a rounded zero is sent with ``+``.
    ``specials`` None: such a reading has no wire form (``ValueError``)."""
    v = float(value_mm)
    status: ChannelStatus | None = None
    if math.isnan(v):
        status = ChannelStatus.INVALID
    elif math.isinf(v):
        status = ChannelStatus.OVER_RANGE if v > 0 else ChannelStatus.UNDER_RANGE
    else:
        text = f"{v:+.4f}"  # correctly rounded (half to even on the exact binary value)
        sign, magnitude = text[0], text[1:]
        whole, frac = magnitude.split(".")
        units = int(whole) * _UNITS_PER_MM + int(frac)
        if units > _limit_units(limit_mm):
            status = ChannelStatus.OVER_RANGE if sign == "+" else ChannelStatus.UNDER_RANGE
        else:
            if units == 0:
                sign = "+"  # never "-000.0000"
            return f"{sign}{int(whole):0{int_digits}d}.{frac}".encode("ascii")
    if specials is None:
        raise ValueError(f"{value_mm!r} has no wire form in this dialect")
    return specials[status]


def _parse_fixed(field: bytes, int_digits: int) -> float | None:
    """``sign``, ``int_digits`` ASCII digits, ``.``, four ASCII digits -> mm; None if not so."""
    if len(field) != 1 + int_digits + 1 + 4 or field[:1] not in (b"+", b"-"):
        return None
    whole, point, frac = field[1:1 + int_digits], field[1 + int_digits:2 + int_digits], field[2 + int_digits:]
    if point != b"." or not set(whole) <= _DIGITS or not set(frac) <= _DIGITS:
        return None
    magnitude = (int(whole) * _UNITS_PER_MM + int(frac)) / _UNITS_PER_MM  # correctly rounded
    return magnitude if field[:1] == b"+" else -magnitude  # "-000.0000" is -0.0


def _digits(field: bytes, n: int) -> bool:
    """Exactly ``n`` ASCII digits."""
    return len(field) == n and set(field) <= _DIGITS


def _is_command_name(field: bytes) -> bool:
    """Two characters of ``A-Z 0-9``: a readable command name."""
    return len(field) == 2 and set(field) <= _UPPER_OR_DIGIT


def _strip_cr_or_crlf(line: bytes) -> bytes:
    """One request terminator, CR LF or CR, removed if present."""
    if line.endswith(CRLF):
        return line[:-2]
    if line.endswith(_CR):
        return line[:-1]
    return line


def busy_echo(line: bytes) -> str:
    """The command name a busy unit echoes in its error reply: the first two characters when
    they are letters or digits, else ``??`` (station-ascii "Frames"; DL-RS1A p. 8 [?] for an
    unreadable command)."""
    head = bytes(line[:2])
    return head.decode("ascii", "replace") if head.isalnum() else "??"


# --------------------------------------------------------------------------------------------
# station-ascii (docs/protocols.md, "Probe-head serial protocol", "station-ascii")
# --------------------------------------------------------------------------------------------

_STATION_MARKER_FIELDS = frozenset(MARKERS.values())


def station_value(value_mm: float) -> bytes:
    """Reading [mm] -> value field: ``+DDD.DDDD`` / ``-DDD.DDDD``, 9 bytes, +000.0000 for zero
    ("Field formats"); NaN -> ``XXXXXXXX``, +inf / beyond +999.9999 -> ``+FFFFFFF``, -inf /
    beyond -999.9999 -> ``-FFFFFFF`` ("Markers")."""
    return _fixed_field(value_mm, 3, STATION_VALUE_LIMIT_MM, MARKERS)


def station_parse_value(field: bytes) -> float | None:
    """A ``±DDD.DDDD`` value field ("Field formats") -> mm; None for anything else."""
    return _parse_fixed(bytes(field), 3)


def _station_channel(channel: int) -> bytes:
    """Channel field: two digits ``00`` .. ``14`` ("Field formats")."""
    ch = int(channel)
    if not 0 <= ch < MAX_CHANNELS:
        raise ValueError(f"channel {ch} outside 00 .. {MAX_CHANNELS - 1:02d}")
    return f"{ch:02d}".encode("ascii")


def _station_text(text: str) -> bytes:
    """Text field: 1 .. 16 characters of ``A-Z a-z 0-9 . _ -`` ("Field formats")."""
    raw = str(text).encode("utf-8")
    if not 1 <= len(raw) <= 16 or not set(raw) <= _TEXT_CHARS:
        raise ValueError(f"text field {text!r} must be 1 .. 16 characters of A-Z a-z 0-9 . _ -")
    return raw


def station_request(line: bytes) -> tuple[str, tuple[int | float, ...]]:
    """Request line -> ``(name, args)`` (channel: int, value: float mm) ("Frames", "Commands",
    "Error codes"). Refusals: a line over 64 bytes -> 01 (echo the name, or ``??``); a name
    the table lacks -> 00; a wrong parameter count or malformed field -> 01; a marker where a
    value belongs -> 02. Whether the channel exists is the unit's business."""
    body = _strip_cr_or_crlf(bytes(line))
    fields = body.split(b",")
    name = fields[0].decode("ascii") if _is_command_name(fields[0]) else "??"
    if len(body) > MAX_REQUEST_BYTES:
        raise Refusal(name, ERR_BAD_PARAMETER)
    spec = STATION_COMMANDS.get(name)
    if spec is None:
        raise Refusal(name, ERR_UNKNOWN_COMMAND)
    params = fields[1:]
    if len(params) != len(spec.params):
        raise Refusal(name, ERR_BAD_PARAMETER)
    args: list[int | float] = []
    for kind, field in zip(spec.params, params):
        if kind is Field.CHANNEL and _digits(field, 2):
            args.append(int(field))
        elif kind is Field.VALUE and field in _STATION_MARKER_FIELDS:
            raise Refusal(name, ERR_OUT_OF_RANGE)
        elif kind is Field.VALUE and (value := station_parse_value(field)) is not None:
            args.append(value)
        else:
            raise Refusal(name, ERR_BAD_PARAMETER)
    return name, tuple(args)


def station_m0(values_mm) -> bytes:
    """``M0,<v0>,...,<vn-1>`` CR LF, one value field per channel, 1 .. 15 channels ("Commands")."""
    fields = [station_value(v) for v in values_mm]
    if not 1 <= len(fields) <= MAX_CHANNELS:
        raise ValueError(f"an M0 reply carries 1 .. {MAX_CHANNELS} channels, not {len(fields)}")
    return b"M0," + b",".join(fields) + CRLF


def station_ms(channel: int, value_mm: float) -> bytes:
    """``MS,<ch>,<v>`` CR LF ("Commands")."""
    return b"MS," + _station_channel(channel) + b"," + station_value(value_mm) + CRLF


def station_id(model: str, firmware: str, channels: int) -> bytes:
    """``ID,<model>,<firmware>,<count>`` CR LF, count two digits ``01`` .. ``15`` ("Commands")."""
    n = int(channels)
    if not 1 <= n <= MAX_CHANNELS:
        raise ValueError(f"channel count {n} outside 01 .. {MAX_CHANNELS:02d}")
    return b"ID," + _station_text(model) + b"," + _station_text(firmware) + b"," + f"{n:02d}".encode("ascii") + CRLF


def station_ack(name: str, channel: int) -> bytes:
    """``ZS,<ch>`` / ``ZC,<ch>`` CR LF: the acknowledgement echoes the channel ("Commands")."""
    if name not in ("ZS", "ZC"):
        raise ValueError(f"{name} is not acknowledged by its channel alone")
    return name.encode("ascii") + b"," + _station_channel(channel) + CRLF


def station_ps(channel: int, value_mm: float) -> bytes:
    """``PS,<ch>,<v>`` CR LF: the preset acknowledged with its value ("Commands")."""
    return b"PS," + _station_channel(channel) + b"," + station_value(value_mm) + CRLF


def station_error(command: str, code: int) -> bytes:
    """``ER,<name>,<code>`` CR LF, code two digits ("Frames", "Error codes")."""
    return b"ER," + command.encode("ascii") + b"," + f"{code:02d}".encode("ascii") + CRLF


# --------------------------------------------------------------------------------------------
# keyence-dl-rs1a (DL-RS1A User's Manual, GT2 Edition, 96078E)
# --------------------------------------------------------------------------------------------

#: p. 14 "Error numbers" [M]: the codes this simulated unit sends (the test checks that the
#: driver's table, ``keyence_dl_rs1a.ERRORS``, holds each)
KEYENCE_INVALID_COMMAND = 0
KEYENCE_PARAMETER_COUNT = 21
KEYENCE_PARAMETER = 22
KEYENCE_ID_NUMBER = 65
KEYENCE_WRITE_CONTROL = 67

_KEYENCE_DATA_CHARS = frozenset(b"0123456789.")


def keyence_value(value_mm: float) -> bytes:
    """Reading [mm] -> ``±DDD.DDDD``, 9 bytes (pp. 11-13 data tables [M]); beyond the GT2 range
    ±199.9999 (p. 13 [M]), +-inf and NaN -> the special values of the table (p. 12 note *5:
    strings not readable [?])."""
    return _fixed_field(value_mm, 3, KEYENCE_VALUE_LIMIT_MM, KEYENCE_SPECIAL_VALUES)


def _keyence_data_field(field: bytes) -> bool:
    """An ``SW`` / ``AW`` data field: optional sign, 1 .. 10 of digits and ``.`` (p. 8: "maximum
    of 10 bytes" [M]; the sign [?])."""
    digits = field[1:] if field[:1] in (b"+", b"-") else field
    return 1 <= len(digits) <= 10 and set(digits) <= _KEYENCE_DATA_CHARS


def keyence_request(line: bytes) -> tuple[str, tuple[bytes, ...]]:
    """Request line (CR or CR LF, p. 7 [M]) -> ``(name, raw params)``.

    p. 8 / pp. 9-10 [M]: a two-letter command and comma-separated fields; the refusals of p. 14:
    a command the table lacks -> 00 (the echo is the first two characters when readable, else
    ``??`` [?]); a wrong number of fields -> 21; an ID that is not two digits, a data number not
    three, a data field not numeric -> 22. Whether the amplifier exists is the unit's business."""
    body = bytes(line).rstrip(b"\r\n")
    fields = body.split(b",")
    head = fields[0]
    name = head[:2].decode("ascii") if _is_command_name(head[:2]) else "??"
    spec = KEYENCE_COMMANDS.get(name)
    if spec is None or len(head) != 2:
        raise Refusal(name, KEYENCE_INVALID_COMMAND)
    params = tuple(fields[1:])
    if len(params) != len(spec.params):
        raise Refusal(name, KEYENCE_PARAMETER_COUNT)
    for kind, field in zip(spec.params, params):
        ok = (_digits(field, 2) if kind == "id" else _digits(field, 3) if kind == "no"
              else _keyence_data_field(field))
        if not ok:
            raise Refusal(name, KEYENCE_PARAMETER)
    return name, params


def _keyence_amplifier_count(n: int) -> None:
    if not 1 <= n <= KEYENCE_MAX_AMPLIFIERS:
        raise ValueError(f"a DL-RS1A serves 1 .. {KEYENCE_MAX_AMPLIFIERS} amplifiers, not {n}")


def keyence_m0(values_mm) -> bytes:
    """``M0,<data ID00>,...,<data last ID>`` CR LF (p. 9 [M])."""
    fields = [keyence_value(v) for v in values_mm]
    _keyence_amplifier_count(len(fields))
    return b"M0," + b",".join(fields) + CRLF


def keyence_ms(values_mm, output: int = 0) -> bytes:
    """``MS,<out>,<data ID00>,<out>,<data ID01>,...`` CR LF (p. 9 [M]); ``output``: the control
    output state, one digit [?] (0: all outputs off)."""
    out = f"{int(output):d}".encode("ascii")
    pairs = [out + b"," + keyence_value(v) for v in values_mm]
    _keyence_amplifier_count(len(pairs))
    return b"MS," + b",".join(pairs) + CRLF


def keyence_sr(amplifier: int, number: int, data: bytes) -> bytes:
    """``SR,<id>,<no>,<data>`` CR LF: ID two digits, data number three (p. 8 example [M])."""
    return f"SR,{amplifier:02d},{number:03d},".encode("ascii") + bytes(data) + CRLF


def keyence_sw(amplifier: int, number: int) -> bytes:
    """``SW,<id>,<no>`` CR LF (p. 10 [M])."""
    return f"SW,{amplifier:02d},{number:03d}".encode("ascii") + CRLF


def keyence_aw(number: int) -> bytes:
    """``AW,<no>`` CR LF (p. 10 [M])."""
    return f"AW,{number:03d}".encode("ascii") + CRLF


def keyence_error(command: str, code: int) -> bytes:
    """``ER,<command>,<nn>`` CR LF, error number two digits (p. 8 "Error response" [M])."""
    return f"ER,{command},{code:02d}".encode("ascii") + CRLF


# --------------------------------------------------------------------------------------------
# mitutoyo-ga (ID-H0530/0560 User's Manual No. 99MAH016B, section 4.2.4)
# --------------------------------------------------------------------------------------------


def mitutoyo_value(value_mm: float) -> bytes:
    """Reading [mm] -> ``±DDDD.DDDD``, 10 bytes (4.2.4, ``+0016.2345`` [M]); NaN, +-inf and
    magnitudes beyond 9999.9999 have no documented form [?]: ``ValueError``."""
    return _fixed_field(value_mm, 4, MITUTOYO_VALUE_LIMIT_MM, None)


def mitutoyo_parse_value(field: bytes) -> float | None:
    """A ``±DDDD.DDDD`` field (4.2.4, ``CP**,+0016.2345`` [M]) -> mm; None for anything else."""
    return _parse_fixed(bytes(field), 4)


def mitutoyo_request(line: bytes) -> tuple[str, int, bytes] | None:
    """Request line -> ``(command, ID No., rest after the ID)``: two letters of the table, the
    two-digit ID No. ``**`` (4.2.4 and section 3.2 [M]), then ``,<value>`` for ``CP`` or
    nothing. None for a line that is no command of the table (the unit stays silent [?])."""
    body = bytes(line).rstrip(b"\r\n")
    command, ident, rest = body[:2].decode("ascii", "replace"), body[2:4], body[4:]
    if command not in MITUTOYO_COMMANDS or not _digits(ident, 2):
        return None
    return command, int(ident), rest


def mitutoyo_data(mode: bytes, ident: int, value_mm: float) -> bytes:
    """``G<mode>**,±DDDD.DDDD`` CR LF, the reply to ``GA**``; ``mode`` ``N`` / ``X`` / ``M`` /
    ``W`` (4.2.4 "Data output" [M])."""
    if mode not in MITUTOYO_MODES:
        raise ValueError(f"measurement mode {mode!r} is not one of {sorted(MITUTOYO_MODES)}")
    return b"G" + mode + f"{ident:02d},".encode("ascii") + mitutoyo_value(value_mm) + CRLF


def mitutoyo_ack(ident: int) -> bytes:
    """``CH**`` CR LF: the answer to mode switching, zero-setting and preset (4.2.4 [M])."""
    return f"CH{ident:02d}".encode("ascii") + CRLF
