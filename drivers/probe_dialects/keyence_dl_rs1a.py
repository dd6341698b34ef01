"""``keyence-dl-rs1a``: Keyence DL-RS1A RS-232C communication unit with GT2 amplifiers.

Source: KEYENCE "RS-232C Communication Unit DL-RS1A User's Manual (GT2 Edition)" (96078E),
cited below by the manual's printed page numbers; [M] the manual says it, [?] not confirmed
from a readable copy (see ``docs/protocols.md``, "keyence-dl-rs1a").

* Line (p. 7 "Communication Specifications"): 2400/4800/9600/19200/38400 bit/s, 7 or 8 data
  bits, parity none/even/odd, 1 stop bit; factory default 9600 8N1 [M]. The manual forbids no
  combination of data bits and parity, so 7N1 is accepted [M: none listed].
* Delimiters (p. 7): the unit detects CR or CR LF on receipt and always sends CR LF [M]; this
  driver sends CR LF, as the manual's examples do (p. 8 ``SR,06,101`` CR LF).
* Commands (pp. 9-10 "Commands and Responses"), one two-letter name, comma-separated fields:
  ``M0`` -> ``M0,<data ID00>,...,<data last ID>``; ``MS`` -> ``MS,<out>,<data ID00>,...``;
  ``SR,<id>,<no>`` -> ``SR,<id>,<no>,<data>``; ``SW,<id>,<no>,<data>`` -> ``SW,<id>,<no>``;
  ``AW,<no>,<data>`` -> ``AW,<no>`` [M]. There is no identification command [M: none listed].
* Errors (p. 14 "Error numbers"): ``ER,<command>,<nn>`` CR LF [M] (p. 8 "Error response").
* Values (p. 11-13 data tables): ``±***.****``, 9 bytes, mm; the GT2 setting ranges are
  -199.9999 .. +199.9999 [M]. The strings of the special values the note *5 of p. 12 lists
  (over range, under range, error) were not readable [?]: a number beyond ±199.9999, a field
  of ``E`` digits and a field of dashes are all decoded as "not a measurement", and the
  driver guards every reading with the probe's stroke anyway.
* Freshness (p. 16 "Communication response time"): ``M0``/``MS`` return data the unit polls
  from the amplifiers periodically, behind each amplifier's response-time filter (data no. 103,
  3 ms .. 1 s, default 100 ms on GT2-H heads) [M]: hence ``fresh_pair``.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from drivers.probe_dialects.base import Dialect, Exchange, LineRule, LineSettings, status_of_number
from drivers.probe_protocol import (
    ChannelStatus,
    ErrorAction,
    ErrorCode,
    ProbeDeviceError,
    ProbeFrameError,
    format_fixed_value,
)

__all__ = ["DIALECT", "COMMANDS", "ERRORS", "LINE", "DATA_NUMBERS", "VALUE_LIMIT_MM", "SPECIAL_VALUES",
           "MAX_AMPLIFIERS", "format_value", "parse_value", "parse_request", "format_error", "NAME"]

NAME = "keyence-dl-rs1a"
_SRC = "DL-RS1A User's Manual (GT2 Edition)"

#: p. 7 "Communication Specifications" [M]
LINE = LineRule(
    baudrates=(2400, 4800, 9600, 19200, 38400), bytesizes=(7, 8), parities=("none", "even", "odd"),
    stopbits=(1,), default=LineSettings(9600, 8, "none", 1),
    source=f"{_SRC}, p. 7 'Communication Specifications'",
)

#: p. 7 "Sensor Amplifier ID Number Assignments": main unit 00, expansion units 01 .. 14 [M]
MAX_AMPLIFIERS = 15
#: GT2 value range, p. 13 (data nos. 105, 117, 118: -199.9999 .. +199.9999) [M]
VALUE_LIMIT_MM = 199.9999


@dataclass(frozen=True)
class Command:
    name: str
    params: tuple[str, ...]   # field kinds: "id" (2 digits), "no" (3 digits), "data"
    reply: tuple[str, ...]    # "value", "out", or param kinds echoed
    per_amplifier: bool       # the reply repeats ``reply`` once per connected amplifier
    read_only: bool
    summary: str


#: pp. 9-10 "Commands and Responses" [M]
COMMANDS: dict[str, Command] = {c.name: c for c in (
    Command("M0", (), ("value",), True, True, "present value of every connected amplifier, ID 00 first"),
    Command("MS", (), ("out", "value"), True, True, "control-output state and value of every amplifier"),
    Command("SR", ("id", "no"), ("id", "no", "data"), False, True, "read data item <no> of amplifier <id>"),
    Command("SW", ("id", "no", "data"), ("id", "no"), False, False, "write data item <no> of amplifier <id>"),
    Command("AW", ("no", "data"), ("no",), False, False, "write data item <no> of every amplifier"),
)}

_WAIT = ErrorAction.RETRY_AFTER_WAIT
#: p. 14 "Error numbers" [M]; 02 is in the GT2 edition's table ("communication timeout error")
ERRORS: dict[int, ErrorCode] = {e.code: e for e in (
    ErrorCode(0, "invalid command", "the unit knows only M0, MS, SR, SW and AW (there is no ID command); "
              "if the station sent another dialect's command, set [devices] probe_protocol", False,
              ErrorAction.DRIVER_ERROR),
    ErrorCode(2, "communication timeout between the DL-RS1A and an amplifier",
              "an amplifier is in its initial reset or applying its ID setting; sent again after a wait", True, _WAIT),
    ErrorCode(20, "data length error", "the unit saw no CR / CR LF delimiter: check that the line settings "
              "match the unit's communication switches", False, ErrorAction.CONFIG_ERROR),
    ErrorCode(21, "number of parameters error", "the request had the wrong number of comma-separated "
              "fields (a driver fault)", False, ErrorAction.DRIVER_ERROR),
    ErrorCode(22, "parameter error (also while amplifiers start up or reset)",
              "out-of-range or unreadable item, or the amplifiers were starting up: sent again after a wait", True, _WAIT),
    ErrorCode(29, "RS-232C communication error", "set [devices] baudrate, probe_bytesize and probe_parity to "
              "the unit's communication setup switches (factory default 9600 8N1)", False, ErrorAction.CONFIG_ERROR),
    ErrorCode(65, "ID number error", "no amplifier has that ID: compare the head file's channels with the "
              "amplifiers connected (main unit 00, expansion units 01 .. 14)", False, ErrorAction.CONFIG_ERROR),
    ErrorCode(66, "expansion line error", "the chain of expansion amplifiers is broken or an amplifier dropped "
              "out: check the amplifiers' connections and power", False, ErrorAction.DEVICE_FAULT),
    ErrorCode(67, "write control: the unit is not writable", "set the DL-RS1A's read/write switch to R/W "
              "(the station itself never writes)", False, ErrorAction.CONFIG_ERROR),
)}

#: GT2 data numbers the simulator serves through SR/SW (p. 13, read/write table) [M]:
#: number -> (name, initial value as sent)
DATA_NUMBERS: dict[int, tuple[str, bytes]] = {
    103: ("response time (0 HSP 3 ms, 1 5 ms, 2 10 ms, 3 100 ms, 4 500 ms, 5 1000 ms)", b"3"),
    110: ("measurement direction (0 normal, 1 reversed)", b"0"),
    113: ("display resolution (0 0.0001, 1 0.001, 2 0.01, 3 0.1)", b"0"),
    120: ("select preset data (0 R.V., 1 P.V.)", b"0"),
    121: ("preset memory (0 YES: a preset survives power off, 1 NO)", b"0"),
}

#: What the simulator sends for a channel without a valid reading [?]: the GT2 strings could
#: not be confirmed; these are the sister editions' forms, all decoded as no measurement.
SPECIAL_VALUES: dict[ChannelStatus, bytes] = {
    ChannelStatus.OVER_RANGE: b"+999.9999",
    ChannelStatus.UNDER_RANGE: b"-999.9999",
    ChannelStatus.INVALID: b"+EEE.EEEE",
}

_VALUE_RE = re.compile(rb"[+-][0-9]{3}\.[0-9]{4}")
_ERROR_RE = re.compile(rb"[+-]?E+\.?E*")        # [?] "amplifier error" form of sister editions
_DASH_RE = re.compile(rb"[+-]?-+\.?-*")          # [?] "-----" display form of sister editions
_OUT_RE = re.compile(rb"[0-9]{1,2}")             # [?] GT2 control-output digits (GT-70A: one digit)
_ID_RE = re.compile(rb"[0-9]{2}")
_NO_RE = re.compile(rb"[0-9]{3}")
_DATA_RE = re.compile(rb"[+-]?[0-9.]{1,10}")
_NAME_RE = re.compile(rb"[A-Z0-9]{2}")


def format_value(value_mm: float) -> bytes:
    """Reading [mm] -> ``±DDD.DDDD``; NaN / beyond ±199.9999 -> the simulator's special values."""
    return format_fixed_value(value_mm, VALUE_LIMIT_MM, SPECIAL_VALUES)


def parse_value(field: bytes) -> tuple[float, ChannelStatus]:
    if _VALUE_RE.fullmatch(field):
        v = float(field)
        status = status_of_number(v, VALUE_LIMIT_MM)
        return (v, status) if status is ChannelStatus.OK else (math.nan, status)
    if _ERROR_RE.fullmatch(field) or _DASH_RE.fullmatch(field):
        return math.nan, ChannelStatus.INVALID
    raise ProbeFrameError(
        f"DL-RS1A value field {field[:20]!r} is neither ±DDD.DDDD nor a special value: the line is garbled; "
        "check the cable and that [devices] baudrate / probe_bytesize / probe_parity match the unit")


def format_error(command: str, code: int) -> bytes:
    """``ER,<command>,<nn>`` CR LF (p. 8 "Error response")."""
    return b"ER,%s,%02d\r\n" % (command.encode("ascii"), code)


def _error(name: str, code: int) -> ProbeDeviceError:
    return ProbeDeviceError(name, code, errors=ERRORS, dialect=NAME)


def parse_request(line: bytes) -> tuple[str, tuple[bytes, ...]]:
    """The unit's side: request line (terminator stripped or not) -> ``(name, raw params)``;
    raises :class:`ProbeDeviceError` with the code the unit answers."""
    body = bytes(line).rstrip(b"\r\n")
    parts = body.split(b",")
    # the command is the first two characters (p. 8); what the unit echoes for a longer or
    # unreadable one is not documented [?]: the first two when readable, else "??"
    name = parts[0][:2].decode("ascii") if _NAME_RE.fullmatch(parts[0][:2]) else "??"
    spec = COMMANDS.get(name)
    if spec is None or len(parts[0]) != 2:
        raise _error(name, 0)
    params = tuple(parts[1:])
    if len(params) != len(spec.params):
        raise _error(name, 21)
    for kind, field in zip(spec.params, params):
        if kind == "id" and not _ID_RE.fullmatch(field):
            raise _error(name, 22)
        if kind == "no" and not _NO_RE.fullmatch(field):
            raise _error(name, 22)
        if kind == "data" and not _DATA_RE.fullmatch(field):
            raise _error(name, 22)
    return name, params


def _split_reply(line: bytes, name: str) -> list[bytes]:
    """Check the terminator, raise the unit's error reply, and return the fields after the echo."""
    if not line.endswith(b"\r\n"):
        raise ProbeFrameError(f"DL-RS1A reply to {name} {line[:40]!r} is not terminated by CR LF (truncated)")
    body = line[:-2]
    if b"\r" in body or b"\n" in body:
        raise ProbeFrameError(f"DL-RS1A reply to {name} has a stray line break ({line[:40]!r})")
    parts = body.split(b",")
    if parts[0] == b"ER":
        if len(parts) != 3 or not _ID_RE.fullmatch(parts[2]) or parts[1] != name.encode("ascii"):
            raise ProbeFrameError(f"malformed DL-RS1A error reply {line[:40]!r} to {name}")
        raise _error(name, int(parts[2]))
    if parts[0] != name.encode("ascii"):
        raise ProbeFrameError(f"reply {line[:40]!r} does not answer {name}: garbled or stale data")
    return parts[1:]


def parse_m0(line: bytes) -> list[tuple[float, ChannelStatus]]:
    """``M0,<v00>,...`` -> one ``(value_mm, status)`` per amplifier; the count is the field count."""
    fields = _split_reply(line, "M0")
    if not 1 <= len(fields) <= MAX_AMPLIFIERS:
        raise ProbeFrameError(f"M0 reply carries {len(fields)} values; a DL-RS1A serves 1 .. {MAX_AMPLIFIERS}")
    return [parse_value(f) for f in fields]


def parse_ms(line: bytes) -> list[tuple[int, float, ChannelStatus]]:
    """``MS,<out>,<v00>,<out>,<v01>,...`` -> ``(output state, value_mm, status)`` per amplifier."""
    fields = _split_reply(line, "MS")
    if not fields or len(fields) % 2 or len(fields) // 2 > MAX_AMPLIFIERS:
        raise ProbeFrameError(f"MS reply with {len(fields)} fields: output/value pairs expected")
    out = []
    for o, v in zip(fields[0::2], fields[1::2]):
        if not _OUT_RE.fullmatch(o):
            raise ProbeFrameError(f"MS control-output field {o[:10]!r} is not 1-2 digits: garbled frame")
        out.append((int(o), *parse_value(v)))
    return out


def parse_sr(line: bytes, amp: int, number: int) -> bytes:
    """``SR,<id>,<no>,<data>`` -> the data field (checks the echoed id and data number)."""
    fields = _split_reply(line, "SR")
    if len(fields) != 3 or fields[0] != b"%02d" % amp or fields[1] != b"%03d" % number:
        raise ProbeFrameError(f"SR reply {line[:40]!r} does not answer SR,{amp:02d},{number:03d}")
    return fields[2]


def reply_names(line: bytes, name: str) -> bool:
    body = bytes(line).rstrip(b"\r\n")
    echo = name.encode("ascii")
    return body == echo or body.startswith(echo + b",") or body.startswith(b"ER," + echo + b",")


def _claims(line: bytes, sent: str) -> bool:
    """A DL-RS1A answers a command it lacks with ``ER,<cmd>,00`` (e.g. ``ER,ID,00``)."""
    body = bytes(line).rstrip(b"\r\n")
    name = sent[:2]
    return name not in COMMANDS and body == b"ER," + name.encode("ascii", "replace") + b",00"


def request(name: str, *params: bytes) -> bytes:
    return b",".join((name.encode("ascii"),) + params) + b"\r\n"


DIALECT = Dialect(
    name=NAME,
    title="Keyence DL-RS1A with GT2 amplifiers",
    model="DL-RS1A",
    source=_SRC,
    line=LINE,
    commands=COMMANDS,
    errors=ERRORS,
    snapshot=lambda channels: [Exchange(request("M0"), "M0", parse_m0)],
    identify=None,
    resync=Exchange(request("M0"), "M0", parse_m0),
    reply_names=reply_names,
    claims=_claims,
    request_end=b"\r\n",
    retry_wait_s=0.3,
    fresh_pair=True,
    # p. 16: the unit refreshes its buffer every ~7 ms (one amplifier) to ~50 ms (ten)
    refresh_s=0.05,
    unknown_command_code=0,
    value_limit_mm=VALUE_LIMIT_MM,
    notes=("The station uses no preset or zero: it reads absolute values against the head file's nominal, "
           "so it needs no preset memory behaviour; a preset set at an amplifier (kept through power-off when "
           "preset memory, data no. 121, is 0 YES, the initial value) would shift every reading: clear it.",),
)
