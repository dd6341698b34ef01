"""The types every probe dialect is made of: line settings and rules, one exchange, the dialect
itself. The dialect modules and the registry (:mod:`drivers.probe_dialects`) import them from here,
so the registry imports its dialects and no dialect imports the registry."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

from drivers.probe_protocol import ChannelStatus, DeviceInfo, ErrorCode

PARITIES = ("none", "even", "odd")
_PARITY_LETTER = {"none": "N", "even": "E", "odd": "O"}


@dataclass(frozen=True)
class LineSettings:
    """One serial framing: baud rate, data bits, parity ("none"/"even"/"odd"), stop bits."""

    baudrate: int
    bytesize: int = 8
    parity: str = "none"
    stopbits: int = 1

    def describe(self) -> str:
        return f"{self.baudrate} {self.bytesize}{_PARITY_LETTER.get(self.parity, '?')}{self.stopbits}"

    @property
    def bits_per_byte(self) -> int:
        """Start bit + data + parity + stop bits: what one byte costs on the wire."""
        return 1 + self.bytesize + (0 if self.parity == "none" else 1) + self.stopbits


@dataclass(frozen=True)
class LineRule:
    """What a dialect's unit offers; ``forbidden``: ``((bytesize, parity), why)`` pairs."""

    baudrates: tuple[int, ...]
    bytesizes: tuple[int, ...]
    parities: tuple[str, ...]
    stopbits: tuple[int, ...]
    default: LineSettings
    source: str
    forbidden: tuple[tuple[tuple[int, str], str], ...] = ()

    def describe(self) -> str:
        return (f"{'/'.join(map(str, self.baudrates))} baud, {' or '.join(map(str, self.bytesizes))} data bits, "
                f"parity {'/'.join(self.parities)}, {' or '.join(map(str, self.stopbits))} stop bit(s); "
                f"factory default {self.default.describe()}")


@dataclass(frozen=True)
class Exchange:
    """One request and its reply: ``frame`` is written; ``name`` is what a reply must present
    itself as (:meth:`Dialect.reply_names`); ``parse`` decodes the reply line (CR LF included)
    and raises only ProbeError subclasses; only ``read_only`` requests are ever repeated."""

    frame: bytes
    name: str
    parse: Callable[[bytes], Any]
    read_only: bool = True


@dataclass(frozen=True)
class Dialect:
    """A dialect: its tables plus the pure functions that build requests and decode replies.

    ``snapshot(channels)`` -> the exchanges of one reading of every channel; each one's parse
    returns a list of ``(value_mm, ChannelStatus)``. ``identify`` -> the exchange of an
    identification command, or None where the unit has none (then the driver synthesises a
    :class:`DeviceInfo` from a snapshot with ``model`` and firmware "n/a"). ``resync``: the
    harmless read-only request that fences the line after a timeout. ``fresh_pair``: readings are
    buffered behind a filter, so one is accepted only when two consecutive snapshots, taken at
    least ``refresh_s`` apart, agree (driver rule). ``claims(line, sent)``: True if ``line``
    is how this dialect's unit answers the request named ``sent`` of another dialect.
    """

    name: str
    title: str
    model: str
    source: str
    line: LineRule
    commands: Mapping[str, Any]
    errors: Mapping[int, ErrorCode]
    snapshot: Callable[[int | None], list[Exchange]]
    identify: Callable[[], Exchange] | None
    resync: Exchange
    reply_names: Callable[[bytes, str], bool]
    claims: Callable[[bytes, str], bool]
    #: request terminator the driver sends
    request_end: bytes = b"\r"
    #: wait before repeating a request answered with a RETRY_AFTER_WAIT error [s]
    retry_wait_s: float = 0.2
    fresh_pair: bool = False
    refresh_s: float = 0.0
    #: a dialect that must be told its channel count (one request per channel) scans for it
    needs_channel_scan: bool = False
    #: the error code meaning "command not recognised", if the dialect has one
    unknown_command_code: int | None = None
    #: the largest representable magnitude of a reading [mm]
    value_limit_mm: float = 999.9999
    notes: tuple[str, ...] = field(default_factory=tuple)

    def info(self, channels: int) -> DeviceInfo:
        return DeviceInfo(self.model, "n/a", channels)


def status_of_number(value: float, limit_mm: float) -> ChannelStatus:
    """A well-formed number beyond the representable range is a range marker, not a reading."""
    if value > limit_mm:
        return ChannelStatus.OVER_RANGE
    if value < -limit_mm:
        return ChannelStatus.UNDER_RANGE
    return ChannelStatus.OK
