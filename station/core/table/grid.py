"""The grid of a correction table: its axes from a range and a step, and what it costs in values.

The table's data (axes, values, their resolution) and the controller's interpolation rule are
:mod:`station.core.table.values`; its register encoding is the driver's. How many values a
controller holds is the controller's: the caller passes that capacity in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from station.core.table.values import TableAxis
from station.core.units import TWO_PI
from station.errors import ConfigError

__all__ = ["GridSpec"]

#: relative tolerance for "range is a whole number of steps"
_STEP_TOL = 1e-9


def _count(name: str, lo: float, hi: float, step: float, unit: str) -> int:
    span = hi - lo
    if span == 0.0:
        return 1
    n = span / step
    k = round(n)
    if k < 1 or abs(n - k) > _STEP_TOL * max(1.0, n):
        divisors = [span / m for m in range(max(1, math.floor(n)), math.floor(n) + 3) if m > 0]
        hint = ", ".join(f"{d:.6g}" for d in divisors[:3])
        raise ConfigError(
            f"grid {name}: the range {lo:.6g}..{hi:.6g} {unit} is not a whole number of "
            f"{step:.6g} {unit} steps ({n:.4g}); choose a step that divides {span:.6g} {unit}, "
            f"e.g. {hint}")
    return k + 1


@dataclass(frozen=True)
class GridSpec:
    """The grid of a correction table over the Cartesian target (robot base frame).

    ``*_range`` = (first node, last node) [mm]; the range must be a whole number of ``*_step``
    [mm] (a range of zero length gives one node: the table is then constant along that axis).
    ``yaw_range`` / ``yaw_step`` [rad]: with ``yaw_periodic`` (default) the range must be one full
    turn and a whole number of steps; node ``count`` is node 0 again. ``elbows``: ``(1, -1)``
    (configuration 0 = elbow +1, 1 = elbow −1, the controller's order) or ``(1,)``.

    The default grid, x∈[350, 650], y∈[−250, 250], z∈[250, 450] mm with 11 × 15 × 2 × 12
    nodes per elbow (31 680 values with 4 joints), keeps the interpolation bound at ≈ 3–4 µm
    over the whole grid for the reference cell's parameter errors (0.04 mm, 2.5′). The full
    reference workspace up to x = 750 mm (:meth:`full_workspace`) reaches a wrist radius of
    ~797 mm (reach 800 mm): near the stretched arm the correction curves so strongly that a few
    µm there need ≤ 10 mm steps, far beyond 32 000 values (figures in ``docs/correction.md``;
    :meth:`CorrectionTable.bound_at` gives the bound per target). The controller refuses
    Cartesian targets outside the grid of an active table.
    """

    x_range: tuple[float, float] = (350.0, 650.0)
    y_range: tuple[float, float] = (-250.0, 250.0)
    z_range: tuple[float, float] = (250.0, 450.0)
    x_step: float = 30.0
    y_step: float = 500.0 / 14
    z_step: float = 200.0
    yaw_range: tuple[float, float] = (-math.pi, math.pi)
    yaw_step: float = TWO_PI / 12
    yaw_periodic: bool = True
    elbows: tuple[int, ...] = (1, -1)

    def __post_init__(self) -> None:
        for name in ("x", "y", "z", "yaw"):
            r = getattr(self, f"{name}_range")
            try:
                lo, hi = (float(v) for v in r)
            except (TypeError, ValueError):
                raise ConfigError(f"grid {name}_range must be two numbers (first, last node), got {r!r}") from None
            step = getattr(self, f"{name}_step")
            if not (math.isfinite(lo) and math.isfinite(hi)):
                raise ConfigError(f"grid {name}_range must be finite, got {r!r}")
            if hi < lo:
                raise ConfigError(f"grid {name}_range must be (low, high), got {r!r}")
            if not (isinstance(step, (int, float)) and math.isfinite(step) and step > 0):
                raise ConfigError(f"grid {name}_step must be a finite number > 0, got {step!r}")
            object.__setattr__(self, f"{name}_range", (lo, hi))
            object.__setattr__(self, f"{name}_step", float(step))
        if self.yaw_periodic:
            lo, hi = self.yaw_range
            if abs((hi - lo) - TWO_PI) > 1e-9:
                raise ConfigError(
                    f"a periodic yaw axis must span one full turn (2π rad), got "
                    f"{hi - lo:.9g} rad; use yaw_range=(-pi, pi) or yaw_periodic=False")
        elbows = tuple(int(e) for e in self.elbows)
        if elbows not in ((1, -1), (1,)):
            raise ConfigError(
                f"grid elbows must be (1, -1) or (1,), got {self.elbows!r}: the controller "
                f"reads configuration 0 as elbow +1 and applies a one-configuration table to "
                f"every move")
        object.__setattr__(self, "elbows", elbows)
        self.axes()  # validates the step divisions

    @classmethod
    def full_workspace(cls, **kw: Any) -> "GridSpec":
        """The whole reference workspace x∈[350, 750], y∈[−250, 250], z∈[250, 450] mm,
        11 × 15 × 2 × 12 nodes per elbow (31 680 values): covers every target there, but the
        bound reaches ~100–260 µm in the corners at radius 760–790 mm (≈ 7–11 µm for
        radius ≤ 700 mm); check :meth:`CorrectionTable.bound_at` for the targets you use."""
        base: dict[str, Any] = {"x_range": (350.0, 750.0), "x_step": 40.0}
        base.update(kw)
        return cls(**base)

    # -- derived ---------------------------------------------------------------------------
    def _counts(self) -> tuple[int, int, int, int]:
        nx = _count("x", *self.x_range, self.x_step, "mm")
        ny = _count("y", *self.y_range, self.y_step, "mm")
        nz = _count("z", *self.z_range, self.z_step, "mm")
        if self.yaw_periodic:
            n = TWO_PI / self.yaw_step
            k = round(n)
            if k < 2 or abs(n - k) > _STEP_TOL * n:
                raise ConfigError(
                    f"grid yaw_step {self.yaw_step:.9g} rad does not divide a full turn "
                    f"({n:.4g} steps); use 2π/N, e.g. {TWO_PI / max(2, math.floor(n)):.9g} or "
                    f"{TWO_PI / max(2, math.ceil(n)):.9g}")
            nyaw = k
        else:
            nyaw = _count("yaw", *self.yaw_range, self.yaw_step, "rad")
        return nx, ny, nz, nyaw

    def axes(self) -> tuple[TableAxis, ...]:
        """The controller's table axes x, y, z, yaw (start and step rounded to float32)."""
        nx, ny, nz, nyaw = self._counts()
        return (
            TableAxis(self.x_range[0], self.x_step, nx),
            TableAxis(self.y_range[0], self.y_step, ny),
            TableAxis(self.z_range[0], self.z_step, nz),
            TableAxis(self.yaw_range[0], self.yaw_step, nyaw, periodic=self.yaw_periodic),
        )

    @property
    def shape(self) -> tuple[int, int, int, int]:
        return self._counts()

    @property
    def n_nodes(self) -> int:
        """Nodes per elbow configuration."""
        return int(np.prod(self.shape))

    def n_values(self, n_joints: int = 4) -> int:
        """Values the table holds: configurations × nodes × joints."""
        return len(self.elbows) * self.n_nodes * n_joints

    def check_capacity(self, n_joints: int, capacity: int) -> None:
        """Refuse (:class:`ConfigError`) a grid of more values than ``capacity`` (the controller's)."""
        n = self.n_values(n_joints)
        if n > capacity:
            raise ConfigError(
                f"correction grid {'×'.join(map(str, self.shape))} × {len(self.elbows)} elbows × "
                f"{n_joints} joints = {n} values exceeds the controller's {capacity}: use "
                f"larger steps or a smaller range")
