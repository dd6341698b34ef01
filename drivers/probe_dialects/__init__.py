"""Probe-interface dialects: one declarative table per real (or the station's own) interface.

Each dialect module holds its unit's commands, replies, line settings, error codes and value
encoding as tables, with the manual and section they come from beside each table. The driver
(:mod:`drivers.probe_head`), the simulator (:mod:`simulators.probe_head_sim`) and the tests all
read the same tables. This module is the registry:

* :data:`DIALECTS` name -> :class:`Dialect`; :func:`get_dialect` (unknown name: a typed error
  listing the known ones); :data:`DEFAULT_DIALECT` (``station-ascii`` until the station flips it);
* :class:`LineSettings` / :class:`LineRule` and :func:`check_line_settings`, which refuses what
  a dialect's unit does not offer and says what it does;
* :class:`Exchange`, one request and how to read its reply, which a dialect hands the driver;
* :func:`dialects_claiming`, which names the dialects a foreign reply looks like.

The configuration keys the station maps onto this: ``[devices] probe_protocol`` -> the dialect
name, ``baudrate``, ``probe_bytesize`` (7/8), ``probe_parity`` ("none"/"even"/"odd").
"""

from __future__ import annotations

from drivers.probe_dialects import keyence_dl_rs1a, mitutoyo_ga, station_ascii
from drivers.probe_dialects.base import (
    PARITIES,
    Dialect,
    Exchange,
    LineRule,
    LineSettings,
    status_of_number,
)
from drivers.probe_protocol import ProbeConfigError, ProbeLineSettingsError

__all__ = [
    "PARITIES",
    "LineSettings",
    "LineRule",
    "Exchange",
    "Dialect",
    "DIALECTS",
    "DEFAULT_DIALECT",
    "get_dialect",
    "check_line_settings",
    "dialects_claiming",
    "status_of_number",
]

def _registry() -> dict[str, Dialect]:
    return {d.name: d for d in (station_ascii.DIALECT, keyence_dl_rs1a.DIALECT, mitutoyo_ga.DIALECT)}


DIALECTS: dict[str, Dialect] = _registry()
DEFAULT_DIALECT = "station-ascii"


def get_dialect(name: str | Dialect) -> Dialect:
    """The dialect called ``name`` (a :class:`Dialect` passes through)."""
    if isinstance(name, Dialect):
        return name
    dialect = DIALECTS.get(str(name))
    if dialect is None:
        raise ProbeConfigError(
            f"unknown probe protocol {name!r}: set [devices] probe_protocol to one of "
            f"{', '.join(repr(n) for n in DIALECTS)}")
    return dialect


def check_line_settings(dialect: str | Dialect, baudrate: int | None = None, bytesize: int | None = None,
                        parity: str | None = None, stopbits: int | None = None) -> LineSettings:
    """The line settings to open the port with: each None takes the dialect's factory default;
    anything the unit does not offer raises :class:`ProbeLineSettingsError` naming what it does."""
    d = get_dialect(dialect)
    rule = d.line
    s = LineSettings(rule.default.baudrate if baudrate is None else int(baudrate),
                     rule.default.bytesize if bytesize is None else int(bytesize),
                     rule.default.parity if parity is None else str(parity).lower(),
                     rule.default.stopbits if stopbits is None else int(stopbits))
    wrong = []
    if s.baudrate not in rule.baudrates:
        wrong.append(f"baudrate {s.baudrate}")
    if s.bytesize not in rule.bytesizes:
        wrong.append(f"probe_bytesize {s.bytesize}")
    if s.parity not in rule.parities:
        wrong.append(f"probe_parity {s.parity!r}")
    if s.stopbits not in rule.stopbits:
        wrong.append(f"{s.stopbits} stop bits")
    why = ""
    for (size, par), reason in rule.forbidden:
        if (s.bytesize, s.parity) == (size, par):
            wrong.append(f"{size} data bits with parity {par}")
            why = f" ({reason})"
    if wrong:
        raise ProbeLineSettingsError(
            f"{d.title} ({d.name}) does not offer {', '.join(wrong)}{why}: it offers {rule.describe()} "
            f"[{rule.source}]; set [devices] baudrate, probe_bytesize and probe_parity to the unit's own settings")
    return s


def dialects_claiming(line: bytes, sent: str, besides: str = "") -> list[str]:
    """Names of the dialects (other than ``besides``) whose unit answers request ``sent`` so."""
    return [d.name for d in DIALECTS.values() if d.name != besides and d.claims(line, sent)]
