"""``station check``'s device lines for people, and its verdict on the probe channels.

The probe interface's identification and one row per probe of the head file (its id, channel and
state); the controller's state in words and its joints in deg / mm, never a driver's dataclass
repr. A probe the head file wires whose channel gives no valid reading is a device fault
(:class:`ProbeChannelsInvalid`, exit 7): the run would stop at its first touch.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from station.cell.limits.joint_text import joint_values
from station.errors import Outcome, StationError

__all__ = ["ProbeChannelsInvalid", "controller_lines", "probe_lines", "wired_channels_invalid"]


class ProbeChannelsInvalid(StationError):
    """Probes the head file wires read no valid value at ``station check``."""

    outcome = Outcome.DEVICE_FAULT


def _status_name(status: Any) -> str:
    return str(getattr(status, "value", status)).replace("_", " ")


def _wired(head: Any, n_channels: int) -> list[tuple[str, int]]:
    """(probe id, channel) of the head file; without a head file every channel as ``P<n>``."""
    if head is None:
        return [(f"P{c}", c) for c in range(1, n_channels + 1)]
    return [(str(pid), int(c)) for pid, c in zip(head.probe_ids, head.probe_channels)]


def probe_lines(where: str, info: Any, statuses: Sequence[Any], head: Any) -> list[str]:
    """The probe interface as a table: model, firmware, channels; a row per wired probe."""
    model = getattr(info, "model", "?")
    firmware = getattr(info, "firmware", "?")
    n = getattr(info, "channels", len(statuses))
    wired = _wired(head, len(statuses))
    lines = [f"probe head {where}: {model}, firmware {firmware}, {n} channels; {len(wired)} probes wired",
             f"  {'probe':8s} {'channel':>7s}  state"]
    for pid, c in wired:
        state = _status_name(statuses[c - 1]) if 1 <= c <= len(statuses) else "no such channel"
        lines.append(f"  {pid:8s} {c:7d}  {state}")
    unused = sorted(set(range(1, len(statuses) + 1)) - {c for _, c in wired})
    if unused:
        lines.append(f"  channel{'s' if len(unused) > 1 else ''} {', '.join(map(str, unused))}: not wired "
                     f"(not read in a run)")
    return lines


def wired_channels_invalid(statuses: Sequence[Any], head: Any) -> ProbeChannelsInvalid | None:
    """The error for the wired probes whose channel reads INVALID (None: none does). Over or
    under range is not one: a free plunger stands at the end of its stroke."""
    bad = [(pid, c, _status_name(statuses[c - 1])) for pid, c in _wired(head, len(statuses))
           if 1 <= c <= len(statuses) and _status_name(statuses[c - 1]) == "invalid"]
    if not bad:
        return None
    named = ", ".join(f"{pid} (channel {c})" for pid, c, _ in bad)
    return ProbeChannelsInvalid(
        f"{len(bad)} of the head's {len(_wired(head, len(statuses)))} wired probes read invalid: {named}. "
        f"Check each one's cable and "
        f"amplifier, and that its plunger is free; a probe touching nothing reads invalid on some units: put the "
        f"head on a cube of the body and check again")


def controller_lines(where: str, status: Any, joints: Sequence[float], joint_types: Sequence[str],
                     map_version: Any, register_base: int) -> list[str]:
    """The controller's state in words and its joints in deg / mm."""
    flags = [("ready", "ready", "NOT ready"), ("in_position", "in position", "not in position"),
             ("moving", "moving", "standing"), ("estop", "E-STOP", "e-stop released")]
    state = ", ".join(yes if getattr(status, k, False) else no for k, yes, no in flags)
    if getattr(status, "error", False):
        message = getattr(status, "error_message", "") or f"error code {getattr(status, 'error_code', '?')}"
        state += f", ERROR: {message}"
    else:
        state += ", no error"
    table = "active" if getattr(status, "table_active", False) else "none active"
    staged = ", one staged" if getattr(status, "table_staged", False) else ""
    return [f"controller {where}: {state}",
            f"  joints: {joint_values(joints, joint_types)}",
            f"  correction table: {table}{staged}; register map {map_version} at base {register_base}"]
