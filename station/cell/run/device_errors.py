"""Typed station errors for a device that could not be used (outcome DEVICE_FAULT, exit 7).

The drivers raise their own errors; :mod:`station.cell.pipeline.outcomes` classifies them for a run.
A command that talks to a device outside a run (``station reset``) wraps them in
:class:`DeviceUnavailable`, whose message says which device, what was and was not sent, and
what to check, so the operator never sees a driver's internals or an "internal error".
"""

from __future__ import annotations

from station.errors import Outcome, StationError

__all__ = ["DeviceUnavailable", "ControllerHeld"]


class DeviceUnavailable(StationError):
    """A device did not answer, or answered wrongly, outside a run; nothing moved."""

    outcome = Outcome.DEVICE_FAULT


class ControllerHeld(StationError):
    """Another station holds the controller (one station per controller, map 3's claim): this one
    was refused before it sent a single command, whatever run database either uses.

    ``hint`` names the holder (host, PID, since): what the operator must go and see."""

    outcome = Outcome.DEVICE_FAULT

    def __init__(self, message: str, hint: str):
        super().__init__(message)
        self.hint = hint
