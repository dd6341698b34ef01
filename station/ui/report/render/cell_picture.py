"""A picture of the cell with the plan's poses (issue 40, "what people see"): the cell seen from
above (X–Y) and from the side (X–Z), in the robot's base frame, mm.

It shows what the collision check knows (:mod:`station.cell.plan.collision`, the same shapes:
:mod:`station.cell.plan.collision_shapes`): the body's cubes and their pillars, the cell's
``[[obstacle]]`` boxes and cylinders, the robot's base link, the arm (links and probe head) at the first touch of each pose family, every touch of the
plan (the head's nominal contact point, one marker per step, coloured by its family: a SCARA's
elbow, an arm's configuration code), the moves between consecutive poses (the contact point's track
along the joint-space move; the moves from or to a via pose apart) and the via poses, and the least
clearance: the pair's closest points where they come closest, the arm there, the figure and the
pair in the title. The views share one scale (docs/collision.md, "The picture of the cell").

``station plan CONFIG --out DIR`` writes it as ``cell.svg`` and ``cell.png``; the run's report embeds
the SVG. Explicit ``Figure`` objects on matplotlib's Agg canvas (no pyplot, no global backend). The
SVG is reproducible: a fixed hash salt for its ids, no date, text kept as text in DejaVu Sans
(matplotlib's own font), so a test reads it back and two writes of one plan are byte-identical.
"""

from __future__ import annotations

import io
import re
import textwrap
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from station.cell.config.cell_config import CellConfig
from station.cell.plan.assembly import Plan, nominal_contact
from station.cell.plan.collision import Clash, CollisionReport, check_path
from station.cell.plan.collision_shapes import CellShapes, Shape, cell_shapes, fcl_shape
from station.cell.plan.path_record import stored_path
from station.cell.plan.run_path import VIA_NAMES, plan_path
from station.cell.plan.steps import PlannedStep, StepKind
from station.core.kinematics.forward import chain_frames
from station.errors import ConfigError

__all__ = ["CellPicture", "SVG_NAME", "PNG_NAME", "cell_picture", "picture_poses", "plan_picture", "run_picture",
           "write_cell_picture", "check_picture_dir", "family_id"]

SVG_NAME = "cell.svg"
PNG_NAME = "cell.png"

#: the printed width [in] (A4 less the report's margins, as the report's plots) and the PNG's dpi
WIDTH_IN = 7.0
PNG_DPI = 110
#: the joint-space move between two poses is drawn as the contact point's track at this step [rad]
#: per sample (a touch's short moves stay one straight segment; a swing of 90° gets 9 samples)
TRACK_STEP_RAD = np.radians(10.0)
MAX_TRACK_SAMPLES = 24
#: samples of the move that holds the least clearance, to show where along it the pair comes closest
CLOSEST_SAMPLES = 64
#: the figure's fixed parts [in]: per line of the title above the top view (and the view's own
#: title), between the views (the top view's X label, the side view's title), the legend below
#: (with the side view's X label), the Y / Z labels on the left
LINE_IN, GAP_IN, LEGEND_IN, LEFT_IN, RIGHT_IN = 0.17, 0.7, 1.25, 0.7, 0.15
#: the tallest figure [in]: what an A4 page of the report leaves under the section's heading and
#: above the sign-off (170 mm), so that it prints at its own size and no text under 8 pt (issue 29)
MAX_HEIGHT_IN = 6.6
#: the views' margin around what they show [mm]
PAD_MM = 40.0
_FAMILY_COLOURS = ("tab:blue", "tab:red", "tab:green", "tab:purple", "tab:brown", "tab:pink", "tab:olive",
                   "tab:cyan")
#: one marker per family, so that two families touching the same corner both show (filled, open)
_FAMILY_MARKERS = (("o", 3.0, True), ("s", 5.0, False), ("D", 4.0, False), ("^", 5.5, False))


@dataclass(frozen=True)
class CellPicture:
    """The picture (``svg`` text, ``png`` bytes or None) and what it shows: ``touches`` markers per
    view (one per step), ``vias`` via poses, the pose families (step elbow codes), the least clearance."""

    svg: str
    png: bytes | None
    touches: int
    vias: int
    families: tuple[int, ...]
    least: Clash | None


def picture_poses(cfg: CellConfig, steps: Sequence[PlannedStep]) -> list[tuple[np.ndarray, str, int]]:
    """Every pose the run commands for ``steps`` (the vias included): the collision check's own
    sequence (:func:`station.cell.plan.run_path.plan_path`) of a plan holding exactly these steps (a
    stored run's plan: the report draws what the run did)."""
    return plan_path(cfg, Plan(tuple(steps), (), ()))


def _stadium(a: np.ndarray, b: np.ndarray, r: float, n: int = 10) -> np.ndarray:
    """The outline (k, 2) of a capsule's projection: the segment ``a``–``b`` (2,) grown by ``r``."""
    d = b - a
    t0 = float(np.arctan2(d[1], d[0])) if np.hypot(*d) > 1e-9 else 0.0
    t = np.linspace(-np.pi / 2, np.pi / 2, n)
    arc_b = b + r * np.column_stack([np.cos(t0 + t), np.sin(t0 + t)])
    arc_a = a + r * np.column_stack([np.cos(t0 + np.pi + t), np.sin(t0 + np.pi + t)])
    return np.vstack([arc_b, arc_a])


def _solid_outline(s: Shape, W: np.ndarray, axes: tuple[int, int]) -> np.ndarray:
    """The outline (k, 2) of a box's or a cylinder's projection onto the plane of ``axes``: the
    convex hull (scipy's qhull) of its corners or rims placed at ``W`` (4, 4)."""
    from scipy.spatial import ConvexHull

    if s.kind == "box":
        h = np.array(s.size) / 2
        local = np.array([[x, y, z] for x in (-h[0], h[0]) for y in (-h[1], h[1]) for z in (-h[2], h[2])])
    else:  # a cylinder: its two rims, 48 points each
        r, half = s.size[0], s.size[1] / 2
        t = np.linspace(0.0, 2 * np.pi, 48, endpoint=False)
        rim = np.column_stack([r * np.cos(t), r * np.sin(t)])
        local = np.vstack([np.column_stack([rim, np.full(48, z)]) for z in (-half, half)])
    pts = (local @ W[:3, :3].T + W[:3, 3])[:, axes]
    pts = np.unique(np.round(pts, 6), axis=0)  # a vertical cylinder's rims coincide from above
    return pts[ConvexHull(pts).vertices]


def _outline(s: Shape, W: np.ndarray, axes: tuple[int, int]) -> np.ndarray:
    if s.kind in ("capsule", "sphere"):
        half = W[:3, 2] * (s.size[1] / 2 if s.kind == "capsule" else 0.0)
        return _stadium((W[:3, 3] - half)[list(axes)], (W[:3, 3] + half)[list(axes)], s.size[0])
    return _solid_outline(s, W, axes)


def _pose_of(where: str, poses: Sequence[tuple[np.ndarray, str, int]]) -> int | None:
    """The index of the pose a :class:`Clash`'s ``where`` names (at it, or on the move from it)."""
    for i, (_q, label, _p) in enumerate(poses):
        if where == f"at {label}" or where.startswith(f"on the move from {label} to "):
            return i
    return None


def _closest(cfg: CellConfig, shapes: CellShapes, poses: Sequence[tuple[np.ndarray, str, int]],
             least: Clash) -> tuple[np.ndarray, np.ndarray] | None:
    """Where the pair that sets the least clearance comes closest: the joints and the two closest
    points (2, 3) [mm], fcl's (the check's library), over :data:`CLOSEST_SAMPLES` samples of the move
    the check names (its samples at the margin's step need not hit the closest one), or at the pose.
    None where the pose or a shape is not found by its name."""
    import fcl

    i = _pose_of(least.where, poses)
    named = {s.name: s for s in (*shapes.moving, *shapes.fixed)}
    if i is None or least.a not in named or least.b not in named:
        return None
    pair = (named[least.a], named[least.b])
    on_move = least.where.startswith("on the move from ") and i + 1 < len(poses)
    t = np.linspace(0.0, 1.0, CLOSEST_SAMPLES) if on_move else np.zeros(1)
    Q = poses[i][0] + t[:, None] * ((poses[i + 1][0] - poses[i][0]) if on_move else 0.0)
    F = chain_frames(cfg.model, Q, setup=False)
    objs = [fcl.CollisionObject(fcl_shape(fcl, s), fcl.Transform()) for s in pair]
    best: tuple[float, int, np.ndarray] | None = None
    for k in range(len(Q)):
        for o, s in zip(objs, pair):
            W = s.local if s.frame < 0 else F[k, s.frame] @ s.local
            o.setTransform(fcl.Transform(np.ascontiguousarray(W[:3, :3]), np.ascontiguousarray(W[:3, 3])))
        res = fcl.DistanceResult()
        d = float(fcl.distance(objs[0], objs[1], fcl.DistanceRequest(enable_nearest_points=True), res))
        if best is None or d < best[0]:
            best = (d, k, np.array(res.nearest_points, dtype=float))
    assert best is not None
    return Q[best[1]], best[2]


def _family_name(cfg: CellConfig, code: int) -> str:
    return f"elbow {code:+d}" if cfg.model.is_scara else f"configuration {code:+d}"


@dataclass(frozen=True)
class _Scene:
    """What is drawn, in the base frame [mm]: fixed shapes (with their poses), the arm's shapes at
    the chosen poses, the contact points of the touches (per family), of the vias, the tracks."""

    fixed: tuple[Shape, ...]
    arms: tuple[tuple[str, int | None, list[tuple[Shape, np.ndarray]]], ...]  # (what, family, [(shape, pose)])
    touches: dict[int, np.ndarray]  # family code -> (k, 3)
    vias: np.ndarray  # (v, 3)
    track_direct: np.ndarray  # (m, 3), NaN rows between moves
    track_via: np.ndarray
    least_pair: np.ndarray | None  # (2, 3) the closest points of the pair that sets the least clearance


def _track(cfg: CellConfig, Q: np.ndarray, contact: np.ndarray, moves: np.ndarray) -> np.ndarray:
    """The contact point's track (m, 3) along the joint-space moves ``moves`` (indices i: from pose
    i to i + 1), NaN rows between them (one polyline for matplotlib)."""
    if moves.size == 0:
        return np.zeros((0, 3))
    delta = Q[moves + 1] - Q[moves]
    n = np.clip(np.ceil(np.max(np.abs(delta), axis=1) / TRACK_STEP_RAD), 1, MAX_TRACK_SAMPLES).astype(int)
    rows = []
    for i, k, d in zip(moves, n, delta):
        rows.append(Q[i] + np.linspace(0.0, 1.0, k + 1)[:, None] * d)
        rows.append(np.full((1, Q.shape[1]), np.nan))
    S = np.vstack(rows)
    ok = ~np.isnan(S[:, 0])
    out = np.full((len(S), 3), np.nan)
    out[ok] = (chain_frames(cfg.model, S[ok], setup=False)[:, -1] @ contact)[:, :3, 3]
    return out


def _scene(cfg: CellConfig, steps: Sequence[PlannedStep], poses: Sequence[tuple[np.ndarray, str, int]],
           least: Clash | None) -> _Scene:
    shapes, _ = cell_shapes(cfg)
    Q = np.array([p[0] for p in poses], dtype=float).reshape(len(poses), cfg.model.n_joints)
    frames = chain_frames(cfg.model, Q, setup=False)
    contact = nominal_contact(cfg)
    point = (frames[:, -1] @ contact)[:, :3, 3]
    by_index = {s.index: s for s in steps}
    family = np.array([by_index[int(m.group(1)) - 1].elbow if (m := re.match(r"step (\d+)", p[1])) else 0
                       for p in poses])
    is_touch = np.array([p[1].endswith(": touch") for p in poses], dtype=bool)
    is_via = np.array([p[1].endswith(VIA_NAMES) for p in poses], dtype=bool)
    touches = {int(c): point[is_touch & (family == c)] for c in sorted(set(family[is_touch].tolist()))}
    moves = np.arange(len(poses) - 1)
    through_via = is_via[:-1] | is_via[1:]
    chosen: list[tuple[str, int | None, np.ndarray]] = []
    for c in touches:  # the arm at the first touch of each family
        first = int(np.flatnonzero(is_touch & (family == c))[0])
        chosen.append((f"arm at the first touch ({c:+d})", c, Q[first]))
    closest = None if least is None else _closest(cfg, shapes, poses, least)
    if closest is not None:
        chosen.append(("arm at the least clearance", None, closest[0]))
    at = chain_frames(cfg.model, np.array([q for *_, q in chosen]).reshape(-1, Q.shape[1]), setup=False)
    arms = tuple((what, code, [(s, at[k, s.frame] @ s.local) for s in shapes.moving if s.frame >= 0])
                 for k, (what, code, _q) in enumerate(chosen))
    base = [s for s in shapes.moving if s.frame < 0]
    return _Scene(tuple(base) + shapes.fixed, arms, touches, point[is_via],
                  _track(cfg, Q, contact, moves[~through_via]), _track(cfg, Q, contact, moves[through_via]),
                  None if closest is None else closest[1])


def family_id(code: int) -> str:
    """A pose family in an SVG id ("p1" for +1, "m7" for -7: '+' is no XML name character)."""
    return f"{'m' if code < 0 else 'p'}{abs(code)}"


def _gid(*parts: str) -> str:
    return "-".join(re.sub(r"[^A-Za-z0-9_.]+", "_", p) for p in parts)


def _draw_view(ax: Any, scene: _Scene, view: str, axes: tuple[int, int], cfg: CellConfig) -> None:
    from matplotlib.patches import Polygon

    names = "XYZ"
    ax.set_gid(f"{view}-view")
    for k, s in enumerate(scene.fixed):  # the body, the obstacles, the robot's base
        what = s.group.split(":")[0]
        face, edge, label = {"cube": ("#c9c9c9", "#555555", "cubes and pillars"),
                             "obstacle": ("#f2c6a0", "#a0522d", "obstacles"),
                             "link": ("#7f7f7f", "#333333", "robot base")}[what]
        patch = Polygon(_outline(s, s.local, axes), closed=True, facecolor=face, edgecolor=edge, lw=0.6,
                        zorder=2 if what != "link" else 1, label=label)
        patch.set_gid(_gid(view, what, str(k), s.name))
        ax.add_patch(patch)
    colour = {c: _FAMILY_COLOURS[k % len(_FAMILY_COLOURS)] for k, c in enumerate(scene.touches)}
    for j, (what, code, placed) in enumerate(scene.arms):
        least = code is None
        tint = "tab:red" if code is None else colour[code]
        for s, W in placed:
            patch = Polygon(_outline(s, W, axes), closed=True, facecolor="none" if least else tint, edgecolor=tint, lw=0.8 if least else 0.4,
                            alpha=0.9 if least else 0.15, zorder=3, label=what)
            patch.set_gid(_gid(view, "arm", str(j), s.name))
            ax.add_patch(patch)
    a, b = axes
    for tr, style, gid in ((scene.track_direct, dict(color="0.55", lw=0.4), "travel"),
                           (scene.track_via, dict(color="tab:orange", lw=0.6, ls="--"), "travel-via")):
        if len(tr):
            (line,) = ax.plot(tr[:, a], tr[:, b], zorder=4, label="moves from or to a via" if "via" in gid
                              else "moves", **style)
            line.set_gid(f"{view}-{gid}")
    if len(scene.vias):
        (line,) = ax.plot(scene.vias[:, a], scene.vias[:, b], "v", ms=3.5, mfc="none", mec="tab:orange", mew=0.6,
                          zorder=5, label="via poses")
        line.set_gid(f"{view}-vias")
    for k, (code, pts) in enumerate(scene.touches.items()):
        marker, size, filled = _FAMILY_MARKERS[k % len(_FAMILY_MARKERS)]
        (line,) = ax.plot(pts[:, a], pts[:, b], marker, ls="none", ms=size, mfc=colour[code] if filled else "none",
                          mec="white" if filled else colour[code], mew=0.3 if filled else 0.7, zorder=6 - 0.1 * k,
                          label=f"touches, {_family_name(cfg, code)}")
        line.set_gid(_gid(view, "touches", family_id(code)))
    if scene.least_pair is not None:  # the pair's closest points, joined, and a star between them
        pts = scene.least_pair
        (line,) = ax.plot(pts[:, a], pts[:, b], "-", color="tab:red", lw=1.2, zorder=7)
        line.set_gid(f"{view}-least-pair")
        mid = pts.mean(axis=0)
        (line,) = ax.plot([mid[a]], [mid[b]], "*", ms=9, color="tab:red", mec="black", mew=0.5, zorder=7,
                          label="least clearance")
        line.set_gid(f"{view}-least")
    ax.set_xlabel(f"{names[a]} [mm]")
    ax.set_ylabel(f"{names[b]} [mm]")
    ax.set_title("from above (X–Y)" if view == "top" else "from the side (X–Z)", fontsize=9)
    ax.grid(True, lw=0.3, alpha=0.5)


def _place_views(fig: Any, top: Any, side: Any, title_lines: int) -> None:
    """One scale [mm per inch] for both views and one X range: the side view under the top view, as a
    drawing's views stand, or beside it where that draws the cell larger (a cell taller or deeper than
    it is wide); the figure as tall as that makes it (at most :data:`MAX_HEIGHT_IN`). Fixed boxes, no
    layout engine: it took half the drawing's time."""
    (x0, y0), (x1, y1) = top.dataLim.get_points()
    (u0, z0), (u1, z1) = side.dataLim.get_points()
    x0, x1 = min(x0, u0) - PAD_MM, max(x1, u1) + PAD_MM
    y0, y1, z0, z1 = y0 - PAD_MM, y1 + PAD_MM, z0 - PAD_MM, z1 + PAD_MM
    xs, ys, zs = x1 - x0, y1 - y0, z1 - z0
    head = (title_lines + 2) * LINE_IN
    stacked = min((WIDTH_IN - LEFT_IN - RIGHT_IN) / xs, (MAX_HEIGHT_IN - head - GAP_IN - LEGEND_IN) / (ys + zs))
    beside = min((WIDTH_IN - 2 * LEFT_IN - RIGHT_IN) / (2 * xs), (MAX_HEIGHT_IN - head - LEGEND_IN) / max(ys, zs))
    scale = max(stacked, beside)  # [in / mm]
    w, h_top, h_side = xs * scale, ys * scale, zs * scale
    if stacked >= beside:
        height = head + h_top + GAP_IN + h_side + LEGEND_IN
        left = (LEFT_IN + (WIDTH_IN - LEFT_IN - RIGHT_IN - w) / 2) / WIDTH_IN
        boxes = ((left, (LEGEND_IN + h_side + GAP_IN) / height, w / WIDTH_IN, h_top / height),
                 (left, LEGEND_IN / height, w / WIDTH_IN, h_side / height))
    else:
        band = max(h_top, h_side)
        height = head + band + LEGEND_IN
        start = (WIDTH_IN - 2 * (LEFT_IN + w) - RIGHT_IN) / 2 + LEFT_IN
        boxes = ((start / WIDTH_IN, (LEGEND_IN + band - h_top) / height, w / WIDTH_IN, h_top / height),
                 ((start + w + LEFT_IN) / WIDTH_IN, (LEGEND_IN + band - h_side) / height, w / WIDTH_IN,
                  h_side / height))
    fig.set_size_inches(WIDTH_IN, height)
    for ax, box, (lo, hi) in ((top, boxes[0], (y0, y1)), (side, boxes[1], (z0, z1))):
        ax.set_position(box)
        ax.set_xlim(x0, x1)
        ax.set_ylim(lo, hi)
        ax.set_aspect("equal", adjustable="box")


def _legend(ax: Any, fig: Any) -> None:
    """One legend for both views: one entry per label, in drawing order."""
    handles, labels = ax.get_legend_handles_labels()
    seen: dict[str, Any] = {}
    for h, lab in zip(handles, labels):
        seen.setdefault(lab, h)
    fig.legend(list(seen.values()), list(seen.keys()), loc="lower center", ncol=3, fontsize=8.0, frameon=False,
               borderaxespad=0.2)


def _caption(report: CollisionReport | None, least: Clash | None) -> str:
    if report is None:
        return "no collision check was made for this picture"
    if least is None:
        return (f"least clearance: over {2 * report.margin_mm:g} mm everywhere (margin {report.margin_mm:g} mm; "
                f"{report.poses} poses and the paths between them checked)")
    return textwrap.fill(f"least clearance {least.clearance_mm:.1f} mm (margin {least.limit_mm:g} mm): {least.a} "
                         f"and {least.b}, {least.where}", 100)


def cell_picture(cfg: CellConfig, steps: Sequence[PlannedStep], poses: Sequence[tuple[np.ndarray, str, int]],
                 report: CollisionReport | None, *, png: bool = True) -> CellPicture:
    """Draw the cell from above and from the side with the plan ``steps`` and the poses the run
    commands for them (:func:`picture_poses`); ``report`` the plan's collision check (its least
    clearance is annotated and the arm drawn at that pose)."""
    import matplotlib
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    least = None if report is None else report.closest
    scene = _scene(cfg, steps, poses, least)
    # a reproducible SVG: ids from a fixed salt, text as <text> elements in matplotlib's own font
    with matplotlib.rc_context({"svg.hashsalt": "station-cell-picture", "svg.fonttype": "none",
                                "font.family": "DejaVu Sans", "font.size": 8.0, "path.simplify": True}):
        fig = Figure(figsize=(WIDTH_IN, MAX_HEIGHT_IN))
        FigureCanvasAgg(fig)
        top, side = fig.add_axes((0.1, 0.5, 0.8, 0.4)), fig.add_axes((0.1, 0.1, 0.8, 0.3))
        _draw_view(top, scene, "top", (0, 1), cfg)
        _draw_view(side, scene, "side", (0, 2), cfg)
        title = f"{cfg.name}: the plan's poses in the robot's base frame\n{_caption(report, least)}"
        _place_views(fig, top, side, title.count("\n") + 1)
        _legend(top, fig)
        fig.suptitle(title, fontsize=8.0, gid="least-clearance", y=1.0 - 0.05 / fig.get_figheight(), va="top")
        buf = io.StringIO()
        fig.savefig(buf, format="svg", metadata={"Date": None})
        out = None
        if png:
            raw = io.BytesIO()
            fig.savefig(raw, format="png", dpi=PNG_DPI, metadata={"Software": None})
            out = raw.getvalue()
    n_touch = int(sum(len(v) for v in scene.touches.values()))
    return CellPicture(buf.getvalue(), out, n_touch, len(scene.vias), tuple(scene.touches), least)


def check_picture_dir(out_dir: Path, option: str = "--out") -> None:
    """Refuse (ConfigError, exit 2) a folder the picture cannot be written into, before the planning
    (a file of that name, no permission): created where missing."""
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise ConfigError(f"{option} {out_dir}: that is a file; give a folder for the plan's files (it is created "
                          f"if missing)")
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        probe = out_dir / ".station-write-test"
        probe.write_text("")
        probe.unlink()
    except OSError as exc:
        raise ConfigError(f"{option} {out_dir}: cannot write there ({exc.strerror or exc}); choose another "
                          f"folder") from None


def write_cell_picture(out_dir: Path, picture: CellPicture) -> list[Path]:
    """Write ``cell.svg`` (and ``cell.png``) into ``out_dir`` (created); the paths written."""
    out_dir = Path(out_dir)
    check_picture_dir(out_dir)
    written = [out_dir / SVG_NAME]
    try:
        written[0].write_text(picture.svg, encoding="utf-8")
        if picture.png is not None:
            written.append(out_dir / PNG_NAME)
            written[1].write_bytes(picture.png)
    except OSError as exc:
        raise ConfigError(f"cannot write the cell's picture into {out_dir} ({exc.strerror or exc}); free space on "
                          f"its disk or choose another folder") from None
    return written


def plan_picture(cfg: CellConfig, plan: Plan, report: CollisionReport | None, with_upload: bool = True,
                 png: bool = True) -> CellPicture:
    """The picture of ``plan`` (``station plan``): ``report`` the pre-motion collision check of the plan
    with its upload; the plan without it (``--no-upload``) gets its own check, so that the least
    clearance annotated is that of the poses drawn."""
    steps = plan.run_steps(cfg.plan.verification_cycles, with_oracle=False, with_upload=with_upload)
    poses = picture_poses(cfg, steps)
    if not with_upload and report is not None:
        report = check_path(cfg, poses)
    return cell_picture(cfg, steps, poses, report, png=png)


#: the run's record of its pre-motion check (:mod:`station.cell.plan.path_record`) while the report
#: draws its picture (:func:`stored_check`); None: none known
_STORED: ContextVar[Any] = ContextVar("stored_check", default=None)


@contextmanager
def stored_check(record: Any) -> Iterator[None]:
    """Within it, :func:`run_picture` draws from ``record`` (the run's stored pre-motion check) where
    it is the check of the steps drawn, instead of planning the vias and checking the path again."""
    token = _STORED.set(record)
    try:
        yield
    finally:
        _STORED.reset(token)


def run_picture(cfg: CellConfig, steps: Sequence[PlannedStep], png: bool = False) -> CellPicture:
    """The picture of a stored run's plan (the report): its steps less the simulation's reference
    verification (the pre-motion check's plan has none), the poses and the clearance the run's
    pre-motion check found for them (its record, :func:`stored_check`), else those the collision
    check finds for them now."""
    steps = tuple(s for s in steps if s.kind is not StepKind.REFERENCE)
    hit = stored_path(cfg, steps, _STORED.get())
    if hit is not None:
        return cell_picture(cfg, steps, hit[0], hit[1], png=png)
    poses = picture_poses(cfg, steps)
    return cell_picture(cfg, steps, poses, check_path(cfg, poses), png=png)
