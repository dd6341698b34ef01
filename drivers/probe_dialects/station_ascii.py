"""``station-ascii``: the station's own ASCII dialect, for a custom interface.

The table itself is :mod:`drivers.probe_protocol` (``COMMANDS``, ``ERROR_CODES``, ``MARKERS``),
unchanged byte for byte; this module presents it as a :class:`~drivers.probe_dialects.Dialect`.
Source: ``docs/protocols.md``, "Probe-head serial protocol", "station-ascii" (this project).
"""

from __future__ import annotations

from drivers import probe_protocol as pp
from drivers.probe_dialects.base import Dialect, Exchange, LineRule, LineSettings

__all__ = ["DIALECT", "LINE"]

#: A custom interface: any standard rate, 7 or 8 data bits, any parity, 1 or 2 stop bits, so
#: long as both ends agree; the station's historical setting 38 400 8N1 is the default.
LINE = LineRule(
    baudrates=(1200, 2400, 4800, 9600, 19200, 38400, 57600, 115200),
    bytesizes=(7, 8), parities=("none", "even", "odd"), stopbits=(1, 2),
    default=LineSettings(38400, 8, "none", 1),
    source="docs/protocols.md, station-ascii, line settings",
)


def _m0_fields(channels: int | None):
    def parse(line: bytes):
        values, status = pp.parse_m0(line, channels)
        return list(zip(values.tolist(), status))
    return parse


def _snapshot(channels: int | None) -> list[Exchange]:
    return [Exchange(pp.format_request("M0"), "M0", _m0_fields(channels))]


def _identify() -> Exchange:
    return Exchange(pp.format_request("ID"), "ID", pp.parse_id)


def _claims(line: bytes, sent: str) -> bool:
    """A station-ascii unit answers a command it lacks with ``ER,<name>,00``."""
    body = bytes(line).rstrip(b"\r\n")
    name = sent[:2].encode("ascii", "replace")
    return sent[:2] not in pp.COMMANDS and body == b"ER," + name + b",00"


DIALECT = Dialect(
    name="station-ascii",
    title="station ASCII probe interface",
    model="station-ascii",
    source="docs/protocols.md, 'Probe-head serial protocol', station-ascii",
    line=LINE,
    commands=pp.COMMANDS,
    errors=pp.ERROR_CODES,
    snapshot=_snapshot,
    identify=_identify,
    resync=Exchange(pp.format_request(pp.RESYNC_COMMAND), pp.RESYNC_COMMAND, pp.parse_id),
    reply_names=pp.reply_names,
    claims=_claims,
    request_end=b"\r",
    unknown_command_code=pp.ERR_UNKNOWN_COMMAND,
    value_limit_mm=pp.VALUE_LIMIT_MM,
)
