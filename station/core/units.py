"""Units and angle helpers: the one place that defines them.

Inside the station everything is millimetres and radians; people read µm and arc seconds, and
robot and cell files are written in mm and degrees. Convert at the edges with these constants:
``value_rad / ARCSEC`` is arc seconds, ``value_mm / UM`` is µm.
"""

from __future__ import annotations

import math

import numpy as np

#: one degree [rad]
DEG = math.pi / 180.0
#: one arc minute [rad]
ARCMIN = DEG / 60.0
#: one arc second [rad]
ARCSEC = DEG / 3600.0
#: one micrometre [mm]
UM = 1e-3
TWO_PI = 2.0 * math.pi


def wrap_angle(a: np.typing.ArrayLike) -> np.ndarray:
    """Angles wrapped to (−π, π] (the convention of the correction table and ISO 9283)."""
    w = np.mod(np.asarray(a, dtype=float) + math.pi, TWO_PI) - math.pi  # [−π, π)
    return np.where(w <= -math.pi, w + TWO_PI, w)


def to_um(mm: np.typing.ArrayLike) -> np.ndarray:
    """mm → µm."""
    return np.asarray(mm, dtype=float) / UM


def to_arcsec(rad: np.typing.ArrayLike) -> np.ndarray:
    """rad → arc seconds."""
    return np.asarray(rad, dtype=float) / ARCSEC
