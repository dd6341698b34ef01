"""ISO 9283 pose accuracy and repeatability (brief §8). Pure functions; inputs in mm and rad.

ISO 9283 (pose characteristics), for one commanded pose visited ``n`` times:

* barycentre ``x̄ = mean(x_j)`` (likewise ȳ, z̄) of the attained positions;
* ``APx = x̄ − x_c`` (likewise APy, APz); pose accuracy ``AP = sqrt(APx² + APy² + APz²)``;
* ``l_j = |(x_j, y_j, z_j) − (x̄, ȳ, z̄)|``; ``l̄ = mean(l_j)``;
  ``S_l = sqrt(Σ (l_j − l̄)² / (n − 1))``; pose repeatability ``RP = l̄ + 3 S_l``;
* orientation about x, y, z (a, b, c): ``APa = ā − a_c`` with ``ā`` the mean attained angle,
  ``RPa = ±3 S_a``, ``S_a = sqrt(Σ (a_j − ā)² / (n − 1))`` (likewise b, c). Angle differences are
  taken relative to the commanded angle and wrapped to (−π, π] before averaging.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from station.core.units import ARCSEC, wrap_angle
from station.errors import ConfigError

__all__ = ["PoseStats", "iso9283_pose"]



@dataclass(frozen=True)
class PoseStats:
    """ISO 9283 figures of one pose [mm, rad]. Orientation fields are None without orientations."""

    n_cycles: int
    barycentre: np.ndarray
    AP: float
    APx: float
    APy: float
    APz: float
    RP: float
    l_mean: float
    S_l: float
    APa: float | None = None
    APb: float | None = None
    APc: float | None = None
    RPa: float | None = None
    RPb: float | None = None
    RPc: float | None = None

    def as_dict(self) -> dict:
        """Figures in µm and arc seconds (JSON-friendly)."""
        d = {"n_cycles": self.n_cycles, "AP_um": self.AP * 1e3, "APx_um": self.APx * 1e3,
             "APy_um": self.APy * 1e3, "APz_um": self.APz * 1e3, "RP_um": self.RP * 1e3}
        for k in ("APa", "APb", "APc", "RPa", "RPb", "RPc"):
            v = getattr(self, k)
            if v is not None:
                d[f"{k}_arcsec"] = v / ARCSEC
        return d


def iso9283_pose(commanded, attained, commanded_orientation=None,
                 attained_orientations=None) -> PoseStats:
    """ISO 9283 pose accuracy AP and repeatability RP of one commanded pose.

    ``commanded`` ``(3,)`` [mm]; ``attained`` ``(n_cycles, 3)`` [mm], n_cycles ≥ 2 (ISO 9283 asks
    for 30). Optional ``commanded_orientation`` ``(3,)`` and ``attained_orientations``
    ``(n_cycles, 3)``: angles a, b, c about x, y, z [rad].
    """
    c = np.asarray(commanded, dtype=float)
    X = np.asarray(attained, dtype=float)
    if c.shape != (3,):
        raise ConfigError(f"commanded position must have shape (3,), got {c.shape}")
    if X.ndim != 2 or X.shape[1] != 3:
        raise ConfigError(f"attained positions must have shape (n_cycles, 3), got {X.shape}")
    n = X.shape[0]
    if n < 2:
        raise ConfigError("ISO 9283 repeatability needs at least 2 cycles per pose (the standard asks for 30)")
    if not (np.all(np.isfinite(c)) and np.all(np.isfinite(X))):
        raise ConfigError("positions contain NaN or infinity")
    bary = X.mean(axis=0)
    ap = bary - c
    dist = np.linalg.norm(X - bary, axis=1)
    l_mean = float(dist.mean())
    s_l = float(np.std(dist, ddof=1))
    ori: dict = {}
    if (commanded_orientation is None) != (attained_orientations is None):
        raise ConfigError("give both the commanded and the attained orientations, or neither")
    if commanded_orientation is not None:
        co = np.asarray(commanded_orientation, dtype=float)
        A = np.asarray(attained_orientations, dtype=float)
        if co.shape != (3,) or A.shape != (n, 3):
            raise ConfigError(f"orientations must have shapes (3,) and ({n}, 3), got {co.shape}, {A.shape}")
        d = wrap_angle(A - co)
        mean = d.mean(axis=0)
        s = np.std(d, axis=0, ddof=1)
        ori = dict(APa=float(mean[0]), APb=float(mean[1]), APc=float(mean[2]),
                   RPa=float(3 * s[0]), RPb=float(3 * s[1]), RPc=float(3 * s[2]))
    bary.setflags(write=False)
    return PoseStats(n, bary, float(np.linalg.norm(ap)), float(ap[0]), float(ap[1]), float(ap[2]),
                     l_mean + 3 * s_l, l_mean, s_l, **ori)
