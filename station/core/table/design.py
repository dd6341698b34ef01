"""The correction table's design: the region it covers, the steps of its grid, its predicted bound.

The controller interpolates the table multilinearly over a grid with one uniform step per axis
(x, y, z [mm], yaw periodic over a full turn; :mod:`station.core.table.grid`). Its wire format
carries one start, step and count per axis, no list of nodes, so a grid that is finer where the
correction bends would need a new table format, a new interpolation rule in every robot program
and in the simulator: instead the station chooses the region and each axis's step. The region is
what the cell commands (the verification targets, the tools' working poses, with margins for the
set-up's uncertainty and the re-centring) and nothing more, so the grid stays away from the
stretched and the folded arm where the correction bends most; the steps are chosen per axis
where the correction bends along that axis.

How the steps are chosen. The linear interpolation of a smooth function over a step ``h`` errs
by at most ``h² · |f''| / 8`` (at the edge midpoint), and the multilinear interpolation of a cell
by at most the sum of its axes' errors (the tensor product). So for every sampled robot, every
elbow and the points of a lattice over the region, :func:`curvature` measures per axis ``k``
the position error ``a_k`` [µm] that a unit step leaves (µm per mm², per rad² for yaw): the
second difference of the exact joint correction along the axis, mapped through the robot's
Jacobian. A grid with steps ``h`` then leaves about ``max over the lattice of Σ_k a_k h_k²``.
:func:`design_table` grows the node counts one at a time, each time on the axis that lowers this
estimate most per value added, until it meets the bound with a margin, then builds the sampled
robots' tables on the chosen grid (the same :func:`build_correction_table` the run uses after
measuring) and refines again while any of them misses the bound.

The robots are samples with the errors a robot of this kind has before calibration (the
configured error sizes, :func:`prior_robots`), never a simulation's true robot: the design is
made before anything moves. After identification, :func:`refine_for` checks the identified
robot's table on the designed grid and refines the grid for that robot where it misses.

Error terms beyond geometry (issue 30: gear harmonics, compliance) are identified from the run's
data, so the sampled robots before motion carry none: no configured prior of their size exists,
and the predicted bound is the geometric robots'. A harmonic of the joint angle bends the
correction little (tests/core/test_correction_table.py: 20″ on joints 1 and 2 move a coarse grid's
bound from 8.7 to 8.8 µm); one of a motor angle (``[gears] ratios``) cycles r times per joint
turn, and the identified table's bound shows what its grid leaves of it.
The identified robot's table carries them where the session fitted them: :func:`refine_for` with
``delta`` builds and bounds it, and samples its curvature, on the robot standing at ``q + δ(q)``
(:mod:`station.core.table.build`).

Pure numerics: arrays in, frozen dataclasses out; mm and rad inside, µm in reported bounds.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from station.core.kinematics.forward import forward
from station.core.kinematics.model import RobotModel
from station.core.table.build import (
    CorrectionTable,
    _delta,
    _ik_masked,
    _stands,
    _targets,
    build_correction_table,
    node_joints,
)
from station.core.table.grid import GridSpec
from station.core.terms.compensation import JointDelta
from station.core.units import TWO_PI
from station.errors import ConfigError

__all__ = ["Region", "Curvature", "TableDesign", "prior_robots", "curvature", "design_table", "refine_for",
           "YAW_COUNTS", "AXES"]

#: the grid's axes, in the table's order
AXES = ("x", "y", "z", "yaw")
#: yaw node counts a design chooses from: those whose step is a multiple of 0.5° (it is written
#: to a configuration as a whole number of tenths of a degree)
YAW_COUNTS = tuple(k for k in range(2, 361) if 720 % k == 0)
#: the design aims this far below the bound before it builds the sampled robots' tables
DESIGN_MARGIN = 0.9
#: an estimate this many times the bound at the controller's capacity: no grid can meet it (the
#: estimate overshoots the built tables' bound by some 5–20 %), so no table is built to show it
HOPELESS = 1.5
#: seed of the sampled robots (fixed: the same cell gets the same design)
PRIOR_SEED = 20240618
#: random samples of each built table's own check (the per-cell edge bound covers every cell)
N_CHECK = 200


@dataclass(frozen=True, eq=False)
class Region:
    """A box of TCP targets in the robot base frame: ``x_mm``, ``y_mm``, ``z_mm`` = (low, high)
    [mm], yaw the full turn, ``elbows`` the configurations the table carries ((1, -1) or (1,)).

    ``working``: ``(m, 3)`` the targets the cell commands [mm] and ``margin_mm`` ``(3,)`` the
    distance along x, y, z [mm] around each within which it may command (set-up uncertainty, re-centring): the bound is
    guaranteed over the grid cells these boxes touch, at every yaw (None: over the whole box, as
    for a region the user names). The box's far corners can lie near the stretched arm, where
    the correction bends most, and nothing is commanded there."""

    x_mm: tuple[float, float]
    y_mm: tuple[float, float]
    z_mm: tuple[float, float]
    elbows: tuple[int, ...] = (1, -1)
    working: np.ndarray | None = None
    margin_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        for name in ("x_mm", "y_mm", "z_mm"):
            lo, hi = (float(v) for v in getattr(self, name))
            if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
                raise ConfigError(f"correction region {name} = [{lo:g}, {hi:g}]: give [low, high] in mm, low ≤ high")
            object.__setattr__(self, name, (lo, hi))
        object.__setattr__(self, "elbows", tuple(int(e) for e in self.elbows))
        if self.working is not None:
            w = np.array(self.working, dtype=float).reshape(-1, 3)
            w.setflags(write=False)
            object.__setattr__(self, "working", w)
        m = np.broadcast_to(np.asarray(self.margin_mm, dtype=float), (3,))
        object.__setattr__(self, "margin_mm", (float(m[0]), float(m[1]), float(m[2])))

    @classmethod
    def around(cls, points: np.ndarray, margin_mm: float | Sequence[float], elbows: tuple[int, ...] = (1, -1),
               round_mm: float = 1.0) -> "Region":
        """The smallest box holding ``points`` ``(m, ≥3)`` (x, y, z [mm]) grown by ``margin_mm``
        (one value, or one per axis x, y, z) on every side, its faces rounded outwards to whole
        ``round_mm``."""
        p = np.asarray(points, dtype=float).reshape(-1, np.shape(points)[-1])[:, :3]
        if p.size == 0 or not np.all(np.isfinite(p)):
            raise ConfigError("the correction region needs at least one finite target")
        m = np.broadcast_to(np.asarray(margin_mm, dtype=float), (3,))
        lo = np.floor((p.min(axis=0) - m) / round_mm) * round_mm
        hi = np.ceil((p.max(axis=0) + m) / round_mm) * round_mm
        return cls((lo[0], hi[0]), (lo[1], hi[1]), (lo[2], hi[2]), elbows, p, (float(m[0]), float(m[1]), float(m[2])))

    @property
    def lows(self) -> np.ndarray:
        return np.array([self.x_mm[0], self.y_mm[0], self.z_mm[0]])

    @property
    def highs(self) -> np.ndarray:
        return np.array([self.x_mm[1], self.y_mm[1], self.z_mm[1]])

    @property
    def spans(self) -> np.ndarray:
        """(3,) x, y, z extent [mm]."""
        return self.highs - self.lows

    def scaled(self, factor: float) -> "Region":
        """The box scaled by ``factor`` about its centre in x and y (z kept)."""
        c, h = 0.5 * (self.lows + self.highs), 0.5 * self.spans * factor
        w = None
        if self.working is not None:
            w = self.working.copy()
            w[:, :2] = c[:2] + (w[:, :2] - c[:2]) * factor
        return Region((c[0] - h[0], c[0] + h[0]), (c[1] - h[1], c[1] + h[1]), self.z_mm, self.elbows, w,
                      self.margin_mm)

    def samples(self, lattice: tuple[int, int, int], centres: bool = False) -> np.ndarray:
        """``(m, 3)`` points where the correction's curvature is sampled: each working target's
        box (its corners, face and edge centres and centre; ``centres``: the targets only), else
        a lattice over the whole box."""
        if self.working is not None and centres:
            return self.working.copy()
        if self.working is not None:
            o = np.array(np.meshgrid(*([(-1.0, 0.0, 1.0)] * 3), indexing="ij")).reshape(3, -1).T * np.array(self.margin_mm)
            pts = (self.working[:, None, :] + o[None]).reshape(-1, 3)
            return np.clip(pts, self.lows, self.highs)
        axes = [np.linspace(lo, hi, n if hi > lo else 1) for (lo, hi), n in
                zip((self.x_mm, self.y_mm, self.z_mm), lattice)]
        return np.stack([g.ravel() for g in np.meshgrid(*axes, indexing="ij")], axis=-1)

    def working_cells(self, table: CorrectionTable) -> np.ndarray:
        """``(n_configs, *cells)`` bool: the cells of ``table`` the bound must hold in (those the
        working targets' boxes touch, at every yaw; every cell without working targets)."""
        cb = table.cell_bound_um
        assert cb is not None
        if self.working is None:
            return np.ones(cb.shape, dtype=bool)
        mask = np.zeros(cb.shape, dtype=bool)
        axes = table.data.axes
        for q in self.working:
            idx: list[slice] = []
            for k in range(3):
                a, nc = axes[k], cb.shape[k + 1]
                m = self.margin_mm[k]
                i0, i1 = (int(np.clip(np.floor((v - a.start) / a.step), 0, nc - 1)) for v in (q[k] - m, q[k] + m))
                idx.append(slice(i0, i1 + 1))
            mask[(slice(None), *idx, slice(None))] = True
        return mask

    def bound_um(self, table: CorrectionTable) -> float:
        """The table's interpolation bound [µm] over the working cells (inf where one of them has a
        node the robot cannot reach: a working target's correction is then not interpolated)."""
        cb = table.cell_bound_um
        if cb is None:
            return float(table.interpolation_bound_um)
        vals = np.where(np.isnan(cb), np.inf, cb)[self.working_cells(table)]
        return float(vals.max()) if vals.size else math.nan

    def outside(self, points: np.ndarray) -> np.ndarray:
        """``(m, 3)`` how far [mm] each point lies outside the box along x, y, z (signed: negative
        below the low face, positive above the high face, 0 inside)."""
        p = np.asarray(points, dtype=float).reshape(-1, np.shape(points)[-1])[:, :3]
        return np.where(p < self.lows, p - self.lows, np.where(p > self.highs, p - self.highs, 0.0))

    def grid(self, counts: Sequence[int]) -> GridSpec:
        """The grid over this box with ``counts`` = (nx, ny, nz, n_yaw) nodes (one node on an axis
        of zero extent; n_yaw ≥ 2 over the full turn)."""
        nx, ny, nz, nyaw = (int(n) for n in counts)
        kw: dict[str, object] = {}
        for name, (lo, hi), n in zip("xyz", (self.x_mm, self.y_mm, self.z_mm), (nx, ny, nz)):
            kw[f"{name}_range"] = (lo, hi)
            kw[f"{name}_step"] = (hi - lo) / (n - 1) if n > 1 and hi > lo else 1.0
        return GridSpec(yaw_step=TWO_PI / nyaw, elbows=self.elbows, **kw)  # type: ignore[arg-type]


def prior_robots(model: RobotModel, n: int, *, length_sigma_mm: float, offset_sigma_rad: float,
                 tilt_sigma_rad: float, angle_sigma_rad: float, seed: int = PRIOR_SEED) -> list[np.ndarray]:
    """``n`` seeded parameter vectors ``(n_params,)`` of robots with errors of the given sizes
    about ``model.nominal``: every length σ ``length_sigma_mm``, roll and pitch of every
    transform σ ``tilt_sigma_rad``, the yaw σ ``angle_sigma_rad`` (a revolute joint's yaw is its
    encoder offset: σ ``offset_sigma_rad``). The set-up (the first six) stays nominal: the table
    never uses it."""
    n_t = model.n_params // 6
    sigma = np.zeros((n_t, 6))
    sigma[1:, :3] = length_sigma_mm
    sigma[1:, 3:5] = tilt_sigma_rad
    sigma[1:, 5] = angle_sigma_rad
    for t, kind in zip(model.joint_transforms, model.joint_types):
        if kind == "revolute":
            sigma[t, 5] = offset_sigma_rad
    rng = np.random.default_rng(seed)
    nominal = np.asarray(model.nominal, dtype=float)
    return [nominal + (rng.standard_normal((n_t, 6)) * sigma).ravel() for _ in range(n)]


@dataclass(frozen=True)
class Curvature:
    """Per lattice point (of every sampled robot and elbow), per axis x, y, z, yaw: the position
    error ``coeff`` ``(m, 4)`` [µm per mm², per rad² for yaw] that linear interpolation leaves
    over a unit step: a grid with steps ``h`` (4,) leaves about ``max(coeff @ h²)`` µm."""

    coeff: np.ndarray

    def estimate(self, steps: Sequence[float] | np.ndarray) -> float:
        """The estimated bound [µm] of a grid with ``steps`` (x, y, z [mm], yaw [rad])."""
        if self.coeff.size == 0:
            return 0.0
        h2 = np.asarray(steps, dtype=float) ** 2
        return float(np.max(self.coeff @ h2))


def curvature(model: RobotModel, robots: Sequence[np.ndarray], region: Region,
              lattice: tuple[int, int, int, int] = (9, 9, 2, 12), probe: tuple[float, float] = (8.0, 0.15),
              centres: bool = False, delta: JointDelta | None = None) -> Curvature:
    """Sample the correction's curvature over ``region`` for each robot of ``robots`` (parameter
    vectors of ``model``). ``lattice``: points per axis (x, y, z, yaw; x, y, z without working
    targets); ``probe``: the second difference's step (mm for x, y, z, capped at a quarter of the
    axis's extent; rad for yaw); ``centres``: at the working targets only, not their boxes (a
    cheap look at many robots). Points where a robot or the nominal model cannot reach a probe
    are left out. ``delta``: joint errors beyond geometry the robots stand with (``q + δ(q)``; the
    identified robot's terms, :func:`refine_for`): the correction is then the joints at which that
    robot reaches the targets (:func:`station.core.table.build.node_joints`)."""
    xyz = region.samples((lattice[0], lattice[1], lattice[2]), centres)
    yaw = np.linspace(-math.pi, math.pi, lattice[3], endpoint=False)
    P = np.concatenate([np.repeat(xyz, len(yaw), axis=0), np.tile(yaw, len(xyz))[:, None]], axis=1)
    spans = np.append(region.spans, TWO_PI)
    steps = np.array([min(probe[0], 0.25 * s) if s > 0 else 0.0 for s in spans[:3]] + [probe[1]])
    live = [k for k in range(4) if steps[k] > 0]
    # every probe point: the centre, then centre ∓ step along each live axis
    probes = [P] + [P + sgn * steps[k] * np.eye(4)[k] for k in live for sgn in (-1.0, 1.0)]
    Q = np.concatenate(probes)
    T = _targets(Q)
    m = P.shape[0]
    rows: list[np.ndarray] = []
    nominal = {elbow: _ik_masked(model, model.nominal, T, elbow) for elbow in region.elbows}
    for params in robots:  # rows: robot by robot, each robot's elbows together
        for elbow in region.elbows:
            q_nom, ok_nom = nominal[elbow]
            q_id, ok_id = node_joints(model, params, T, elbow, delta)
            ok = ok_nom & ok_id
            d = np.where(ok[:, None], _delta(model, np.nan_to_num(q_id), np.nan_to_num(q_nom)), np.nan)
            centre, q0 = d[:m], q_id[:m]
            coeff = np.zeros((m, 4))
            for i, k in enumerate(live):
                lo, hi = d[m * (1 + 2 * i):m * (2 + 2 * i)], d[m * (2 + 2 * i):m * (3 + 2 * i)]
                second = (lo - 2.0 * centre + hi) / 8.0  # the midpoint error of a step equal to the probe's
                good = np.all(np.isfinite(second), axis=1) & np.all(np.isfinite(q0), axis=1)
                if not good.any():
                    continue
                base = forward(model, _stands(q0[good], delta), params, setup=False)[:, :3, 3]
                moved = forward(model, _stands(q0[good] + second[good], delta), params, setup=False)[:, :3, 3]
                coeff[good, k] = np.linalg.norm(moved - base, axis=1) * 1000.0 / steps[k] ** 2
            rows.append(coeff)
    return Curvature(np.concatenate(rows) if rows else np.zeros((0, 4)))


@dataclass(frozen=True)
class TableDesign:
    """A designed correction grid and what is known about it before the robot moves.

    ``grid``: the grid (the region's box, one uniform step per axis). ``counts``: nodes
    (x, y, z, yaw). ``n_values``: values it holds (elbows × nodes × joints) against the
    controller's ``capacity``. ``bounds_um``: the interpolation bound of each sampled robot's
    table on this grid (built as the run builds it). ``predicted_bound_um``: the bound a typical
    robot's table has: the median over many more sampled robots of the curvature estimate at the
    working targets, scaled by the built tables' bound over that estimate (their median ratio);
    without them, the built bounds' median. ``feasible``: every sampled robot's table meets
    ``limit_um`` within the capacity. When not: ``best_bound_um`` is the bound the finest grid
    within the capacity reaches (the estimate, median robot), and ``region_scale`` the factor
    on the region's x and y extent with which a grid within capacity meets the limit (None when
    none does down to a tenth).
    """

    grid: GridSpec
    region: Region
    counts: tuple[int, int, int, int]
    n_values: int
    capacity: int
    limit_um: float
    bounds_um: tuple[float, ...]
    estimate_um: float
    feasible: bool
    best_bound_um: float = math.nan
    region_scale: float | None = None
    predicted_um: float = math.nan
    frozen: tuple[int, ...] = ()  # axes whose node count the configuration fixed (never refined)

    @property
    def predicted_bound_um(self) -> float:
        if math.isfinite(self.predicted_um):
            return self.predicted_um
        b = [v for v in self.bounds_um if math.isfinite(v)]
        return float(np.median(b)) if b else math.nan

    @property
    def worst_bound_um(self) -> float:
        b = [v for v in self.bounds_um if math.isfinite(v)]
        return float(max(b)) if b else math.nan

    @property
    def steps(self) -> tuple[float, float, float, float]:
        """Steps x, y, z [mm] (0 on an axis with one node) and yaw [deg]."""
        g = self.grid
        n = self.counts
        return (g.x_step if n[0] > 1 else 0.0, g.y_step if n[1] > 1 else 0.0, g.z_step if n[2] > 1 else 0.0,
                360.0 / n[3])

    def describe(self) -> str:
        """One line: the grid, its size against the capacity and its predicted bound."""
        r, (sx, sy, sz, syaw) = self.region, self.steps
        axes = [f"x {r.x_mm[0]:g} … {r.x_mm[1]:g} mm step {sx:.4g}", f"y {r.y_mm[0]:g} … {r.y_mm[1]:g} mm step {sy:.4g}",
                f"z {r.z_mm[0]:g} … {r.z_mm[1]:g} mm" + (f" step {sz:.4g}" if sz else " (one node)"),
                f"yaw step {syaw:g}°"]
        return (f"{'×'.join(map(str, self.counts))} nodes × {len(r.elbows)} elbows ({'; '.join(axes)}): "
                f"{self.n_values} of the controller's {self.capacity} values; predicted bound "
                f"{self.predicted_bound_um:.1f} µm (sampled robots {min(self.bounds_um, default=math.nan):.1f}–"
                f"{self.worst_bound_um:.1f} µm) against {self.limit_um:g} µm")


def _n_values(counts: Sequence[int], n_elbows: int, n_joints: int) -> int:
    return int(n_elbows * n_joints * np.prod(counts))


def _steps(region: Region, counts: Sequence[int]) -> np.ndarray:
    s = region.spans
    return np.array([s[k] / (counts[k] - 1) if counts[k] > 1 else 0.0 for k in range(3)] + [TWO_PI / counts[3]])


def _grow(curv: Curvature, region: Region, counts: list[int], target_um: float, n_joints: int,
          capacity: int, frozen: frozenset[int] = frozenset()) -> tuple[list[int], float]:
    """Add nodes, one axis at a time, the axis whose next node lowers the estimate most per value
    added, until the estimate meets ``target_um`` or no axis can grow within ``capacity``
    (the axes in ``frozen`` keep their counts)."""
    n_el = len(region.elbows)
    est = curv.estimate(_steps(region, counts))
    while est > target_um:
        best: tuple[float, list[int], float] | None = None
        for k in range(4):
            if (k < 3 and region.spans[k] <= 0) or k in frozen:
                continue
            trial = list(counts)
            if k < 3:
                trial[k] += 1
            else:
                bigger = [c for c in YAW_COUNTS if c > counts[3]]
                if not bigger:
                    continue
                trial[3] = bigger[0]
            if _n_values(trial, n_el, n_joints) > capacity:
                continue
            e = curv.estimate(_steps(region, trial))
            gain = (est - e) / math.log(np.prod(trial) / np.prod(counts))
            if best is None or gain > best[0]:
                best = (gain, trial, e)
        if best is None or best[0] <= 0.0:
            break
        counts, est = best[1], best[2]
    return counts, est


def _start_counts(region: Region, fixed: Mapping[int, int] | None = None) -> list[int]:
    start = [2 if region.spans[k] > 0 else 1 for k in range(3)] + [4]
    for k, n in (fixed or {}).items():
        start[k] = int(n)
    return start


def _table_bound(model: RobotModel, params: np.ndarray, region: Region, counts: Sequence[int]) -> float:
    return region.bound_um(build_correction_table(model, params, region.grid(counts), n_check=N_CHECK))


def _scale_that_fits(curv_of, region: Region, limit_um: float, n_joints: int, capacity: int) -> float | None:
    """The largest factor (0.1 … 1, two digits) on the region's x, y extent with which a grid
    within capacity meets ``limit_um`` by the estimate; ``curv_of(region)`` samples a region."""
    lo, hi = 0.1, 1.0
    c = curv_of(region.scaled(lo))
    if _grow(c, region.scaled(lo), _start_counts(region), DESIGN_MARGIN * limit_um, n_joints, capacity)[1] \
            > DESIGN_MARGIN * limit_um:
        return None
    for _ in range(6):
        mid = 0.5 * (lo + hi)
        r = region.scaled(mid)
        est = _grow(curv_of(r), r, _start_counts(r), DESIGN_MARGIN * limit_um, n_joints, capacity)[1]
        lo, hi = (mid, hi) if est <= DESIGN_MARGIN * limit_um else (lo, mid)
    return math.floor(lo * 100) / 100


def design_table(model: RobotModel, robots: Sequence[np.ndarray], region: Region, limit_um: float, *,
                 capacity: int, counts: Sequence[int] | None = None, fixed: Mapping[int, int] | None = None,
                 rounds: int = 4, more: Sequence[np.ndarray] = ()) -> TableDesign:
    """Design the grid over ``region`` whose tables meet ``limit_um`` [µm] for every robot of
    ``robots`` (``(n_params,)`` parameter vectors of ``model``, the controller's nominal model),
    within ``capacity`` values. ``counts`` (x, y, z, yaw nodes) fixes the grid instead (a
    configured override): it is then only checked; ``fixed`` {axis: count} fixes some axes' nodes
    (axis 0 … 3: x, y, z, yaw) and designs the others.
    Builds each robot's table on the final grid (a few seconds for ten robots). ``more``: further
    sampled robots for the predicted bound only (see :class:`TableDesign`)."""
    if not model.is_scara:
        raise ConfigError(f"robot {model.name!r} is not a SCARA: it takes compensated targets, not a table")
    if not robots:
        raise ValueError("design_table needs at least one sampled robot")
    g = model.n_joints
    n_el = len(region.elbows)
    curv = curvature(model, robots, region)
    given = counts is not None  # a configured grid: only checked
    cur = [int(c) for c in counts] if counts is not None else _start_counts(region, fixed)
    frozen = frozenset(fixed or {})
    target = DESIGN_MARGIN * limit_um
    bounds: tuple[float, ...] = ()
    est = curv.estimate(_steps(region, cur))
    for _ in range(rounds):
        before = list(cur)
        if not given:
            cur, est = _grow(curv, region, cur, target, g, capacity, frozen)
        if _n_values(cur, n_el, g) > capacity:
            break
        if bounds and cur == before:  # full: no grid within the capacity does better
            break
        if not given and est > HOPELESS * limit_um:  # the finest grid within the capacity is far off: no builds
            break
        bounds = tuple(_table_bound(model, p, region, cur) for p in robots)
        worst = max((b for b in bounds if math.isfinite(b)), default=math.nan)
        if given or not worst > limit_um:
            break
        target *= 0.95 * limit_um / worst  # the estimate missed these robots: aim lower
    n_values = _n_values(cur, n_el, g)
    worst = max((b for b in bounds if math.isfinite(b)), default=math.nan)
    feasible = n_values <= capacity and bool(bounds) and not worst > limit_um
    best, scale = math.nan, None
    if not feasible:
        # what a grid within capacity can reach, and the region with which it meets the limit
        best_counts, _ = _grow(curv, region, _start_counts(region, fixed), 0.0, g, capacity, frozen)
        per_robot = [Curvature(c) for c in np.split(curv.coeff, len(robots))]
        ests = [c.estimate(_steps(region, best_counts)) for c in per_robot]
        best = float(np.median(ests))
        if not given:  # the region's scale from the estimate of the two robots that bend most (~7 regions)
            few = [robots[int(i)] for i in np.argsort(ests)[::-1][:2]]
            scale = _scale_that_fits(lambda r: curvature(model, few, r), region, limit_um, g, capacity)
    grid = region.grid(cur) if n_values <= capacity else region.grid(_start_counts(region))
    predicted = _predicted(model, robots, more, region, cur, bounds) if bounds else math.nan
    return TableDesign(grid, region, (cur[0], cur[1], cur[2], cur[3]), n_values, capacity, float(limit_um), bounds,
                       float(est), feasible, float(best), scale, predicted, tuple(sorted(frozen)))


def _predicted(model: RobotModel, built: Sequence[np.ndarray], more: Sequence[np.ndarray], region: Region,
               counts: Sequence[int], bounds: Sequence[float]) -> float:
    """The median bound over ``built`` and ``more`` robots: each robot's curvature estimate at the
    working targets, scaled by the median of built bound / estimate."""
    h = _steps(region, counts)
    allr = list(built) + list(more)
    per = np.split(curvature(model, allr, region, centres=True).coeff, len(allr))
    est = np.array([Curvature(c).estimate(h) for c in per])
    ok = np.isfinite(bounds) & (est[:len(built)] > 0)
    if not ok.any():
        return float(np.median([b for b in bounds if math.isfinite(b)])) if any(map(math.isfinite, bounds)) else math.nan
    scale = float(np.median(np.asarray(bounds)[ok] / est[:len(built)][ok]))
    return float(np.median(est) * scale)


def refine_for(model: RobotModel, params: np.ndarray, design: TableDesign, *,
               rounds: int = 3, delta: JointDelta | None = None) -> tuple[CorrectionTable, TableDesign, float]:
    """The identified robot's table: on the designed grid, refined (more nodes on the axes where
    this robot's correction bends) while its bound over the region's working cells misses the
    design's limit and the capacity allows. Returns the table, the design it was built on and
    that bound [µm]; the caller judges it against the limit. ``delta``: the identified error
    terms' joint error ``q ↦ δ(q)`` (see the module): the tables are built, bounded and refined
    with them."""
    limit, region = design.limit_um, design.region
    table = build_correction_table(model, params, design.grid, delta=delta)
    bound = region.bound_um(table)
    if not bound > limit:
        return table, design, bound
    g, n_el = model.n_joints, len(region.elbows)
    curv = curvature(model, [params], region, delta=delta)
    cur, target = list(design.counts), DESIGN_MARGIN * limit
    for _ in range(rounds):
        grown, est = _grow(curv, region, cur, target, g, design.capacity, frozenset(design.frozen))
        if grown == cur:
            break
        cur = grown
        trial = build_correction_table(model, params, region.grid(cur), delta=delta)
        b = region.bound_um(trial)
        if b < bound:
            table, bound = trial, b
            design = dataclasses.replace(design, grid=region.grid(cur), counts=(cur[0], cur[1], cur[2], cur[3]),
                                         n_values=_n_values(cur, n_el, g), estimate_um=est)
        if not bound > limit:
            break
        target *= 0.95 * limit / b if math.isfinite(b) else 0.5
    return table, design, bound
