"""The correction table a cell needs, designed before anything moves (issue 27).

The table covers what the cell commands through it: the plan's verification targets (Cartesian
moves with the table active), each with a margin for what moves it after the plan (the set-up
R is identified, so a target's base-frame position shifts by the set-up guess's error; a
re-centred touch moves the head onto the corner, by the robot's error). The grid's x, y, z are
the head frame's origin (MKKS, the point the probe head's CMM report names) in the robot base
frame, yaw its rotation about the base z axis. A ``[[tool]]`` gets its own design over its TCP
at the same joints (:func:`tool_grid_for`).

* No ``[correction]`` grid keys: the station derives the region (the box around the targets
  with their margins, or ``[correction] region`` where the user names it) and designs the steps
  (:func:`station.core.table.design.design_table`) for robots with errors of the configured
  size (``[simulation]``'s σ: the station's prior for an uncalibrated robot of this kind, never a
  simulation's true robot).
* ``x_mm`` / ``y_mm`` / ``z_mm`` (and ``yaw_step_deg``) given: that grid, checked the same way.

:func:`check_design` is the pre-motion check ``station plan`` and ``station calibrate`` share
(:func:`station.cell.correction.precheck.check_correction` adds the checked advice to its refusal):
every verification target inside the table (named by target, axis and key when not) and a table
within the controller's capacity that meets ``correction.max_interpolation_um`` (else the
numbers to change). :func:`identified_table` builds the identified robot's table on the design,
refined where that robot needs it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from drivers.controller_map import MAX_TABLE_VALUES
from station.cell.config.cell_config import DEFAULT_YAW_STEP_DEG, CellConfig
from station.cell.correction.design_cache import key_digest, load_design, store_design
from station.core.kinematics.tool_frame import nominal_head_in_flange
from station.core.kinematics.transforms import invert, pose_to_matrix
from station.core.table.build import CorrectionTable
from station.core.table.design import Region, TableDesign, design_table, prior_robots, refine_for
from station.core.table.grid import GridSpec
from station.core.units import ARCSEC, DEG
from station.errors import ConfigError

__all__ = ["CorrectionRefused", "WorkingTarget", "working_targets", "target_margin_mm", "region_for",
           "design_for", "check_design", "identified_table", "grid_to_json", "grid_from_json", "tool_grid_for",
           "worst_cell", "DRAWS", "GRID_POINT"]

#: robots with the expected error size the design is made and checked for (their tables built)
DRAWS = 8
#: robots in all whose curvature the predicted bound is the median of (a cheap look at each)
PREDICT_DRAWS = 64
#: how far [mm] a re-centred touch may move the head from its target, in x, y and in z: the robot's
#: error before correction (a few tenths of a mm for an industrial SCARA, far less along its quill)
RECENTRE_MM = (1.5, 0.25)
#: which point the grid's x, y, z describe, in the words the plan and the messages use
GRID_POINT = ("the head frame's origin (MKKS, as the probe head's CMM report gives it) in the robot base "
              "frame, yaw its rotation about the base z axis")


class CorrectionRefused(ConfigError):
    """No correction table as configured can serve the cell (a target outside it, or no grid
    within the controller's capacity meets the bound): found before anything moved (exit 2).

    A refusal that checked advice can answer (:meth:`found`) carries its parts: ``finding`` (what
    fails), ``way`` (what to change) and what the advice starts from, ``widened`` (targets outside
    the table: per axis the (lo, hi) [mm] that holds them all with their margins) or ``design`` (the
    design that misses the bound). Its message is the finding, the way, then "Nothing was measured"."""

    finding: str = ""
    way: str = ""
    widened: tuple[tuple[float, float], ...] | None = None
    design: TableDesign | None = None

    @classmethod
    def found(cls, finding: str, way: str, widened: tuple[tuple[float, float], ...] | None = None,
              design: TableDesign | None = None) -> CorrectionRefused:
        exc = cls(f"{finding}. {way}. Nothing was measured")
        exc.finding, exc.way, exc.widened, exc.design = finding, way, widened, design
        return exc

    def with_way(self, way: str) -> CorrectionRefused:
        """The same finding with another way out (the advice that passes the same check)."""
        return self.found(self.finding, way, self.widened, self.design)


@dataclass(frozen=True)
class WorkingTarget:
    """A pose the cell commands through the table: ``label`` ("C2.b elbow -1"), ``xyz`` (3,)
    [mm] and ``yaw`` [rad] of the head frame in the robot base frame (nominal set-up)."""

    label: str
    xyz: tuple[float, float, float]
    yaw: float
    elbow: int


def working_targets(cfg: CellConfig, verification: Any = None) -> tuple[WorkingTarget, ...]:
    """The plan's verification targets in the robot base frame of the nominal set-up
    (``verification``: the plan's held-out targets; None: the plan is built)."""
    if verification is None:
        from station.cell.plan.measurement_plan import build_plan

        verification = build_plan(cfg).verification
    R = invert(pose_to_matrix(cfg.model.nominal[:6]))
    out = []
    for t in verification:
        T = R @ t.head_world
        out.append(WorkingTarget(t.label, (float(T[0, 3]), float(T[1, 3]), float(T[2, 3])),
                                 float(math.atan2(T[1, 0], T[0, 0])), int(t.elbow)))
    return tuple(out)


def _sim(cfg: CellConfig, key: str, default: float | None) -> float | None:
    v = getattr(cfg.simulation, key, None) if cfg.simulation is not None else None
    return default if v is None else float(v)


def target_margin_mm(cfg: CellConfig, targets: tuple[WorkingTarget, ...]) -> tuple[float, float, float]:
    """How far [mm] along x, y, z a verification target may move from its planned base-frame
    position before the table interpolates it: 3 σ of the set-up guess's error (the targets are
    commanded in the identified base frame; ``[simulation]`` setup_sigma_mm, and its yaw (x, y)
    and tilt (z) at the targets' largest radius) plus what a re-centred touch moves the head
    (:data:`RECENTRE_MM`), rounded up to 0.5 mm."""
    r = max((math.hypot(*t.xyz[:2]) for t in targets), default=0.0)
    xyz = _sim(cfg, "setup_sigma_mm", 1.5) or 0.0
    yaw = (_sim(cfg, "setup_yaw_sigma_deg", 0.2) or 0.0) * DEG * r
    tilt = (_sim(cfg, "setup_tilt_sigma_deg", 0.03) or 0.0) * DEG * r
    xy = math.ceil(2.0 * (3.0 * math.hypot(xyz, yaw) + RECENTRE_MM[0])) / 2.0
    z = math.ceil(2.0 * (3.0 * math.hypot(xyz, tilt) + RECENTRE_MM[1])) / 2.0
    return xy, xy, z


def region_for(cfg: CellConfig, targets: tuple[WorkingTarget, ...] | None = None) -> Region:
    """The region the table covers: the configured grid's box (explicit grid), ``[correction]
    region``, or the box around the verification targets with their margins (derived)."""
    targets = working_targets(cfg) if targets is None else targets
    elbows = tuple(cfg.plan.elbows)
    pts = np.array([t.xyz for t in targets]).reshape(-1, 3)
    margin = target_margin_mm(cfg, targets)
    c = cfg.correction
    if c.x_mm is not None and c.y_mm is not None and c.z_mm is not None:  # judged where the cell commands
        return Region(c.x_mm[:2], c.y_mm[:2], c.z_mm[:2], elbows, pts if len(pts) else None, margin)
    region = c.region
    if region is not None:
        return Region(region[0], region[1], region[2], elbows)
    if not len(pts):
        raise CorrectionRefused("the plan holds no verification target: the correction has no region; "
                                "lower [plan] verification_every or name correction.region")
    return Region.around(pts, margin, elbows, round_mm=5.0)


def _counts(cfg: CellConfig) -> tuple[int, int, int, int] | None:
    c = cfg.correction
    if c.x_mm is None or c.y_mm is None or c.z_mm is None:
        return None
    n = [int(round((hi - lo) / step)) + 1 for lo, hi, step in (c.x_mm, c.y_mm, c.z_mm)]
    return n[0], n[1], n[2], int(round(360.0 / (c.yaw_step_deg or DEFAULT_YAW_STEP_DEG)))


def _prior(cfg: CellConfig, plan: Any = None, n: int = DRAWS) -> list[np.ndarray]:
    """The robots the design is made for: :data:`DRAWS` robots with errors of the configured size
    (``[simulation]``'s σ), each as the identification will see it: the plan's identification
    poses fit with the minimal parameter set (linearised, noise-free), so that what the minimal
    set holds at nominal or merges into the set-up (axis 1's tilts, for a SCARA) is where the
    identified robot has it. Without ``plan``: the full error vectors."""
    angle = _sim(cfg, "angle_sigma_arcsec", 150.0) or 0.0
    full = prior_robots(cfg.model, n, length_sigma_mm=(_sim(cfg, "length_sigma_um", 40.0) or 0.0) / 1000.0,
                        offset_sigma_rad=(_sim(cfg, "offset_sigma_arcsec", angle) or 0.0) * ARCSEC,
                        tilt_sigma_rad=(_sim(cfg, "tilt_sigma_arcsec", angle) or 0.0) * ARCSEC,
                        angle_sigma_rad=angle * ARCSEC)
    if plan is None:
        return full
    from station.cell.plan.steps import StepKind
    from station.core.identification.identifiability import analyze
    from station.core.measurement.measurements import residuals_and_jacobian, synthetic_set

    q = np.array([s.q for s in plan.identification if s.kind is StepKind.IDENTIFICATION])
    if not len(q):
        return full
    m, ident = cfg.model, cfg.identification
    data = synthetic_set(m, "pose", q, m.nominal, sigma=ident.pose_sigma())
    a = analyze(m, data, prefer=ident.prefer, fix=ident.fix, exclude=ident.exclude, describe=False)
    _, J = residuals_and_jacobian(m, data, m.nominal)
    Jw = J / data.sigma[:, None]
    idx = a.chosen_indices()
    nominal = np.asarray(m.nominal, dtype=float)
    out = []
    for p in full:
        dp = np.linalg.lstsq(Jw[:, idx], Jw @ (p - nominal), rcond=None)[0]
        seen = nominal.copy()
        seen[idx] += dp
        out.append(seen)
    return out


#: designs made in this process, by everything they depend on (a rehearsal or the suite starts
#: the same cell again and again; a design takes a few seconds); across processes they are kept
#: on disk by the same inputs and the code (:mod:`station.cell.correction.design_cache`)
_DESIGNS: dict[tuple[Any, ...], TableDesign] = {}


def design_for(cfg: CellConfig, plan: Any = None, capacity: int | None = None) -> TableDesign:
    """The cell's correction design (see the module; ``plan``: the cell's plan, built when not
    given); cached per process."""
    if plan is None:
        from station.cell.plan.measurement_plan import build_plan

        plan = build_plan(cfg)
    targets = working_targets(cfg, plan.verification)
    region = region_for(cfg, targets)
    cap = MAX_TABLE_VALUES if capacity is None else capacity
    counts = _counts(cfg)
    yaw = cfg.correction.yaw_step_deg
    fixed = None if counts is not None or yaw is None else {3: int(round(360.0 / yaw))}
    m = cfg.model
    key = (m.name, tuple(m.joint_types), np.asarray(m.nominal, dtype=float).tobytes(), region.x_mm, region.y_mm,
           region.z_mm, region.elbows, None if region.working is None else region.working.tobytes(),
           region.margin_mm, float(cfg.correction.max_interpolation_um), cap, counts, repr(fixed),
           tuple(_sim(cfg, k, None) for k in ("length_sigma_um", "angle_sigma_arcsec", "offset_sigma_arcsec",
                                              "tilt_sigma_arcsec")), cfg.identification,
           np.array([s.q for s in plan.identification]).tobytes())
    if key not in _DESIGNS:
        # on disk, the model's whole structure names it (two files may share a robot's name)
        digest = key_digest(key + (m.transforms, np.asarray(m.joint_limits, dtype=float).tobytes(),
                                   tuple(s.kind.value for s in plan.identification)))
        kept = load_design(digest)
        if kept is None:
            robots = _prior(cfg, plan, PREDICT_DRAWS)
            kept = design_table(m, robots[:DRAWS], region, float(cfg.correction.max_interpolation_um),
                                capacity=cap, counts=counts, fixed=fixed, more=robots[DRAWS:])
            store_design(digest, kept)
        _DESIGNS[key] = kept
    return _DESIGNS[key]


_AXIS_KEY = {"x": "x_mm", "y": "y_mm", "z": "z_mm"}


def _coverage(cfg: CellConfig, targets: tuple[WorkingTarget, ...], region: Region) -> None:
    """Refuse a verification target that (with its margin) leaves the table, named by target,
    axis, amount and key; the refusal carries the region that holds every target, from which
    :func:`station.cell.correction.advice.coverage_advice` seeks the ways out."""
    margin = target_margin_mm(cfg, targets)
    c = cfg.correction
    key = ("correction.x_mm / y_mm / z_mm" if c.explicit else "correction.region")
    problems = []
    lows, highs = [list(r) for r in zip(region.x_mm, region.y_mm, region.z_mm)]
    for t in targets:
        p = np.array(t.xyz)
        for k, axis in enumerate("xyz"):
            lo, hi = (region.x_mm, region.y_mm, region.z_mm)[k]
            m = margin[k]
            if p[k] - m < lo - 0.05 or p[k] + m > hi + 0.05:  # 0.05 mm: the margin's own rounding
                side, edge, need = (("below", lo, p[k] - m) if p[k] - m < lo else ("above", hi, p[k] + m))
                lows[k], highs[k] = min(lows[k], need), max(highs[k], need)
                which = f"correction.{_AXIS_KEY[axis]}" if c.explicit else f"correction.region {axis}_mm"
                problems.append(f"verification target {t.label}: {axis} = {p[k]:.1f} mm, with its {m:g} mm "
                                f"margin {need:.1f} mm, lies {abs(need - edge):.1f} mm {side} the table's {axis} "
                                f"range [{lo:g}, {hi:g}] mm ({which})")
    if problems:
        raise CorrectionRefused.found(
            f"before the first motion: {len(problems)} verification target{'s' if len(problems) > 1 else ''} "
            f"would leave the correction table ({GRID_POINT}; the margin covers the set-up guess's error, "
            f"[simulation] setup_sigma_*, and a re-centred touch): " + "; ".join(problems[:6])
            + ("; …" if len(problems) > 6 else ""),
            f"Change {key}, or remove it so that the station derives the region", widened=tuple(zip(lows, highs)))


def _infeasible(cfg: CellConfig, d: TableDesign) -> CorrectionRefused:
    """The refusal of a design that misses the bound; it carries the design, from which
    :func:`station.cell.correction.advice.advice_text` seeks the changes that pass the same check."""
    r = d.region
    limit = cfg.correction.max_interpolation_um
    what = ("the configured grid (correction.x_mm, y_mm, z_mm, yaw_step_deg) interpolates with "
            f"{min(d.bounds_um):.1f}–{d.worst_bound_um:.1f} µm over {len(d.bounds_um)} robots with errors of the "
            f"size [simulation] states" if _counts(cfg) is not None and d.n_values <= d.capacity else
            f"no correction grid within the controller's {d.capacity} values meets it for every one of "
            f"{len(d.bounds_um) or DRAWS} robots with errors of the size [simulation] states")
    return CorrectionRefused.found(
        f"before the first motion: {what}, above correction.max_interpolation_um = {limit:g} over the region "
        f"x {r.x_mm[0]:g} … {r.x_mm[1]:g}, y {r.y_mm[0]:g} … {r.y_mm[1]:g}, z {r.z_mm[0]:g} … {r.z_mm[1]:g} mm "
        f"({GRID_POINT})", "Change the bound, the region or the grid", design=d)


def check_design(cfg: CellConfig, plan: Any) -> TableDesign | None:
    """The correction's pre-motion check on ``plan`` without advice (the advice's own check of a
    changed file; ``station plan`` and ``station calibrate`` add the advice:
    :func:`station.cell.correction.precheck.check_correction`): the design, or None for a robot
    without a table. Raises :class:`CorrectionRefused` when a verification target leaves the table
    or no table meets the bound within the capacity."""
    if not cfg.model.is_scara:
        return None
    targets = working_targets(cfg, plan.verification)
    region = region_for(cfg, targets)
    if cfg.correction.explicit or cfg.correction.region is not None:
        _coverage(cfg, targets, region)
    d = design_for(cfg, plan)
    if not d.feasible:
        raise _infeasible(cfg, d)
    return d


def identified_table(cfg: CellConfig, params: np.ndarray, design: TableDesign,
                     delta: Any = None) -> tuple[CorrectionTable, TableDesign, float]:
    """The identified robot's table on ``design``, refined where it misses the bound: the table,
    the design it was built on and its bound over the region's working cells [µm]. ``delta``: the
    identified error terms' joint error ``q ↦ δ(q)`` (issue 30; None: geometric): the nodes, the
    bound and the refinement carry them (:func:`station.core.table.design.refine_for`)."""
    return refine_for(cfg.model, params, design, delta=delta)



def grid_to_json(grid: GridSpec) -> dict[str, Any]:
    """The grid as the run database stores it (the table of a run is rebuilt on it)."""
    return {"x_range": list(grid.x_range), "x_step": grid.x_step, "y_range": list(grid.y_range), "y_step": grid.y_step,
            "z_range": list(grid.z_range), "z_step": grid.z_step, "yaw_step": grid.yaw_step, "elbows": list(grid.elbows)}


def grid_from_json(d: dict[str, Any]) -> GridSpec:
    return GridSpec(x_range=tuple(d["x_range"]), x_step=d["x_step"], y_range=tuple(d["y_range"]),
                    y_step=d["y_step"], z_range=tuple(d["z_range"]), z_step=d["z_step"],
                    yaw_step=d["yaw_step"], elbows=tuple(d["elbows"]))


def head_in_flange(cfg: CellConfig) -> np.ndarray:
    """``H`` ``(4, 4)``: MKKS in the flange frame from the head's CMM report
    (``cfg.head_in_flange``); without one, the robot model's nominal K (the nominal flange is then
    the last joint frame, and the tools' TCPs are given in it)."""
    if cfg.head_in_flange is None:
        return nominal_head_in_flange(cfg.model)
    return np.asarray(cfg.head_in_flange, dtype=float)


def tool_grid_for(cfg: CellConfig, tool: Any) -> GridSpec:
    """A tool's grid. All of its x_mm / y_mm / z_mm given (or the head's grid configured): that
    grid, the head's on the axes the tool does not give. Else the station designs it as the
    head's: over the tool's working poses (its TCP at the plan's verification joints, with the
    same margins) for the sampled robots carrying the tool; an axis the tool gives keeps its
    range and step. Checked against the controller's capacity."""
    from station.cell.config.cell_config import correction_grid

    c = tool.correction
    if c.explicit:
        return correction_grid(c, tuple(cfg.plan.elbows))
    return _tool_design(cfg, tool).grid


def _tool_design(cfg: CellConfig, tool: Any) -> TableDesign:
    from station.cell.plan.measurement_plan import build_plan
    from station.core.kinematics.forward import forward
    from station.core.kinematics.tool_frame import tool_model, tool_params

    plan = build_plan(cfg)
    c = tool.correction
    H, T = head_in_flange(cfg), tool.tcp_matrix
    nominal = tool_model(cfg.model, H, T)
    q = np.array([t.joints for t in plan.verification]).reshape(-1, cfg.model.n_joints)
    heads = working_targets(cfg, plan.verification)
    margin = target_margin_mm(cfg, heads)
    pts = forward(nominal, q, setup=False)[:, :3, 3] if len(q) else np.zeros((0, 3))
    if not len(pts):
        raise CorrectionRefused(f"tool {tool.name!r}: the plan holds no verification target to design its table over")
    region = Region.around(pts, margin, tuple(cfg.plan.elbows), round_mm=5.0)
    fixed: dict[int, int] = {}
    ranges = [region.x_mm, region.y_mm, region.z_mm]
    for k, axis in enumerate("xyz"):
        own = getattr(c, f"{axis}_mm")  # the tool's own axis ([correction]'s are designed here)
        if own is not None:
            ranges[k] = (own[0], own[1])
            fixed[k] = int(round((own[1] - own[0]) / own[2])) + 1
    if c.yaw_step_deg is not None:
        fixed[3] = int(round(360.0 / c.yaw_step_deg))
    region = Region(ranges[0], ranges[1], ranges[2], region.elbows, pts, margin)
    cap = MAX_TABLE_VALUES
    key = ("tool", tool.name, np.asarray(tool.tcp, dtype=float).tobytes(), np.asarray(H).tobytes(),
           np.asarray(cfg.model.nominal, dtype=float).tobytes(), ranges[0], ranges[1], ranges[2], repr(fixed),
           float(c.max_interpolation_um), pts.tobytes())
    if key not in _DESIGNS:
        robots = [tool_params(cfg.model, p, H, T) for p in _prior(cfg, plan, PREDICT_DRAWS)]
        _DESIGNS[key] = design_table(nominal, robots[:DRAWS], region, float(c.max_interpolation_um), capacity=cap,
                                     fixed=fixed or None, more=robots[DRAWS:])
    return _DESIGNS[key]


def worst_cell(table: CorrectionTable, region: Region) -> str:
    """Where the table's bound over the region's working cells is reached: the cell's x, y, z, yaw
    ranges and elbow (robot base frame)."""
    cb = table.cell_bound_um
    if cb is None:
        return ""
    vals = np.where(np.isnan(cb), np.inf, cb)
    vals = np.where(region.working_cells(table), vals, -np.inf)
    idx = np.unravel_index(int(np.argmax(vals)), vals.shape)
    axes = table.data.axes
    lo = [a.start + a.step * i for a, i in zip(axes, idx[1:])]
    parts = [f"{n} {v:.0f} … {v + a.step:.0f} mm" for n, v, a in zip("xyz", lo[:3], axes[:3])]
    parts.append(f"yaw {math.degrees(lo[3]):.0f} … {math.degrees(lo[3] + axes[3].step):.0f}°")
    return f"in the cell {', '.join(parts)}, elbow {table.elbows[int(idx[0])]:+d} (robot base frame)"
