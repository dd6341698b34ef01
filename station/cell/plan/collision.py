"""Plans that cannot hit anything (issue 40): the cell's collision shapes and the check of every
commanded pose and every path between consecutive poses, before the first motion.

Shapes, all in the robot's base frame (docs/collision.md):

* **the robot's links**: one capsule per link along its transform's offset, split in two where the
  offset has a part along the joint axis and one across it (a DH link's d, then its a), with the
  radius the robot file's ``[collision] radius_mm`` states, else :func:`default_radii`;
* **the probe head**: a capsule per probe from its tip back along its axis by its stroke plus the
  tip's diameter (the probe's body), and the mount from the flange to the head frame;
* **the body**: every cube (from its measuring points' corner frames and ``[body] cube_edge_mm``), the
  pillar under it down to the plate, and the plate (the cubes' footprint grown by one edge, one edge
  thick below z = 0 of the body frame);
* **the cell's fixed obstacles**: ``[[obstacle]]`` boxes and cylinders.

The distances and collisions are python-fcl's (FCL, the Flexible Collision Library: GJK/EPA on the
primitives, a dynamic AABB tree as the broad phase); nothing here computes one. Every shape is grown by
half of ``[plan] collision_margin_mm`` (a box by half the margin on each side, conservative at its
corners), so a collision of the grown shapes is a clearance under the margin between the true ones;
the refusal reports the true clearance (fcl's distance, negative where they overlap: the depth).

Pairs not checked: a link and its neighbours in the chain (a zero-length link, such as a spherical
wrist's, joins its neighbours), the pairs the robot file allows, the head and the last link, and the
head and the cube it touches during that touch (approach, above the point, touch, retract).
Paths are sampled in joint space at a step that moves no point of the arm by more than the margin
(each joint's step times the largest distance from its axis to any shape beyond it).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from station.cell.config.cell_config import CellConfig
from station.cell.plan.assembly import Plan
from station.core.kinematics.forward import chain_frames
from station.core.kinematics.transforms import invert, pose_to_matrix
from station.errors import ConfigError

__all__ = ["Shape", "CellShapes", "Clash", "CollisionReport", "cell_shapes", "default_radii", "check_path",
           "check_plan", "plan_path", "fcl_available", "TOUCH_MARGIN_MM",
           "head_depth_mm"]

#: the least clearance [mm] of the probes' bodies (their tips excepted) from the cube they touch,
#: during that touch (approach, above the point, touch, retract): the tips press on its faces, the
#: bodies behind them must not (every other move keeps [plan] collision_margin_mm from that cube too)
TOUCH_MARGIN_MM = 0.5

#: default link radius as a fraction of the robot's size (the sum of its link offsets): 4 % gives
#: 58 mm on the PUMA 560's 1.45 m and 57 mm on a 600 mm SCARA with its 820 mm column, about an
#: industrial arm's half-width (a PUMA's forearm is ~110 mm across)
DEFAULT_RADIUS_FRACTION = 0.04


def fcl_available() -> bool:
    """Whether python-fcl imports (the station refuses a collision check it cannot do)."""
    try:
        import fcl  # noqa: F401
    except ImportError:
        return False
    return True


def _fcl():
    try:
        import fcl
    except ImportError:
        raise ConfigError("the collision check needs python-fcl, which is not installed: pip install python-fcl "
                          "(the station does not skip the check)") from None
    return fcl


@dataclass(frozen=True)
class Shape:
    """One collision shape: ``kind`` "capsule" (size = radius, length; axis along local z), "box"
    (edges), "cylinder" (radius, height) or "sphere" (radius); ``local`` (4, 4) its centre in the frame
    it rides on: ``frame`` (an index into the chain's frames; -1: the robot base, fixed); ``group`` what
    it belongs to ("link:A2", "head", "cube:3", "plate", "obstacle:column"); ``name`` for people."""

    name: str
    kind: str
    size: tuple[float, ...]
    local: np.ndarray
    frame: int
    group: str


@dataclass(frozen=True)
class CellShapes:
    """The moving shapes (links and head), the fixed ones (body, obstacles, the base link), the pairs
    of groups never checked, and each joint's largest lever [mm] (for the path's step)."""

    moving: tuple[Shape, ...]
    fixed: tuple[Shape, ...]
    allowed: frozenset[frozenset[str]]
    levers: np.ndarray
    margin_mm: float


def default_radii(cfg: CellConfig) -> tuple[float, ...]:
    """One radius per link (base, then every joint transform): :data:`DEFAULT_RADIUS_FRACTION` of the
    sum of the joint transforms' and the tool's offsets."""
    p = cfg.model.nominal.reshape(-1, 6)
    size = float(np.sum(np.linalg.norm(p[1:, :3], axis=1)))
    n = cfg.model.n_joints + 1
    return (DEFAULT_RADIUS_FRACTION * size,) * n


def _segment(name: str, a: np.ndarray, b: np.ndarray, r: float, frame: int, group: str) -> Shape:
    """A capsule from ``a`` to ``b`` (3,) in ``frame``; a sphere where they meet."""
    d = b - a
    length = float(np.linalg.norm(d))
    local = np.eye(4)
    local[:3, 3] = (a + b) / 2
    if length < 1e-9:
        return Shape(name, "sphere", (r,), local, frame, group)
    z = d / length
    x = np.cross(z, [1.0, 0.0, 0.0] if abs(z[0]) < 0.9 else [0.0, 1.0, 0.0])
    x /= np.linalg.norm(x)
    local[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    return Shape(name, "capsule", (r, length), local, frame, group)


def _link_shapes(cfg: CellConfig) -> tuple[list[Shape], list[str]]:
    """The links' capsules and the link names (base first). Link k rides on the frame after
    transform k (k = 0: the base) and reaches to transform k + 1's origin; the last link's reach to
    the head frame is the head's mount."""
    spec = cfg.robot_collision
    radii = spec.radius_mm if spec is not None and spec.radius_mm is not None else default_radii(cfg)
    p = cfg.model.nominal.reshape(-1, 6)
    tr = cfg.model.transforms
    names = [tr[0].name] + [t.name for t in tr if t.joint is not None]
    out: list[Shape] = []
    link = 0
    for t in range(len(tr) - 2):  # the link after transform t reaches to transform t + 1
        if t > 0 and tr[t].joint is None:
            continue
        off = p[t + 1, :3]
        knee = np.array([0.0, 0.0, off[2]])
        frame = -1 if t == 0 else t
        group = f"link:{names[link]}"
        out.append(_segment(f"link {names[link]} (along its axis)", np.zeros(3), knee, radii[link], frame, group))
        out.append(_segment(f"link {names[link]}", knee, off, radii[link], frame, group))
        link += 1
    return [s for s in out if s.kind == "capsule"], names


def _head_shapes(cfg: CellConfig) -> list[Shape]:
    """The probes and the mount, riding on the last frame (the head frame MKKS). Each probe is two
    capsules of its tip's radius: its tip ("tip", from the free tip, half the stroke beyond the
    mount point, back to one tip diameter behind it: what presses on the face at a touch) and its
    body ("head", from there back by the stroke: what must never touch the cube)."""
    from station.core.probe.geometry import default_probe_head

    head = cfg.head if cfg.head is not None else default_probe_head(cube_edge_mm=cfg.cube_edge_mm)
    last = len(cfg.model.transforms) - 1
    out = []
    for i in range(head.n_probes):
        mount, d = head.mount_points[i], head.directions[i]
        r, stroke = float(head.tip_radii[i]), float(head.strokes[i])
        neck = mount - d * 2 * r
        out.append(_segment(f"probe {head.label(i)}'s tip", mount + d * stroke / 2, neck, r, last, "tip"))
        out.append(_segment(f"probe {head.label(i)}", neck, neck - d * stroke, r, last, "head"))
    K = pose_to_matrix(cfg.model.nominal.reshape(-1, 6)[-1])
    flange = invert(K)[:3, 3]  # the flange's origin in MKKS
    r_mount = float(np.max(np.linalg.norm(head.mount_points, axis=1))) / 4
    out.append(_segment("head mount", flange, np.zeros(3), r_mount, last, "head"))
    return [s for s in out if s.kind in ("capsule", "sphere")]


def head_depth_mm(cfg: CellConfig) -> float:
    """How far [mm] the head's lowest point (a free probe's tip, a probe's body, the mount) hangs
    below its nominal contact, along the contact frame's z (up, out of the cube's top face): a
    SCARA's travel height lifts the contact this much more, or a side probe drags over a cube."""
    from station.cell.plan.assembly import nominal_contact

    M = nominal_contact(cfg)
    up, c = M[:3, 2], M[:3, 3]
    low = 0.0
    for s in _head_shapes(cfg):
        half = s.local[:3, 2] * (s.size[1] / 2 if s.kind == "capsule" else 0.0)
        for end in (s.local[:3, 3] + half, s.local[:3, 3] - half):
            low = max(low, float((c - end) @ up) + s.size[0])
    return low


def _body_shapes(cfg: CellConfig) -> tuple[list[Shape], tuple[str, ...]]:
    """The cubes, their pillars and the plate in the body frame, and each measuring point's cube
    (its group)."""
    e = cfg.cube_edge_mm
    centre = np.eye(4)
    centre[:3, 3] = [e / 2, e / 2, -e / 2]  # the cube lies in x, y >= 0, z <= 0 of its corner frame
    cubes: dict[tuple, tuple[np.ndarray, str]] = {}
    of_point = []
    for pid, M in zip(cfg.point_ids, cfg.body_points):
        C = M @ centre
        key = tuple(np.round(C[:3, 3], 1))
        cubes.setdefault(key, (C, pid))
        of_point.append(f"cube:{list(cubes).index(key)}")
    out, lows, highs = [], [], []
    for k, (C, pid) in enumerate(cubes.values()):
        out.append(Shape(f"cube of {pid}", "box", (e, e, e), C, -2, f"cube:{k}"))
        bottom = C[2, 3] - e / 2
        if bottom > 1e-6:  # a pillar from the plate to the cube's underside
            P = C.copy()
            P[2, 3] = bottom / 2
            out.append(Shape(f"pillar of {pid}", "box", (e, e, bottom), P, -2, f"cube:{k}"))
        lows.append(C[:2, 3] - e)
        highs.append(C[:2, 3] + e)
    lo, hi = np.min(lows, axis=0) - e, np.max(highs, axis=0) + e
    plate = np.eye(4)
    plate[:3, 3] = [*((lo + hi) / 2), -e / 2]
    out.append(Shape("the body's plate", "box", (*(hi - lo), e), plate, -2, "plate"))
    return out, tuple(of_point)


def _obstacle_shapes(cfg: CellConfig) -> list[Shape]:
    return [Shape(f"obstacle {o.name!r}", o.shape, o.size, o.pose, -2 if o.frame == "body" else -1,
                  f"obstacle:{o.name}") for o in cfg.obstacles]


# --- the shapes of a cell ---------------------------------------------------------------------

def cell_shapes(cfg: CellConfig) -> tuple[CellShapes, tuple[str, ...]]:
    """Every shape of the cell (fixed ones placed in the robot's base frame) and each measuring
    point's cube group."""
    links, names = _link_shapes(cfg)
    head = _head_shapes(cfg)
    body, point_cube = _body_shapes(cfg)
    base_from_body = invert(pose_to_matrix(cfg.model.nominal[:6]))
    fixed = [Shape(s.name, s.kind, s.size, base_from_body @ s.local if s.frame == -2 else s.local, -1, s.group)
             for s in (*body, *_obstacle_shapes(cfg))]
    chain = [g for g in dict.fromkeys(s.group for s in links)] + ["head"]
    allowed = {frozenset(p) for p in zip(chain, chain[1:])}
    allowed |= {frozenset(("tip", "head")), frozenset(("tip", chain[-2]))}  # the tips ride on the head
    spec = cfg.robot_collision
    allowed |= {frozenset((f"link:{a}", f"link:{b}")) for a, b in (spec.allowed_pairs if spec is not None else ())}
    base = f"link:{names[0]}"  # the base stands where it stands: nothing fixed is checked against it
    allowed |= {frozenset((base, s.group)) for s in fixed}
    return CellShapes(tuple(links + head), tuple(fixed), frozenset(allowed), _levers(cfg, links + head),
                      cfg.plan.collision_margin_mm), point_cube


def _levers(cfg: CellConfig, moving: list[Shape]) -> np.ndarray:
    """Per joint, an upper bound of how far any moving shape's axis point lies from the joint's
    axis [mm] (1 for a prismatic joint: a point moves as far as the joint): the length of every
    link beyond it plus the head's reach from the flange."""
    tr = cfg.model.transforms
    p = cfg.model.nominal.reshape(-1, 6)
    seg = np.linalg.norm(p[:, :3], axis=1)
    reach = max((float(np.linalg.norm(s.local[:3, 3])) + s.size[-1] / 2 for s in moving if s.group == "head"),
                default=0.0)
    out, j = [], 0
    for t, spec in enumerate(tr):
        if spec.joint is None:
            continue
        out.append(1.0 if spec.joint == "prismatic" else float(np.sum(seg[t + 1:])) + reach)
        j += 1
    return np.array(out)


def _grown(fcl, s: Shape, grow: float):
    r = s.size
    if s.kind == "capsule":
        return fcl.Capsule(r[0] + grow, r[1])
    if s.kind == "sphere":
        return fcl.Sphere(r[0] + grow)
    if s.kind == "cylinder":
        return fcl.Cylinder(r[0] + grow, r[1] + 2 * grow)
    return fcl.Box(*(v + 2 * grow for v in r))


class _Checker:
    """The checked pairs, a cheap screen of every sample in numpy (a lower bound of each pair's
    distance: a moving capsule's segment boxed in a fixed shape's frame, or two bounding spheres),
    and fcl's exact signed distance of each pair the screen leaves within twice the margin (so the
    plan's closest approach is reported even where nothing clashes)."""

    def __init__(self, cfg: CellConfig, shapes: CellShapes):
        self.fcl = fcl = _fcl()
        self.shapes = shapes
        mv, fx = shapes.moving, shapes.fixed

        def checked(x: Shape, y: Shape) -> bool:
            return x.group != y.group and frozenset((x.group, y.group)) not in shapes.allowed

        self.mm = np.array([(i, j) for i in range(len(mv)) for j in range(i + 1, len(mv)) if checked(mv[i], mv[j])],
                           dtype=int).reshape(-1, 2)
        self.mf = np.array([(i, j) for i in range(len(mv)) for j in range(len(fx)) if checked(mv[i], fx[j])],
                           dtype=int).reshape(-1, 2)
        self.half_len = np.array([s.size[1] / 2 if s.kind == "capsule" else 0.0 for s in mv])
        self.radius = np.array([s.size[0] for s in mv])
        # a fixed shape's half extents in its own frame (a cylinder's bounding box: still a lower bound)
        self.half_box = np.array([np.array(s.size) / 2 if s.kind == "box" else
                                  np.array([s.size[0], s.size[0], s.size[1] / 2]) for s in fx]).reshape(-1, 3)
        self.fixed_inv = np.array([invert(s.local) for s in fx]).reshape(-1, 4, 4)
        self.objs = {id(s): fcl.CollisionObject(_grown(fcl, s, 0.0), _tf(fcl, s.local)) for s in (*mv, *fx)}

    def placed(self, frames: np.ndarray) -> np.ndarray:
        """(n, moving, 4, 4): every moving shape's pose for each of ``frames`` (n, nt, 4, 4)."""
        n = len(frames)
        return np.stack([frames[:, s.frame] @ s.local if s.frame >= 0 else np.broadcast_to(s.local, (n, 4, 4))
                         for s in self.shapes.moving], axis=1)

    def screen(self, W: np.ndarray, watch: float) -> tuple[np.ndarray, np.ndarray]:
        """Per sample, which moving-moving and moving-fixed pairs may lie within ``watch`` [mm]:
        boolean (n, pairs) each, never False for a pair that does. The first of a pair is a segment
        grown by its radius, the second is boxed in its own frame (a capsule or cylinder in its
        bounding box: the bound stays a lower one)."""
        c, z = W[..., :3, 3], W[..., :3, 2]
        ends = [c + s * self.half_len[:, None] * z for s in (1.0, -1.0)]  # (n, moving, 3) each
        i, j = self.mm.T
        Rt = W[:, j, :3, :3]  # into the second capsule's frame: x_box = Rᵀ (x - c)
        local = [(np.swapaxes(Rt, -1, -2) @ (e[:, i] - c[:, j])[..., None])[..., 0] for e in ends]
        box = np.stack([self.radius[j], self.radius[j], self.radius[j] + self.half_len[j]], axis=-1)
        near_mm = _box_gap(local[0], local[1], box) - self.radius[i] < watch
        i, f = self.mf.T
        gaps = np.empty((len(W), len(self.mf)))
        for g in np.unique(f):  # each fixed shape: every moving segment's ends in its frame at once
            k = np.flatnonzero(f == g)
            R, t = self.fixed_inv[g, :3, :3], self.fixed_inv[g, :3, 3]
            p0, p1 = (e[:, i[k]] @ R.T + t for e in ends)
            gaps[:, k] = _box_gap(p0, p1, self.half_box[g]) - self.radius[i[k]]
        return near_mm, gaps < watch

    def clearance(self, a: Shape, b: Shape, Wa: np.ndarray, Wb: np.ndarray) -> float:
        """The true distance [mm] between ``a`` and ``b`` placed at ``Wa``, ``Wb``; negative: the depth
        by which they overlap."""
        fcl = self.fcl
        oa, ob = self.objs[id(a)], self.objs[id(b)]
        oa.setTransform(_tf(fcl, Wa))
        ob.setTransform(_tf(fcl, Wb))
        return float(fcl.distance(oa, ob, fcl.DistanceRequest(enable_signed_distance=True), fcl.DistanceResult()))


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

    def lines(self) -> list[str]:
        """What ``station plan`` prints."""
        head = (f"collision check: {self.poses} poses and the paths between them ({self.samples} samples), "
                f"margin {self.margin_mm:g} mm, {self.seconds:.1f} s")
        if self.clash is not None:
            return [head, f"  CLASH: {self.clash.describe()}"]
        out = [head, "  least clearance: " + (f"over {2 * self.margin_mm:g} mm" if self.closest is None else
                                              self.closest.describe())]
        if self.closest_touch is not None:
            out.append(f"  during the touches: {self.closest_touch.describe()}")
        return out


def plan_path(cfg: CellConfig, plan: Plan, with_upload: bool = True) -> list[tuple[np.ndarray, str, int]]:
    """Every pose a run commands, in order: (joints, what it is, the measuring point it touches). The
    first move, from wherever the robot stands to the first approach, is not known before the run."""
    from station.cell.plan.measurement_plan import all_motion_poses, retracted

    out = []
    for s in plan.run_steps(cfg.plan.verification_cycles, with_oracle=False, with_upload=with_upload):
        q = s.q
        names = ("approach", "above the point", "touch")
        for name, qq in zip(names, all_motion_poses(cfg, q, s.direction)):
            out.append((np.asarray(qq, dtype=float), f"step {s.index + 1} ({s.label}): {name}", s.point))
        out.append((np.asarray(retracted(cfg, q), dtype=float), f"step {s.index + 1} ({s.label}): retract", s.point))
    return out


def _where(poses: list[tuple[np.ndarray, str, int]], i: int, on_path: bool) -> str:
    """What people read for pose ``i`` (or the path from it to the next)."""
    label = poses[i][1]
    if not on_path:
        return f"at {label}"
    step, nxt = label.split(":")[0], poses[i + 1][1]
    same = nxt.split(":")[0] == step
    return (f"on the move from {label} to {nxt.split(': ', 1)[-1]}" + ("" if same else f" ({nxt.split(':')[0]})"))


def _samples(shapes: CellShapes, poses: list[tuple[np.ndarray, str, int]], point_cube: tuple[str, ...]):
    """The joints of every pose and of the path to the next one, at a step that moves no point of
    the arm by more than the margin; per sample its pose's index and whether it lies on the path
    from it, and per pose and path the cube the head may touch there (None: none)."""
    qs, owner, on_path, touch = [], [], [], []
    for i, (q, label, point) in enumerate(poses):
        nxt = poses[i + 1] if i + 1 < len(poses) else None
        step = label.split(":")[0]
        same = nxt is not None and nxt[1].split(":")[0] == step  # within one touch: the head meets its cube
        cube = point_cube[point] if point >= 0 else None
        qs.append(q[None])
        owner.append(i)
        on_path.append(False)
        # the touch is its approach, the pose above the point, the touch and the retract, and the
        # moves between them; the retract pose itself starts the next travel move
        touch.append((cube if label.endswith(("touch", "above the point")) or same else None, cube if same else None))
        if nxt is None:
            break
        n = int(np.ceil(np.sum(np.abs(nxt[0] - q) * shapes.levers) / shapes.margin_mm))
        if n > 1:
            qs.append(q + (nxt[0] - q) * (np.arange(1, n) / n)[:, None])
            owner.extend([i] * (n - 1))
            on_path.extend([True] * (n - 1))
    return np.concatenate(qs), np.array(owner), np.array(on_path), touch


def check_path(cfg: CellConfig, poses: list[tuple[np.ndarray, str, int]], chunk: int = 4096) -> CollisionReport:
    """Check every pose of ``poses`` and every path between consecutive ones (joint-space samples);
    stops at the first clash, else reports the closest approach."""
    t0 = time.perf_counter()
    shapes, point_cube = cell_shapes(cfg)
    checker = _Checker(cfg, shapes)
    Q, owner, on_path, touch = _samples(shapes, poses, point_cube)
    clash = None
    best: dict[bool, tuple] = {}  # a touch pair or not: (clearance, a, b, sample, limit)
    mv, fx, margin = shapes.moving, shapes.fixed, shapes.margin_mm
    for start in range(0, len(Q), chunk):
        W = checker.placed(chain_frames(cfg.model, Q[start:start + chunk], setup=False))
        near_mm, near_mf = checker.screen(W, 2 * margin)
        for k in np.flatnonzero(near_mm.any(axis=1) | near_mf.any(axis=1)):
            n = start + k
            touched = touch[owner[n]][int(on_path[n])]
            todo = [(mv[i], mv[j], W[k, i], W[k, j]) for i, j in checker.mm[near_mm[k]]]
            todo += [(mv[i], fx[j], W[k, i], fx[j].local) for i, j in checker.mf[near_mf[k]]]
            for a, b, Wa, Wb in todo:
                limit = margin
                if touched is not None and b.group == touched:
                    if a.group == "tip":
                        continue  # the tips press on the cube they touch
                    if a.group == "head":
                        limit = TOUCH_MARGIN_MM
                d = checker.clearance(a, b, Wa, Wb)
                key = limit != margin
                if d < 2 * margin and (key not in best or d < best[key][0]):  # beyond: unmeasured
                    best[key] = (d, a, b, n, limit)
                if d < limit:
                    clash = best[key]
                    break
            if clash is not None:
                break
        if clash is not None:
            break

    def named(hit) -> Clash | None:
        if hit is None:
            return None
        d, a, b, n, limit = hit
        return Clash(a.name, b.name, _where(poses, int(owner[n]), bool(on_path[n])), d, limit)

    return CollisionReport(len(poses), len(Q), named(clash), shapes.margin_mm, named(best.get(False)),
                           named(best.get(True)), time.perf_counter() - t0)


def check_plan(cfg: CellConfig, plan: Plan, with_upload: bool = True) -> CollisionReport:
    """Refuse (ConfigError, exit 2) a plan any of whose poses or paths collides, naming the pair, the
    step and the clearance; the report of a clear plan."""
    report = check_path(cfg, plan_path(cfg, plan, with_upload))
    if report.clash is not None:
        raise ConfigError(f"the plan collides: {report.clash.describe()}; nothing was moved. "
                          f"Move the obstacle or the body, change [limits] or [plan], or state the robot's link "
                          f"radii in its file's [collision] table (docs/collision.md)")
    return report
