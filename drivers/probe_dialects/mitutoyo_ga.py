"""``mitutoyo-ga``: Mitutoyo Digimatic indicators ID-H0530/0560 on their RS-232C interface.

Source: Mitutoyo "ID-H0530/0560 Digimatic Indicator User's Manual" (No. 99MAH016B), section
4.2.4 "Communication command (I/O format)" [M]; [?] marks what a readable copy did not confirm
(see ``docs/protocols.md``, "mitutoyo-ga").

* One indicator per ID No. ``00`` .. ``99`` (section 3.2 sets it) [M]; the station reads
  channel ``k`` (0-based) from the indicator with ID ``k + 1``: one request per channel, so a
  snapshot is sequential, not latched at one instant.
* ``GA**`` CR LF -> ``GN**,+0016.2345`` CR LF: data output of the indicator ``**``; the reply's
  second letter is the measurement mode: ``N`` normal, ``X`` max, ``M`` min, ``W`` TIR [M].
  The station needs normal mode (a max/min/TIR value is not a position).
* Mode switching ``CN**`` / ``CX**`` / ``CM**`` / ``CW**`` -> ``CH**``; zero-setting ``CR**``
  -> ``CH**``; preset value ``CP**,+0016.2345`` -> ``CH**`` [M]. The station uses none of them.
* Values: sign, 4 digits, ``.``, 4 digits, mm [M: the manual's examples]. How an over-range
  spindle is reported on the line, and any error reply, were not found [?]: an indicator that
  does not answer is a timeout, and every reading is guarded by the probe's stroke.
* Line settings: not confirmed from a readable copy [?]; the table below (9600 8N1 default) is
  the usual Mitutoyo RS-232C set. Check the indicator's own parameter menu.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from drivers.probe_dialects.base import Dialect, Exchange, LineRule, LineSettings, status_of_number
from drivers.probe_protocol import ChannelStatus, ErrorCode, ProbeDeviceError, ProbeFrameError

__all__ = ["DIALECT", "COMMANDS", "MODES", "LINE", "NAME", "VALUE_LIMIT_MM", "channel_id", "format_value",
           "parse_value", "parse_ga", "request"]

NAME = "mitutoyo-ga"
_SRC = "Mitutoyo ID-H0530/0560 User's Manual No. 99MAH016B"

#: [?] not confirmed: see the module docstring
LINE = LineRule(
    baudrates=(2400, 4800, 9600, 19200), bytesizes=(7, 8), parities=("none", "even", "odd"),
    stopbits=(1, 2), default=LineSettings(9600, 8, "none", 1),
    source=f"{_SRC}, section 4.2 [not confirmed: check the indicator's RS-232C parameters]",
)

#: Largest magnitude the ``±DDDD.DDDD`` form carries [mm]
VALUE_LIMIT_MM = 9999.9999
#: IDs 01 .. 15 serve channels 0 .. 14 (ID 00 is left out: the manual's note on ID 00 versus
#: 01 .. 99 is cut off in the readable copy [?])
MAX_CHANNELS = 15


@dataclass(frozen=True)
class Command:
    name: str
    reply: str
    read_only: bool
    summary: str


#: section 4.2.4 "Communication command (I/O format)" [M] (``**`` = the ID No.)
COMMANDS: dict[str, Command] = {c.name: c for c in (
    Command("GA", "G<mode>**,±DDDD.DDDD", True, "data output (the reply letter names the mode)"),
    Command("CN", "CH**", False, "measurement mode: normal"),
    Command("CX", "CH**", False, "measurement mode: max"),
    Command("CM", "CH**", False, "measurement mode: min"),
    Command("CW", "CH**", False, "measurement mode: TIR (run-out)"),
    Command("CR", "CH**", False, "zero-setting (moves to the INC system)"),
    Command("CP", "CH**", False, "preset value setting, CP**,±DDDD.DDDD"),
)}

#: the reply's mode letter (section 4.2.4 "Data output") [M]
MODES: dict[bytes, str] = {b"N": "normal", b"X": "max", b"M": "min", b"W": "TIR (run-out)"}

#: No error reply is documented in section 4.2.4 [?]
ERRORS: dict[int, ErrorCode] = {}

_VALUE_RE = re.compile(rb"[+-][0-9]{4}\.[0-9]{4}")
_REPLY_RE = re.compile(rb"G([A-Z])([0-9]{2}),(.*)")


def channel_id(channel: int) -> int:
    return channel + 1


def request(name: str, ident: int, *params: bytes) -> bytes:
    return b",".join((b"%s%02d" % (name.encode("ascii"), ident),) + params) + b"\r\n"


def format_value(value_mm: float) -> bytes:
    """Reading [mm] -> ``±DDDD.DDDD`` (the simulator's side; NaN has no documented form)."""
    v = round(float(value_mm), 4)
    if not math.isfinite(v) or abs(v) > VALUE_LIMIT_MM:
        raise ValueError(f"{value_mm!r} has no Mitutoyo wire form")
    return f"{0.0 if v == 0 else v:+010.4f}".encode("ascii")


def parse_value(field: bytes) -> tuple[float, ChannelStatus]:
    if not _VALUE_RE.fullmatch(field):
        raise ProbeFrameError(
            f"Mitutoyo value field {field[:20]!r} is not ±DDDD.DDDD: the line is garbled; check the cable "
            "and that [devices] baudrate / probe_bytesize / probe_parity match the indicator")
    v = float(field)
    # the largest magnitude is what the simulator sends for "no reading" [?]: never a measurement
    status = status_of_number(v, VALUE_LIMIT_MM - 0.00005)
    return (v, status) if status is ChannelStatus.OK else (math.nan, status)


def parse_ga(line: bytes, ident: int) -> list[tuple[float, ChannelStatus]]:
    """``GN**,±DDDD.DDDD`` CR LF -> ``[(value_mm, status)]``; another mode letter is refused."""
    if not line.endswith(b"\r\n"):
        raise ProbeFrameError(f"Mitutoyo reply {line[:40]!r} is not terminated by CR LF (truncated)")
    m = _REPLY_RE.fullmatch(line[:-2])
    if m is None or int(m.group(2)) != ident:
        raise ProbeFrameError(f"reply {line[:40]!r} does not answer GA{ident:02d}: garbled or stale data")
    mode = m.group(1)
    if mode != b"N":
        raise ProbeDeviceError(
            f"GA{ident:02d}", 0, f"indicator {ident:02d} is in {MODES.get(mode, 'an unknown')} mode: switch it "
            f"to normal (CN{ident:02d}, or at the indicator); a {MODES.get(mode, '?')} value is not a position",
            errors={0: ErrorCode(0, "indicator not in normal measurement mode", "switch it to normal mode", False)},
            dialect=NAME)
    return [parse_value(m.group(3))]


def _snapshot(channels: int | None) -> list[Exchange]:
    if channels is None:
        raise ValueError("the Mitutoyo dialect reads one indicator per request: the channel count is needed")
    return [_ga(channel_id(k)) for k in range(channels)]


def _ga(ident: int) -> Exchange:
    return Exchange(request("GA", ident), f"G?{ident:02d}", lambda line: parse_ga(line, ident))


def reply_names(line: bytes, name: str) -> bool:
    """``name`` is ``G?<id>``: any data-output reply of that indicator, whatever its mode."""
    body = bytes(line).rstrip(b"\r\n")
    if name.startswith("G?"):
        return len(body) >= 5 and body[:1] == b"G" and body[2:4] == name[2:].encode("ascii") and body[4:5] == b","
    return body.startswith(name.encode("ascii"))


def _claims(line: bytes, sent: str) -> bool:
    """A Mitutoyo indicator answers only its own ``G*``/``C*`` commands [?]: it claims nothing."""
    return False


DIALECT = Dialect(
    name=NAME,
    title="Mitutoyo Digimatic indicator (ID-H RS-232C, GA/GN)",
    model="Mitutoyo ID-H",
    source=_SRC,
    line=LINE,
    commands=COMMANDS,
    errors=ERRORS,
    snapshot=_snapshot,
    identify=None,
    resync=_ga(1),
    reply_names=reply_names,
    claims=_claims,
    request_end=b"\r\n",
    needs_channel_scan=True,
    value_limit_mm=VALUE_LIMIT_MM,
    notes=("One request per indicator: a snapshot of n channels is n sequential GA requests.",),
)
