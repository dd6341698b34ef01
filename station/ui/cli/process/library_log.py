"""Where the libraries' own log lines go: into the station's log, never onto the terminal.

pymodbus logs what it meets on the wire ("Invalid Modbus protocol id: 21584", "Connection to (…)
failed") at ERROR level on its logger ``pymodbus.logging``. With no handler of the station's
there, Python's last-resort handler printed them on stderr, in the middle of the station's own
messages, in words for a Modbus developer. :func:`route_library_logs` gives the ``pymodbus``
logger a handler that hands each record to the station's log, the ``station.devices.pymodbus``
logger, at DEBUG level (its own level kept in the text): the station's message about the same
event (a device fault with what to do) is what the operator reads; whoever configures the
``station`` logger (a service's logging set-up, a debugging session) still gets every line.
"""

from __future__ import annotations

import logging

__all__ = ["LIBRARY_LOGGERS", "STATION_LOG", "route_library_logs"]

#: the third-party loggers whose records belong in the station's log
LIBRARY_LOGGERS = ("pymodbus",)
#: the station's log of what the device libraries said
STATION_LOG = "station.devices"


class _IntoStationLog(logging.Handler):
    """Re-log a library's record on the station's log at DEBUG, its level and text kept."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            text = record.getMessage()
        except Exception:  # a malformed record must not break the command that logged it
            text = str(record.msg)
        logging.getLogger(f"{STATION_LOG}.{record.name.split('.')[0]}").debug(
            "%s %s: %s", record.name, record.levelname.lower(), text)


def route_library_logs() -> None:
    """Route :data:`LIBRARY_LOGGERS` into the station's log (idempotent; imports no library)."""
    for name in LIBRARY_LOGGERS:
        lib = logging.getLogger(name)
        if not any(isinstance(h, _IntoStationLog) for h in lib.handlers):
            lib.addHandler(_IntoStationLog())
        lib.propagate = False
