"""The correction grid's interpolation bound, checked before the first motion (issue 18).

The pipeline builds the table only after measuring (:mod:`station.cell.results.pipeline`); a grid too
coarse for the robot's errors then fails after all the robot time is spent. The bound scales with
the curvature of the correction, i.e. with the size of the robot's errors, which is known before
measuring only as a magnitude: ``[simulation]``'s σ of the lengths, the joint offsets and the axis
tilts (its defaults are realistic for an industrial SCARA). So the table is built for a few seeded
robots with errors of that size, and a grid that no such robot meets is refused; one that some of
them miss is reported. A rehearsal is checked the same way as a real cell: the simulated robot's
true errors are the oracle, never an input to the station's decisions.

The refusal says where the bound is reached and which grid step would meet it (the bound of a
multilinear interpolation falls with the square of the step; the proposal is verified).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from drivers.controller_map import MAX_TABLE_VALUES
from station.cell.config.cell_config import CellConfig, correction_grid
from station.core.correction_table import CorrectionTable, build_correction_table
from station.core.units import ARCSEC
from station.errors import ConfigError

__all__ = ["GridTooCoarse", "GridCheck", "expected_errors", "check_grid", "DRAWS"]

#: seeded robots with the expected error magnitude whose tables are checked
DRAWS = 5
#: random samples of each table's own interpolation check (the edge bound covers every cell)
_N_CHECK = 200
_SEED = 20240618


class GridTooCoarse(ConfigError):
    """The correction grid cannot carry the expected correction within
    ``correction.max_interpolation_um``: found before anything moved (exit code of a
    configuration error)."""


@dataclass(frozen=True)
class GridCheck:
    """The bound [µm] of each seeded robot's table."""

    bounds_um: tuple[float, ...]
    limit_um: float

    @property
    def n_over(self) -> int:
        return sum(1 for b in self.bounds_um if b > self.limit_um)

    def note(self) -> str | None:
        """A line for the operator when some robots of this error size would miss the limit."""
        if not self.n_over:
            return None
        return (f"the correction grid meets correction.max_interpolation_um = {self.limit_um:g} for "
                f"{len(self.bounds_um) - self.n_over} of {len(self.bounds_um)} robots with errors of the size "
                f"[simulation] states (bounds {min(self.bounds_um):.1f}–{max(self.bounds_um):.1f} µm): if the "
                f"identified robot is one of the others, the run stops after measuring; a finer grid avoids that")


def _sim(cfg: CellConfig, key: str, default: float) -> float:
    sim = cfg.simulation
    v = getattr(sim, key, None) if sim is not None else None
    return float(default if v is None else v)


def expected_errors(cfg: CellConfig, n: int = DRAWS, seed: int = _SEED) -> list[np.ndarray]:
    """``n`` seeded parameter vectors of the robot with errors of the ``[simulation]`` sizes:
    lengths σ ``length_sigma_um``, joint offsets σ ``offset_sigma_arcsec`` and axis tilts σ
    ``tilt_sigma_arcsec`` (both ``angle_sigma_arcsec`` where not given). The set-up stays
    nominal: the table never uses it."""
    m = cfg.model
    length = _sim(cfg, "length_sigma_um", 40.0) / 1000.0
    angle = _sim(cfg, "angle_sigma_arcsec", 150.0)
    offset = _sim(cfg, "offset_sigma_arcsec", angle) * ARCSEC
    tilt = _sim(cfg, "tilt_sigma_arcsec", angle) * ARCSEC
    n_t = m.n_params // 6
    sigma = np.zeros((n_t, 6))
    sigma[1:, :3] = length
    sigma[1:, 3:5] = tilt
    sigma[1:, 5] = angle * ARCSEC
    for t, kind in zip(m.joint_transforms, m.joint_types):
        if kind == "revolute":
            sigma[t, 5] = offset  # the yaw of a revolute joint's transform is its encoder offset
    rng = np.random.default_rng(seed)
    return [np.asarray(m.nominal, dtype=float) + (rng.standard_normal((n_t, 6)) * sigma).ravel() for _ in range(n)]


def _table(cfg: CellConfig, params: np.ndarray, correction: Any = None) -> CorrectionTable:
    grid = correction_grid(correction or cfg.correction, tuple(cfg.plan.elbows))
    return build_correction_table(cfg.model, params, grid, n_check=_N_CHECK, capacity=MAX_TABLE_VALUES)


def _where(table: CorrectionTable) -> str:
    """Where the table's bound is reached: the worst cell's lower corner (or the worst sample)."""
    cb = table.cell_bound_um
    if cb is not None and np.any(np.isfinite(cb)):
        idx = np.unravel_index(int(np.nanargmax(cb)), cb.shape)
        axes = table.data.axes
        corner = [a.start + a.step * i for a, i in zip(axes, idx[1:])]
        ends = [a.start + a.step * (i + 1) for a, i in zip(axes, idx[1:])]
        elbow = table.elbows[int(idx[0])]
        parts = [f"{n} {lo:g}…{hi:g} mm" for n, lo, hi in zip("xyz", corner[:3], ends[:3])]
        if len(axes) > 3:
            parts.append(f"yaw {round(math.degrees(corner[3]), 3):g}…{round(math.degrees(ends[3]), 3):g}°")
        return f"in the cell {', '.join(parts)}, elbow {elbow:+d} (robot base frame)"
    w = table.check.worst if table.check is not None else ()
    if len(w) >= 5:
        return f"at x {w[0]:.0f}, y {w[1]:.0f}, z {w[2]:.0f} mm, yaw {math.degrees(w[3]):.0f}°, elbow {int(w[4]):+d}"
    return "somewhere in the grid"


def _finer(cfg: CellConfig, factor: float) -> Any:
    """``[correction]`` with the x, y and yaw steps shrunk by ``factor`` (each range a whole number
    of steps, the yaw step a divisor of 360°); z is left (the correction is near linear along it)."""
    c = cfg.correction

    def axis(v: tuple[float, float, float]) -> tuple[float, float, float]:
        lo, hi, step = (float(x) for x in v)
        n = max(1, math.ceil((hi - lo) / (step * factor) - 1e-9))
        return (lo, hi, (hi - lo) / n)

    divisors = [360.0 / k for k in range(1, 361) if 3600 % k == 0]
    yaw = max((d for d in divisors if d <= c.yaw_step_deg * factor + 1e-9), default=1.0)
    return dataclasses.replace(c, x_mm=axis(c.x_mm), y_mm=axis(c.y_mm), yaw_step_deg=yaw)


def _suggest(cfg: CellConfig, params: np.ndarray, bound: float) -> str:
    """The finer grid that meets the limit for ``params`` (tried, up to three refinements)."""
    limit = cfg.correction.max_interpolation_um
    factor = 1.0
    for _ in range(3):
        factor *= 0.9 * math.sqrt(limit / bound)
        corr = _finer(cfg, factor)
        try:
            b = _table(cfg, params, corr).interpolation_bound_um
        except ConfigError as exc:  # the finer grid is over the controller's capacity
            return (f"a grid fine enough (x, y and yaw steps about {factor:.2f}× the present ones) holds too many "
                    f"values ({exc}): narrow the grid's ranges to where the robot works, then refine its steps")
        if b <= limit:
            return (f"steps of x {corr.x_mm[2]:.4g} mm, y {corr.y_mm[2]:.4g} mm and yaw {corr.yaw_step_deg:g}° "
                    f"(correction.x_mm = [{corr.x_mm[0]:g}, {corr.x_mm[1]:g}, {corr.x_mm[2]:.4g}], correction.y_mm = "
                    f"[{corr.y_mm[0]:g}, {corr.y_mm[1]:g}, {corr.y_mm[2]:.4g}], correction.yaw_step_deg = "
                    f"{corr.yaw_step_deg:g}) give {b:.1f} µm")
        bound = b
    return "a finer grid (smaller x, y and yaw steps) or narrower ranges"


#: bounds already computed in this process, by robot, grid and error sizes: the same inputs give
#: the same bounds, and a rehearsal or a test suite starts the same cell again and again
_BOUNDS: dict[tuple[Any, ...], tuple[float, ...]] = {}


def _bounds(cfg: CellConfig) -> tuple[float, ...]:
    m = cfg.model
    sizes = tuple(_sim(cfg, k, d) for k, d in (("length_sigma_um", 40.0), ("angle_sigma_arcsec", 150.0),
                                               ("offset_sigma_arcsec", -1.0), ("tilt_sigma_arcsec", -1.0)))
    key = (m.name, tuple(m.joint_types), np.asarray(m.nominal, dtype=float).tobytes(), repr(cfg.correction),
           tuple(cfg.plan.elbows), sizes)
    if key not in _BOUNDS:
        _BOUNDS[key] = tuple(float(_table(cfg, p).interpolation_bound_um) for p in expected_errors(cfg))
    return _BOUNDS[key]


def check_grid(cfg: CellConfig) -> GridCheck | None:
    """Check the configured grid before the first motion; None for a robot without a table.

    Raises :class:`GridTooCoarse` when every seeded robot with the expected error size exceeds
    ``correction.max_interpolation_um``."""
    if not cfg.model.is_scara:
        return None
    limit = float(cfg.correction.max_interpolation_um)
    bounds = _bounds(cfg)
    if all(b > limit for b in bounds):
        k = int(np.argsort(bounds)[len(bounds) // 2])  # the median robot: the typical one
        tables = [_table(cfg, p) for p in expected_errors(cfg)]
        hint = _suggest(cfg, expected_errors(cfg)[k], bounds[k])
        length = _sim(cfg, "length_sigma_um", 40.0)
        angle = _sim(cfg, "angle_sigma_arcsec", 150.0)
        raise GridTooCoarse(
            f"before the first motion: for robot errors of the size [simulation] states (lengths σ {length:g} µm, "
            f"angles σ {angle:g}″), the correction grid interpolates with {min(bounds):.1f}–{max(bounds):.1f} µm over "
            f"{len(bounds)} seeded robots, above correction.max_interpolation_um = {limit:g} for every one; the "
            f"typical one reaches {bounds[k]:.1f} µm {_where(tables[k])}; for it, {hint}. Nothing was measured")
    return GridCheck(bounds, limit)
