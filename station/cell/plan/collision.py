"""Plans that cannot hit anything (issue 40): the check of every commanded pose and every path
between consecutive poses, before the first motion, against the cell's collision shapes (the robot's
links, the probe head, the body's cubes and pillars, the cell's obstacles:
:mod:`station.cell.plan.collision_shapes`).

The distances and collisions are python-fcl's (FCL, the Flexible Collision Library: GJK/EPA on the
primitives, a dynamic AABB tree as the broad phase); nothing here computes one. Every shape is grown by
half of ``[plan] collision_margin_mm`` (a box by half the margin on each side, conservative at its
corners), so a collision of the grown shapes is a clearance under the margin between the true ones;
the refusal reports the true clearance (fcl's distance, negative where they overlap: the depth).

Pairs not checked: a link and its neighbours in the chain (a zero-length link, such as a spherical
wrist's, joins its neighbours, and so does one shorter than their radii together), the pairs the
robot file allows, the head and the last link, and the head and the cube it touches during that
touch (approach, above the point, touch, retract; there its probes' bodies keep TOUCH_MARGIN_MM).
Paths are sampled in joint space at a step that moves no point of the arm by more than the margin
(each joint's step times the largest distance from its axis to any point beyond it); stretches the
distances at their ends prove clear are not sampled (:func:`_check_paths`). Between measurements an
articulated arm travels through via poses over the body (:mod:`station.cell.plan.vias`).

This module holds the check of any sequence of poses (:func:`check_path`, and
:func:`moves_clear` / :func:`poses_clear`, which the vias and the plan's candidates ask); it imports no
planner. The whole plan's sequence and its check (:func:`station.cell.plan.run_path.check_plan`)
stand above the planners and the vias.
"""

from __future__ import annotations

import re
import time
import weakref
from dataclasses import dataclass, field

import numpy as np

from station.cell.config.cell_config import CellConfig
from station.cell.plan.collision_shapes import CellShapes, Shape, bounding_capsule, cell_shapes, fcl_shape
from station.core.kinematics.forward import chain_frames
from station.core.kinematics.transforms import invert
from station.errors import ConfigError

__all__ = ["Clash", "CollisionReport", "check_path", "moves_clear", "poses_clear", "fcl_available", "require_fcl",
           "TOUCH_MARGIN_MM"]

#: the least clearance [mm] of the probes' bodies (their tips excepted) from the cube they touch,
#: during that touch (approach, above the point, touch, retract): the tips press on its faces, the
#: bodies behind them must not (every other move keeps [plan] collision_margin_mm from that cube too)
TOUCH_MARGIN_MM = 0.5

#: pairs whose bounding spheres come within this [mm] get the tighter bound (a segment in a box): a
#: loose bound far away would only make the path's bisection halve stretches that are clear
NEAR_MM = 100.0


def fcl_available() -> bool:
    """Whether python-fcl imports (the station refuses a collision check it cannot do)."""
    try:
        import fcl  # noqa: F401
    except ImportError:
        return False
    return True


def require_fcl():
    """python-fcl, or a refusal (ConfigError) that says how to install it."""
    try:
        import fcl
    except ImportError:
        raise ConfigError("the collision check needs python-fcl, which is not installed: pip install python-fcl "
                          "(the station does not skip the check)") from None
    return fcl


class _Checker:
    """The checked pairs, a cheap screen of every sample in numpy (a lower bound of each pair's
    distance: two bounding spheres, then a moving capsule's segment boxed in the other's frame), and
    fcl's exact distance (the depth where they overlap) of each pair the screen leaves within its
    watch distance (so the plan's closest approach is reported even where nothing clashes)."""

    def __init__(self, cfg: CellConfig, shapes: CellShapes):
        self.fcl = fcl = require_fcl()
        self.shapes = shapes
        mv, fx = shapes.moving, shapes.fixed

        def checked(x: Shape, y: Shape) -> bool:
            return x.group != y.group and frozenset((x.group, y.group)) not in shapes.allowed

        self.mm = np.array([(i, j) for i in range(len(mv)) for j in range(i + 1, len(mv)) if checked(mv[i], mv[j])],
                           dtype=int).reshape(-1, 2)
        self.mf = np.array([(i, j) for i in range(len(mv)) for j in range(len(fx)) if checked(mv[i], fx[j])],
                           dtype=int).reshape(-1, 2)
        self.half_len, self.radius = np.array([bounding_capsule(s) for s in mv]).reshape(-1, 2).T
        # a fixed shape's half extents in its own frame (a cylinder's bounding box: still a lower bound)
        self.half_box = np.array([np.array(s.size) / 2 if s.kind == "box" else
                                  np.array([s.size[0], s.size[0], s.size[1] / 2]) for s in fx]).reshape(-1, 3)
        self.fixed_inv = np.array([invert(s.local) for s in fx]).reshape(-1, 4, 4)
        # bounding spheres: a moving shape's about its centre, a fixed one's about its box's
        self.ball = self.half_len + self.radius
        self.fixed_centre = np.array([s.local[:3, 3] for s in fx]).reshape(-1, 3)
        self.fixed_ball = np.linalg.norm(self.half_box, axis=1)
        self.objs = {id(s): fcl.CollisionObject(fcl_shape(fcl, s), _tf(fcl, s.local)) for s in (*mv, *fx)}

    def placed(self, frames: np.ndarray) -> np.ndarray:
        """(n, moving, 4, 4): every moving shape's pose for each of ``frames`` (n, nt, 4, 4)."""
        n = len(frames)
        return np.stack([frames[:, s.frame] @ s.local if s.frame >= 0 else np.broadcast_to(s.local, (n, 4, 4))
                         for s in self.shapes.moving], axis=1)

    def bounds(self, W: np.ndarray, near: float) -> tuple[np.ndarray, np.ndarray]:
        """Per sample, a lower bound [mm] of every moving-moving and moving-fixed pair's distance:
        (n, pairs) each. Two bounding spheres' gap first; where that comes within ``near``, the first
        of the pair as a segment grown by its radius and the second boxed in its own frame (a capsule
        or cylinder in its bounding box: the bound stays a lower one)."""
        c, z = W[..., :3, 3], W[..., :3, 2]
        i, j = self.mm.T
        gap_mm = np.linalg.norm(c[:, i] - c[:, j], axis=-1) - self.ball[i] - self.ball[j]
        k, p = np.nonzero(gap_mm < near)
        if k.size:
            a, b = i[p], j[p]
            Rt = W[k, b, :3, :3]  # into the second capsule's frame: x_box = Rᵀ (x - c)
            ends = [c[k, a] + sgn * self.half_len[a, None] * z[k, a] for sgn in (1.0, -1.0)]
            local = [(np.swapaxes(Rt, -1, -2) @ (e - c[k, b])[..., None])[..., 0] for e in ends]
            box = np.stack([self.radius[b], self.radius[b], self.radius[b] + self.half_len[b]], axis=-1)
            gap_mm[k, p] = np.maximum(gap_mm[k, p], _box_gap(local[0], local[1], box) - self.radius[a])
        i, f = self.mf.T
        gaps = np.linalg.norm(c[:, i] - self.fixed_centre[f], axis=-1) - self.ball[i] - self.fixed_ball[f]
        k, p = np.nonzero(gaps < near)
        if k.size:
            a, g = i[p], f[p]
            R, t = self.fixed_inv[g, :3, :3], self.fixed_inv[g, :3, 3]
            ends = [c[k, a] + sgn * self.half_len[a, None] * z[k, a] for sgn in (1.0, -1.0)]
            p0, p1 = ((R @ e[..., None])[..., 0] + t for e in ends)
            gaps[k, p] = np.maximum(gaps[k, p], _box_gap(p0, p1, self.half_box[g]) - self.radius[a])
        return gap_mm, gaps

    def clearance(self, a: Shape, b: Shape, Wa: np.ndarray, Wb: np.ndarray | None) -> float:
        """The true distance [mm] between ``a`` and ``b`` placed at ``Wa``, ``Wb`` (None: a fixed shape,
        placed once); negative: the depth by which they overlap (the deepest contact fcl's collision
        finds). Not fcl's signed distance: its penetration solver never returned for a capsule deep in
        a cylinder (the PUMA's forearm through a column), where the collision's contacts take 0.1 ms."""
        fcl = self.fcl
        oa, ob = self.objs[id(a)], self.objs[id(b)]
        oa.setTransform(_tf(fcl, Wa))
        if Wb is not None:
            ob.setTransform(_tf(fcl, Wb))
        d = float(fcl.distance(oa, ob, fcl.DistanceRequest(), fcl.DistanceResult()))
        if d > 0.0:
            return d
        res = fcl.CollisionResult()
        fcl.collide(oa, ob, fcl.CollisionRequest(num_max_contacts=8, enable_contact=True), res)
        return -max((float(c.penetration_depth) for c in res.contacts), default=0.0)


def _box_gap(p0: np.ndarray, p1: np.ndarray, half: np.ndarray) -> np.ndarray:
    """A lower bound [mm] of the distance from the segments ``p0``–``p1`` (…, 3) to the centred box of
    ``half`` extents: the distance of the segment's own bounding box to it."""
    lo, hi = np.minimum(p0, p1), np.maximum(p0, p1)
    return np.linalg.norm(np.maximum(0.0, np.maximum(lo - half, -half - hi)), axis=-1)


def _tf(fcl, T: np.ndarray):
    return fcl.Transform(np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(T[:3, 3]))


# --- the check ----------------------------------------------------------------------------------

@dataclass(frozen=True)
class Clash:
    """Two shapes' closest approach: the shapes, the step and the move, the clearance [mm] and the
    least clearance that pair must keep there [mm] (under it: a clash)."""

    a: str
    b: str
    where: str
    clearance_mm: float
    limit_mm: float

    def describe(self) -> str:
        under = "overlapping" if self.clearance_mm < 0 else "under" if self.clearance_mm < self.limit_mm else "over"
        return (f"{self.a} and {self.b} come within {self.clearance_mm:.1f} mm of each other "
                f"({under} the margin of {self.limit_mm:g} mm) {self.where}")


@dataclass(frozen=True)
class CollisionReport:
    """What the check found: poses and path samples checked, the first clash (None: clear), the
    closest approach of any pair held to the full margin (None: none came within twice the margin)
    and of a probe's body to the cube it touches, the margin [mm] and the time the check took [s]."""

    poses: int
    samples: int
    clash: Clash | None
    margin_mm: float
    closest: Clash | None = None
    closest_touch: Clash | None = None
    seconds: float = field(compare=False, default=0.0)
    #: the samples evaluated (of ``samples`` at the margin's step: the rest lie on stretches proven clear)
    evaluated: int = 0
    #: how many poses and moves clash (the first is ``clash``)
    clashing_moves: int = 0
    #: the via poses among ``poses`` (:mod:`station.cell.plan.vias`)
    vias: int = 0
    #: per plan step (its index) the closest approach of a pair held to the full margin on that step's
    #: moves (the travel to it, its approach, touch and retract; :func:`_step_moves`), None where no
    #: pair came within twice the margin: what the TUI shows as the next move's clearance
    by_step: tuple[tuple[int, Clash | None], ...] = field(default=(), compare=False)

    def to_json(self) -> dict:
        """What ``station plan --json`` says (clearances in mm, time in s)."""
        def pair(c: Clash | None):
            return None if c is None else {"a": c.a, "b": c.b, "where": c.where, "clearance_mm": round(c.clearance_mm, 3),
                                           "limit_mm": c.limit_mm}
        return {"poses": self.poses, "vias": self.vias, "samples": self.samples, "evaluated": self.evaluated,
                "margin_mm": self.margin_mm, "clash": pair(self.clash), "closest": pair(self.closest),
                "closest_touch": pair(self.closest_touch), "seconds": round(self.seconds, 3)}

    def lines(self) -> list[str]:
        """What ``station plan`` prints."""
        head = (f"collision check: {self.poses} poses ({self.vias} of them vias over the body) and the paths "
                f"between them ({self.samples} samples at the margin's step, {self.evaluated} evaluated), margin "
                f"{self.margin_mm:g} mm, {self.seconds:.1f} s")
        if self.clash is not None:
            return [head, f"  CLASH ({self.clashing_moves} poses or moves): {self.clash.describe()}"]
        out = [head, "  least clearance: " + (f"over {2 * self.margin_mm:g} mm" if self.closest is None else
                                              self.closest.describe())]
        if self.closest_touch is not None:
            out.append(f"  during the touches: {self.closest_touch.describe()}")
        return out


def _where(poses: list[tuple[np.ndarray, str, int]], i: int, on_path: bool) -> str:
    """What people read for pose ``i`` (or the path from it to the next)."""
    label = poses[i][1]
    if not on_path:
        return f"at {label}"
    step, nxt = label.split(":")[0], poses[i + 1][1]
    same = nxt.split(":")[0] == step
    return (f"on the move from {label} to {nxt.split(': ', 1)[-1]}" + ("" if same else f" ({nxt.split(':')[0]})"))


def _touch_status(poses: list[tuple[np.ndarray, str, int]], point_cube: tuple[str, ...]) -> list[tuple]:
    """Per pose, the cube the head may touch at the pose and on the move from it (None: none). The
    touch is its approach, the pose above the point, the touch and the retract, and the moves
    between them; the retract pose itself starts the next travel move."""
    out = []
    for i, (_q, label, point) in enumerate(poses):
        nxt = poses[i + 1] if i + 1 < len(poses) else None
        same = nxt is not None and nxt[1].split(":")[0] == label.split(":")[0]
        cube = point_cube[point] if point >= 0 else None
        out.append((cube if label.endswith(("touch", "above the point")) or same else None, cube if same else None))
    return out


@dataclass
class _Found:
    """Every exact distance under its pair's watch distance (the limit plus the margin): (path
    order key, pose index, on the path, clearance, moving shape, other shape, limit)."""

    hits: list = field(default_factory=list)
    evaluated: int = 0


class _Evaluator:
    """Evaluate samples: the lower bounds of every checked pair, fcl's exact distance where the
    bound comes within the pair's watch distance, and per sample the least slack (distance less
    watch) of the moving-fixed and of the moving-moving pairs: what a path interval may lose."""

    def __init__(self, cfg: CellConfig, checker: _Checker):
        self.cfg, self.c = cfg, checker
        sh = checker.shapes
        codes = {g: k for k, g in enumerate(dict.fromkeys(s.group for s in sh.fixed))}
        self.codes = codes
        i, j = checker.mf.T
        self.fixed_code = np.array([codes[sh.fixed[k].group] for k in j], dtype=int)
        self.is_tip = np.array([sh.moving[k].group == "tip" for k in i], dtype=bool)
        self.is_head = np.array([sh.moving[k].group == "head" for k in i], dtype=bool)

    def __call__(self, Q: np.ndarray, cube: np.ndarray, key: np.ndarray, owner: np.ndarray, on_path: bool,
                 found: _Found) -> tuple[np.ndarray, np.ndarray]:
        c, margin = self.c, self.c.shapes.margin_mm
        mv, fx = c.shapes.moving, c.shapes.fixed
        found.evaluated += len(Q)
        W = c.placed(chain_frames(self.cfg.model, Q, setup=False))
        d_mm, d_mf = c.bounds(W, NEAR_MM)
        touched = self.fixed_code[None, :] == cube[:, None]  # (n, mf): the pair's fixed shape is the touched cube
        limit = np.where(touched & self.is_head, TOUCH_MARGIN_MM, margin)
        limit = np.where(touched & self.is_tip, -np.inf, limit)  # the tips press on the cube they touch
        for k, p in zip(*np.nonzero(d_mm < 2 * margin)):
            a, b = c.mm[p]
            d_mm[k, p] = d = c.clearance(mv[a], mv[b], W[k, a], W[k, b])
            if d < 2 * margin:
                found.hits.append((key[k], int(owner[k]), on_path, d, mv[a], mv[b], margin))
        for k, p in zip(*np.nonzero(d_mf < limit + margin)):
            a, b = c.mf[p]
            d_mf[k, p] = d = c.clearance(mv[a], fx[b], W[k, a], None)
            if d < limit[k, p] + margin:
                found.hits.append((key[k], int(owner[k]), on_path, d, mv[a], fx[b], float(limit[k, p])))
        slack_mm = np.min(d_mm - 2 * margin, axis=1, initial=np.inf)
        slack_mf = np.min(np.where(np.isfinite(limit), d_mf - limit - margin, np.inf), axis=1, initial=np.inf)
        return slack_mf, slack_mm


def _check_paths(ev: _Evaluator, poses: list, touch: list, cube_code, found: _Found, first_clash: bool = False) -> int:
    """Every path between consecutive poses, bisected from its ends: an interval whose ends' slacks
    exceed what any point of the arm can move along it (the joints' steps times their levers) is
    clear, every pair farther than its watch distance all along; the others are halved down to
    the step that moves no point by more than the margin, and those samples are evaluated. The
    result is that of checking every sample at that step (``first_clash``: it stops at a clash).
    Returns the number of such samples."""
    shapes = ev.c.shapes
    q = np.array([p[0] for p in poses])
    reach = np.abs(np.diff(q, axis=0)) @ shapes.levers  # (moves,): how far any point moves [mm]
    n = np.maximum(1, np.ceil(reach / shapes.margin_mm)).astype(int)
    moves = np.flatnonzero(n > 1)
    if moves.size == 0:
        return len(poses)
    code = np.array([cube_code(touch[i][1]) for i in moves])
    m = len(moves)
    ends = np.concatenate([q[moves], q[moves + 1]])
    keys = np.concatenate([moves + 0.25, moves + 0.75])  # pose i < the path from it < pose i + 1
    s_mf, s_mm = ev(ends, np.concatenate([code, code]), keys, np.concatenate([moves, moves]), True, found)
    move, lo, hi = np.arange(m), np.zeros(m, dtype=int), n[moves].copy()
    lo_s = np.stack([s_mf[:m], s_mm[:m]], axis=1)
    hi_s = np.stack([s_mf[m:], s_mm[m:]], axis=1)
    while move.size:
        if first_clash and any(h[3] < h[6] for h in found.hits):
            break
        i = moves[move]
        span = reach[i] * (hi - lo) / n[i]
        open_ = np.any(lo_s + hi_s <= span[:, None], axis=1) & (hi - lo > 1)
        move, lo, hi, lo_s, hi_s, i = move[open_], lo[open_], hi[open_], lo_s[open_], hi_s[open_], i[open_]
        if not move.size:
            break
        mid = (lo + hi) // 2
        t = mid / n[i]
        Q = q[i] + (q[i + 1] - q[i]) * t[:, None]
        mf, mm = ev(Q, code[move], i + 0.25 + 0.5 * t, i, True, found)
        mid_s = np.stack([mf, mm], axis=1)
        move, lo, hi = np.concatenate([move, move]), np.concatenate([lo, mid]), np.concatenate([mid, hi])
        lo_s, hi_s = np.concatenate([lo_s, mid_s]), np.concatenate([mid_s, hi_s])
    return int(len(poses) + np.sum(n[moves] - 1))


# One evaluator per configuration object (weak keys: the entry goes with the configuration): the
# travel vias ask about single moves (station/cell/plan/vias.py), during planning and in the runner.
_EVALUATORS: weakref.WeakKeyDictionary[CellConfig, tuple] = weakref.WeakKeyDictionary()


def _evaluator(cfg: CellConfig) -> tuple[_Evaluator, tuple[str, ...]]:
    hit = _EVALUATORS.get(cfg)
    if hit is None:
        shapes, point_cube = cell_shapes(cfg)
        hit = _EVALUATORS[cfg] = (_Evaluator(cfg, _Checker(cfg, shapes)), point_cube)
    return hit


def moves_clear(cfg: CellConfig, qs: list[np.ndarray]) -> bool:
    """Whether the travel through the joints ``qs`` (poses and the joint-space paths between them,
    away from every measuring point: the full margin from every shape) is clear."""
    ev, _ = _evaluator(cfg)
    poses = [(np.asarray(q, dtype=float), f"via {k}: travel", -1) for k, q in enumerate(qs)]
    touch = [(None, None)] * len(poses)
    found = _Found()
    ix = np.arange(len(poses))
    ev(np.array([p[0] for p in poses]), np.full(len(poses), -1), ix.astype(float), ix, False, found)
    if len(poses) > 1 and not any(h[3] < h[6] for h in found.hits):
        _check_paths(ev, poses, touch, lambda g: -1, found, first_clash=True)
    return not any(h[3] < h[6] for h in found.hits)


def poses_clear(cfg: CellConfig, Q: np.ndarray, points: np.ndarray) -> list[str | None]:
    """Per row of ``Q (n, g)``: None when the pose is clear, with the head touching measuring point
    ``points[k]`` (its cube's tips may press; -1: none), else the clash named (pair and clearance)."""
    ev, point_cube = _evaluator(cfg)
    code = np.array([-1 if p < 0 else ev.codes.get(point_cube[p], -1) for p in points], dtype=int)
    found = _Found()
    ix = np.arange(len(Q))
    ev(np.asarray(Q, dtype=float).reshape(len(ix), -1), code, ix.astype(float), ix, False, found)
    out: list[str | None] = [None] * len(Q)
    for _key, i, _on, d, a, b, limit in sorted(found.hits, key=lambda h: h[3]):
        if d < limit and out[i] is None:
            out[i] = f"{a.name} and {b.name} come within {d:.1f} mm of each other (the margin: {limit:g} mm)"
    return out


def check_path(cfg: CellConfig, poses: list[tuple[np.ndarray, str, int]]) -> CollisionReport:
    """Check every pose of ``poses`` and every path between consecutive ones (joint space, at a step
    that moves no point of the arm by more than the margin; :func:`_check_paths` skips the stretches
    the distances at their ends prove clear): the first clash in the order of motion (None: clear),
    the closest approach of the pairs held to the margin and of a probe's body to the cube it touches."""
    t0 = time.perf_counter()
    ev, point_cube = _evaluator(cfg)
    shapes = ev.c.shapes
    touch = _touch_status(poses, point_cube)

    def cube_code(group: str | None) -> int:
        return -1 if group is None else ev.codes.get(group, -1)

    found = _Found()
    if poses:
        ix = np.arange(len(poses))
        ev(np.array([p[0] for p in poses]), np.array([cube_code(t[0]) for t in touch]), ix.astype(float), ix,
           False, found)
    fine = _check_paths(ev, poses, touch, cube_code, found) if len(poses) > 1 else len(poses)
    clashes = sorted((h for h in found.hits if h[3] < h[6]), key=lambda h: h[0])

    def named(hit) -> Clash | None:
        if hit is None:
            return None
        _key, i, on_path, d, a, b, limit = hit
        return Clash(a.name, b.name, _where(poses, i, on_path), d, limit)

    margin = shapes.margin_mm
    normal = [h for h in found.hits if h[6] == margin]
    at_touch = [h for h in found.hits if h[6] != margin]
    owner = _step_moves(poses)
    least: dict[int, tuple | None] = {k: None for k in owner if k >= 0}
    for h in normal:  # the pose's step, or the step the move from pose i leads to (pose i + 1's)
        k = owner[h[1] + 1] if h[2] else owner[h[1]]
        held = least.get(k)
        if k >= 0 and (held is None or h[3] < held[3]):
            least[k] = h
    return CollisionReport(len(poses), fine, named(clashes[0] if clashes else None), margin,
                           named(min(normal, key=lambda h: h[3], default=None)),
                           named(min(at_touch, key=lambda h: h[3], default=None)), time.perf_counter() - t0,
                           evaluated=found.evaluated, clashing_moves=len({(h[1], h[2]) for h in clashes}),
                           by_step=tuple((k, named(h)) for k, h in sorted(least.items())))


def _step_moves(poses: list[tuple[np.ndarray, str, int]]) -> list[int]:
    """Per pose, the plan step (its index; -1: none) whose moves reach it: a retract pose its own
    step's, every other pose (a depart or a stage of the travel, labelled with the step the head
    leaves, an arrive, the approach, the pose above the point, the touch) the step of the next
    touch. Labels as :func:`station.cell.plan.run_path.plan_path` writes them ("step N (…): what")."""
    out, nxt = [-1] * len(poses), -1
    for i in range(len(poses) - 1, -1, -1):
        label = poses[i][1]
        m = _STEP.match(label)
        own = int(m.group(1)) - 1 if m else -1
        if label.endswith(": touch"):
            nxt = own
        out[i] = own if label.endswith(": retract") else nxt
    return out


_STEP = re.compile(r"step (\d+) \(")
