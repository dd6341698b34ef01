"""Joint values and soft-limit margins as a person reads them: revolute joints in degrees and
prismatic ones in mm, the units robot files and ``[limits]`` are written in (docs/robot-file.md:
``angle_unit = "deg"`` by default), never the radians the station computes in.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["LimitMargin", "joint_value", "joint_values", "nearest_limit"]


def joint_value(v: float, kind: str, digits: int = 2) -> str:
    """One joint value [rad | mm] as text in deg or mm."""
    if not np.isfinite(v):
        return "—"
    return f"{np.degrees(v):.{digits}f}°" if kind == "revolute" else f"{v:.{max(digits - 1, 1)}f} mm"


def joint_values(q: Sequence[float] | np.ndarray, kinds: Sequence[str], digits: int = 2) -> str:
    """Joint values [rad | mm] as ``"12.30°, 45.00°, -161.5 mm, …"``."""
    return ", ".join(joint_value(float(v), k, digits) for v, k in zip(q, kinds))


@dataclass(frozen=True)
class LimitMargin:
    """The joint nearest to (or beyond) a soft limit: ``joint`` 1-based, ``side`` "lower" or
    "upper", ``margin`` in rad | mm (negative: beyond the limit), ``kind`` the joint's type."""

    joint: int
    side: str
    margin: float
    kind: str
    limit: float

    def describe(self, required: float = 0.0) -> str:
        """e.g. ``joint 5 is 1.20° inside its upper soft limit 120.00° (at least 3.00° needed)``."""
        where = "inside" if self.margin >= 0 else "beyond"
        text = (f"joint {self.joint} is {joint_value(abs(self.margin), self.kind)} {where} its {self.side} soft limit "
                f"{joint_value(self.limit, self.kind)}")
        if required > 0:
            text += f" (the plan keeps at least {joint_value(required, self.kind)})"
        return text


def nearest_limit(q: Sequence[float] | np.ndarray, limits: np.ndarray, kinds: Sequence[str],
                  required: Sequence[float] | np.ndarray | None = None) -> LimitMargin | None:
    """The joint of ``q`` [rad | mm] with the smallest margin to ``limits`` ``(g, 2)``, less
    ``required`` per joint (what the plan keeps free): the joint that made a pose "too close".
    None when ``q`` is not finite (the inverse kinematics found no solution)."""
    q = np.asarray(q, dtype=float)
    if not np.all(np.isfinite(q)):
        return None
    lim = np.asarray(limits, dtype=float)
    need = np.zeros(len(q)) if required is None else np.asarray(required, dtype=float)
    lower, upper = q - lim[:, 0], lim[:, 1] - q
    slack = np.minimum(lower, upper) - need
    j = int(np.argmin(slack))
    side = "lower" if lower[j] <= upper[j] else "upper"
    margin = float(lower[j] if side == "lower" else upper[j])
    return LimitMargin(j + 1, side, margin, kinds[j], float(lim[j, 0 if side == "lower" else 1]))
