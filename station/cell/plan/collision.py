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
           "check_plan", "plan_path", "fcl_available"]

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
    """The probes' bodies and the mount, riding on the last frame (the head frame MKKS)."""
    from station.core.probe.geometry import default_probe_head

    head = cfg.head if cfg.head is not None else default_probe_head(cube_edge_mm=cfg.cube_edge_mm)
    last = len(cfg.model.transforms) - 1
    out = []
    for i in range(head.n_probes):
        tip = head.mount_points[i]
        r = float(head.tip_radii[i])
        back = tip - head.directions[i] * (float(head.strokes[i]) + 2 * r)
        out.append(_segment(f"probe {head.label(i)}", tip, back, r, last, "head"))
    K = pose_to_matrix(cfg.model.nominal.reshape(-1, 6)[-1])
    flange = invert(K)[:3, 3]  # the flange's origin in MKKS
    r_mount = float(np.max(np.linalg.norm(head.mount_points, axis=1))) / 4
    out.append(_segment("head mount", flange, np.zeros(3), r_mount, last, "head"))
    return [s for s in out if s.kind in ("capsule", "sphere")]


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
    """The shapes as fcl objects, grown by half the margin, in two broad-phase managers."""

    def __init__(self, cfg: CellConfig, shapes: CellShapes):
        self.fcl = fcl = _fcl()
        self.cfg, self.shapes = cfg, shapes
        half = shapes.margin_mm / 2
        g_moving = [_grown(fcl, s, half) for s in shapes.moving]
        g_fixed = [_grown(fcl, s, half) for s in shapes.fixed]
        self.moving = [fcl.CollisionObject(g, _tf(fcl, s.local)) for g, s in zip(g_moving, shapes.moving)]
        fixed = [fcl.CollisionObject(g, _tf(fcl, s.local)) for g, s in zip(g_fixed, shapes.fixed)]
        # a contact names its geometries: the shapes they were made for
        self.by_geom = {id(g): s for g, s in zip([*g_moving, *g_fixed], [*shapes.moving, *shapes.fixed])}
        self._keep = (g_moving, g_fixed)  # the ids above stay valid while the geometries live
        self.m_moving = fcl.DynamicAABBTreeCollisionManager()
        self.m_moving.registerObjects(self.moving)
        self.m_moving.setup()
        self.m_fixed = fcl.DynamicAABBTreeCollisionManager()
        self.m_fixed.registerObjects(fixed)
        self.m_fixed.setup()

    def place(self, frames: np.ndarray) -> None:
        """Put the moving shapes where the chain's ``frames`` (nt, 4, 4) carry them."""
        for o, s in zip(self.moving, self.shapes.moving):
            if s.frame >= 0:
                o.setTransform(_tf(self.fcl, frames[s.frame] @ s.local))
        self.m_moving.update()

    def clash(self, touched: str | None, frames: np.ndarray) -> tuple[Shape, Shape, float] | None:
        """The first pair closer than the margin where the shapes are placed, with its clearance, or
        None. A grown box's corners reach beyond the margin: each pair found is measured again."""
        fcl = self.fcl
        for other in (None, self.m_fixed):
            data = fcl.CollisionData(request=fcl.CollisionRequest(num_max_contacts=10_000, enable_contact=False))
            if other is None:
                self.m_moving.collide(data, fcl.defaultCollisionCallback)
            else:
                self.m_moving.collide(other, data, fcl.defaultCollisionCallback)
            for c in data.result.contacts:
                a, b = self.by_geom[id(c.o1)], self.by_geom[id(c.o2)]
                pair = frozenset((a.group, b.group))
                if a.group == b.group or pair in self.shapes.allowed or pair == frozenset(("head", touched)):
                    continue
                d = self.clearance(a, b, frames)
                if d < self.shapes.margin_mm:
                    return a, b, d
        return None

    def clearance(self, a: Shape, b: Shape, frames: np.ndarray) -> float:
        """The true (not grown) distance [mm] between ``a`` and ``b`` placed by ``frames``; negative:
        the depth by which they overlap."""
        fcl = self.fcl
        objs = [fcl.CollisionObject(_grown(fcl, s, 0.0), _tf(fcl, frames[s.frame] @ s.local if s.frame >= 0
                                                              else s.local)) for s in (a, b)]
        return float(fcl.distance(objs[0], objs[1], fcl.DistanceRequest(enable_signed_distance=True),
                                  fcl.DistanceResult()))


def _tf(fcl, T: np.ndarray):
    return fcl.Transform(np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(T[:3, 3]))


# --- the check ----------------------------------------------------------------------------------

@dataclass(frozen=True)
class Clash:
    """Where a plan would collide: the two shapes, the step and the move, the clearance [mm]."""

    a: str
    b: str
    where: str
    clearance_mm: float

    def describe(self, margin_mm: float) -> str:
        return (f"{self.a} and {self.b} come within {self.clearance_mm:.1f} mm of each other "
                f"({'overlapping' if self.clearance_mm < 0 else 'under the margin'} of {margin_mm:g} mm) {self.where}")


@dataclass(frozen=True)
class CollisionReport:
    """What the check found: poses and path samples checked, the first clash (None: clear), the
    margin [mm] and the time the check took [s]."""

    poses: int
    samples: int
    clash: Clash | None
    margin_mm: float
    seconds: float = field(compare=False, default=0.0)


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


def _samples(shapes: CellShapes, poses: list[tuple[np.ndarray, str, int]], point_cube: tuple[str, ...]):
    """The joints of every pose and of the path to the next one, at a step that moves no point of
    the arm by more than the margin; with each sample what it is and the cube the head may touch."""
    qs, where, touched = [], [], []
    for i, (q, label, point) in enumerate(poses):
        nxt = poses[i + 1] if i + 1 < len(poses) else None
        step = label.split(":")[0]
        same = nxt is not None and nxt[1].split(":")[0] == step  # within one touch: the head meets its cube
        cube = point_cube[point] if point >= 0 else None
        qs.append(q)
        where.append(f"at {label}")
        touched.append(cube if label.endswith(("touch", "above the point")) or same else None)
        if nxt is None:
            break
        n = int(np.ceil(np.sum(np.abs(nxt[0] - q) * shapes.levers) / shapes.margin_mm))
        for k in range(1, n):
            qs.append(q + (nxt[0] - q) * k / n)
            where.append(f"on the move from {label} to {nxt[1].split(': ', 1)[-1]}"
                         + ("" if same else f" ({nxt[1].split(':')[0]})"))
            touched.append(cube if same else None)
    return np.array(qs), where, touched


def check_path(cfg: CellConfig, poses: list[tuple[np.ndarray, str, int]], chunk: int = 4096) -> CollisionReport:
    """Check every pose of ``poses`` and every path between consecutive ones (joint-space samples);
    stops at the first clash."""
    t0 = time.perf_counter()
    shapes, point_cube = cell_shapes(cfg)
    checker = _Checker(cfg, shapes)
    Q, where, touched = _samples(shapes, poses, point_cube)
    clash = None
    for start in range(0, len(Q), chunk):
        frames = chain_frames(cfg.model, Q[start:start + chunk], setup=False)
        for k in range(len(frames)):
            checker.place(frames[k])
            hit = checker.clash(touched[start + k], frames[k])
            if hit is not None:
                clash = Clash(hit[0].name, hit[1].name, where[start + k], hit[2])
                break
        if clash is not None:
            break
    return CollisionReport(len(poses), len(Q), clash, shapes.margin_mm, time.perf_counter() - t0)


def check_plan(cfg: CellConfig, plan: Plan, with_upload: bool = True) -> CollisionReport:
    """Refuse (ConfigError, exit 2) a plan any of whose poses or paths collides, naming the pair, the
    step and the clearance; the report of a clear plan."""
    report = check_path(cfg, plan_path(cfg, plan, with_upload))
    if report.clash is not None:
        raise ConfigError(f"the plan collides: {report.clash.describe(report.margin_mm)}; nothing was moved. "
                          f"Move the obstacle or the body, change [limits] or [plan], or state the robot's link "
                          f"radii in its file's [collision] table (docs/collision.md)")
    return report
