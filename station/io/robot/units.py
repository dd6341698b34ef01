"""Unit plausibility of a robot file's raw numbers, before any conversion or wrapping (issue 37 §3).

A unit slip turns a robot into another robot that still parses: a DH α of 90 under ``[rad]`` is
90 rad, which the conversion to a rotation wraps to 26.6°; link lengths in metres under ``[mm]``
make a robot a thousand times too small; radians under ``[deg]`` give twists of 1.57°. Each
passed :mod:`station.io.robot.bounds` (±2π·10 rad, ±100 m after conversion) and failed later,
far from the file, blaming the set-up or the soft limits. So each column is judged here on the
numbers as written, against what its header's unit makes of them, and a slip is refused naming
the column (or key), the line, the value and the unit it reads like.

The rules, deliberately wide so that no real robot trips them:

* an angle under rad beyond a turn (2π; a revolute limit beyond two turns, 4π): degrees;
* an angle under deg that is a non-zero multiple of π/2 in radians (1.5708, 3.1416, 4.7124 to
  1e-3) where no DH twist or offset is a few degrees; or every revolute joint's range under
  deg narrower than 4π (12.6°): radians;
* all lengths of the arm together (|d| + |a| of every row, |x| + |y| + |z| of every joint
  transform and the tool) under mm below 10 mm: metres; under m beyond 50 m: millimetres.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from station.errors import ConfigError

__all__ = ["RawValue", "check_raw_units", "check_toml_units"]

TURN = 2.0 * math.pi
#: a whole arm shorter than this [mm] under mm is in metres; longer than this [m] under m in mm
ARM_MIN_MM = 10.0
ARM_MAX_M = 50.0
_RADIAN_LOOKS = (math.pi / 2, math.pi, 1.5 * math.pi)


@dataclass(frozen=True)
class RawValue:
    """One number as the file writes it: ``where`` (``"line 4"``, ``"transform A2"``),
    ``column`` (``"alpha [rad]"``, ``"A2.yaw"``), ``kind`` (``"angle"``, ``"length"``,
    ``"limit-angle"``, ``"limit-length"``), ``unit`` as declared, ``value`` raw."""

    where: str
    column: str
    kind: str
    unit: str
    value: float


def _refuse(source: str, v: RawValue, reads: str, why: str, fix: str) -> ConfigError:
    return ConfigError(f"{source}: {v.column} = {v.value:g} ({v.where}) {why}: it reads like {reads}, not "
                       f"{v.unit}; {fix}")


def _looks_radian(x: float) -> bool:
    return any(abs(abs(x) - r) <= 1e-3 for r in _RADIAN_LOOKS)


def check_raw_units(values: Sequence[RawValue], source: str, fix_angle: str, fix_length: str) -> None:
    """Refuse the first unit slip among ``values`` (see the module); ``fix_angle`` /
    ``fix_length`` say where the unit is written ({unit} is replaced by the likely one)."""
    for v in values:
        if v.kind == "angle" and v.unit == "rad" and abs(v.value) > TURN * 1.001:
            raise _refuse(source, v, "degrees", "is more than a turn (2π rad)", fix_angle.format(unit="deg"))
        if v.kind == "limit-angle" and v.unit == "rad" and abs(v.value) > 2 * TURN * 1.001:
            raise _refuse(source, v, "degrees", "is more than two turns (4π rad) from zero", fix_angle.format(unit="deg"))
        if v.kind == "angle" and v.unit == "deg" and _looks_radian(v.value):
            raise _refuse(source, v, "radians", f"is π/2·{round(abs(v.value) / (math.pi / 2))} in radians, "
                          "and no twist or joint offset is a degree and a half", fix_angle.format(unit="rad"))
    lim = [v for v in values if v.kind == "limit-angle" and v.unit == "deg"]
    if len(lim) >= 2:
        ranges: dict[str, list[float]] = {}
        for v in lim:
            ranges.setdefault(v.where, []).append(v.value)
        spans = [max(x) - min(x) for x in ranges.values() if len(x) == 2]
        if spans and max(spans) < 2 * TURN:
            v = max(lim, key=lambda w: abs(w.value))
            raise _refuse(source, v, "radians", f"and every revolute joint's range is narrower than {2 * TURN:.1f}°",
                          fix_angle.format(unit="rad"))
    lengths = [v for v in values if v.kind == "length"]
    if lengths:
        total = sum(abs(v.value) for v in lengths)
        longest = max(lengths, key=lambda w: abs(w.value))
        if longest.unit == "mm" and 0.0 < total < ARM_MIN_MM:
            raise _refuse(source, longest, "metres", f"and the whole arm's lengths add up to {total:g} mm",
                          fix_length.format(unit="m"))
        if longest.unit == "m" and total > ARM_MAX_M:
            raise _refuse(source, longest, "millimetres", f"and the whole arm's lengths add up to {total:g} m",
                          fix_length.format(unit="mm"))


def check_toml_units(data: dict, source: str) -> None:
    """:func:`check_raw_units` on a TOML robot file's transforms (the first, the set-up, left out:
    where the robot stands is no property of the robot), as written under ``[robot]``'s
    ``angle_unit`` and ``length_unit``."""
    head = data.get("robot", {}) if isinstance(data, dict) else {}
    a_unit, l_unit = str(head.get("angle_unit", "deg")), str(head.get("length_unit", "mm"))
    values: list[RawValue] = []
    for e in (data.get("transform") or [])[1:]:
        if not isinstance(e, dict):
            continue
        name = str(e.get("name", "?"))
        for key in ("x", "y", "z", "roll", "pitch", "yaw"):
            v = e.get(key)
            if isinstance(v, (int, float)) and not isinstance(v, bool):
                angle = key in ("roll", "pitch", "yaw")
                values.append(RawValue(f"transform {name}", f"{name}.{key}", "angle" if angle else "length",
                                       a_unit if angle else l_unit, float(v)))
        lim = e.get("limits")
        if e.get("joint") == "revolute" and isinstance(lim, list):
            values += [RawValue(f"transform {name}", f"{name}.limits", "limit-angle", a_unit, float(x))
                       for x in lim if isinstance(x, (int, float)) and not isinstance(x, bool)]
    check_raw_units(values, source, "if so, write [robot] angle_unit = \"{unit}\"",
                    "if so, write [robot] length_unit = \"{unit}\"")
