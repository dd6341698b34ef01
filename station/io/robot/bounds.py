"""Physical plausibility of robot files (issue 33): lengths and offsets beyond 100 m, angles and
revolute limits beyond 2π·10 rad, and absurd joint-map factors are refused with the bound, for every
robot file format (TOML, DH/MDH, URDF); and :func:`nearest`, the "did you mean" of a refused name.
"""

from __future__ import annotations

import difflib
import math

import numpy as np

from station.core.kinematics.model import RobotModel
from station.errors import ConfigError

#: a length or offset beyond 100 m, or an angle beyond 2π·10 rad, is no robot's
LENGTH_BOUND_MM = 100_000.0
ANGLE_BOUND_RAD = 20 * math.pi
#: a joint map's coupling factor beyond this (mm per deg, deg per deg …) is a typo
COUPLING_BOUND = 1e4


def nearest(name: str, known: tuple[str, ...] | list[str]) -> str:
    """`` (did you mean 'length_unit'?)`` for a near miss, else ``''``."""
    close = difflib.get_close_matches(name, list(known), n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""


def check_plausible(model: RobotModel, source: str) -> None:
    """Refuse lengths and offsets beyond 100 m, angles and revolute limits beyond 2π·10 rad, with the
    bound: such a value is a unit slip or a typo, and the numerics would only hide it."""
    nominal = np.asarray(model.nominal, dtype=float)
    for k, name in enumerate(model.param_names):
        is_angle = name.rsplit(".", 1)[-1] in ("roll", "pitch", "yaw")
        bound = ANGLE_BOUND_RAD if is_angle else LENGTH_BOUND_MM
        if not abs(nominal[k]) <= bound:
            raise ConfigError(f"{source}: parameter {name} = {_shown(nominal[k], is_angle)} is beyond physical "
                              f"plausibility (at most {_bound(is_angle)}); check the value and the file's unit")
    for j, (lo, hi) in enumerate(np.asarray(model.joint_limits, dtype=float)):
        is_angle = model.joint_types[j] == "revolute"
        bound = ANGLE_BOUND_RAD if is_angle else LENGTH_BOUND_MM
        if not (abs(lo) <= bound and abs(hi) <= bound):
            raise ConfigError(f"{source}: joint {j + 1}'s limits [{_shown(lo, is_angle)}, {_shown(hi, is_angle)}] "
                              f"are beyond physical plausibility (at most {_bound(is_angle)})")


def check_map_plausible(offsets: tuple[float, ...], ks: tuple[float, ...], names: tuple[str, ...],
                        joint_types: tuple[str, ...], source: str) -> None:
    """A joint map's offsets (rad | mm) within the bounds of :func:`check_plausible`, its coupling
    factors within ±:data:`COUPLING_BOUND`."""
    for name, off, k, kind in zip(names, offsets, ks, joint_types):
        is_angle = kind == "revolute"
        if not abs(off) <= (ANGLE_BOUND_RAD if is_angle else LENGTH_BOUND_MM):
            raise ConfigError(f"{source}: the joint map's offset of {name} = {_shown(off, is_angle)} is beyond "
                              f"physical plausibility (at most {_bound(is_angle)})")
        if not abs(k) <= COUPLING_BOUND:
            raise ConfigError(f"{source}: the joint map's coupling factor of {name} = {k:.6g} is beyond "
                              f"plausibility (at most ±{COUPLING_BOUND:g}); check the value and its unit")


def _shown(v: float, is_angle: bool) -> str:
    return f"{math.degrees(v):.6g} deg" if is_angle and math.isfinite(v) else f"{v:.6g} {'rad' if is_angle else 'mm'}"


def _bound(is_angle: bool) -> str:
    return "±3600 deg = 2π·10 rad" if is_angle else "±100 m"
