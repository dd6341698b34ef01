"""Plans that cannot hit anything (issue 40): the cell's collision shapes and the check of every
commanded pose and every path between consecutive poses, before the first motion.

Shapes, all in the robot's base frame (docs/collision.md):

* **the robot's links**: one capsule per link along its transform's offset, split in two where the
  offset has a part along the joint axis and one across it (a DH link's d, then its a), with the
  radius the robot file's ``[collision] radius_mm`` states, else :func:`default_radii`; a URDF link
  with ``<collision>`` elements gets those instead (boxes, cylinders, spheres, meshes as fcl's BVH
  models; :mod:`station.io.robot.urdf_collision`), a mesh file not found is refused;
* **the probe head**: a capsule per probe from its tip back along its axis by its stroke plus the
  tip's diameter (the probe's body), and the mount from the flange to the head frame;
* **the body**: every cube (from its measuring points' corner frames and ``[body] cube_edge_mm``) and
  the pillar under it down to z = 0 of the body frame. No plate: the body file does not give one, and
  a guessed plate (the cubes' footprint grown by one edge) refused cells whose upper arm passes over
  its edge; a plate or a table is an ``[[obstacle]]``;
* **the cell's fixed obstacles**: ``[[obstacle]]`` boxes and cylinders.

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
"""

from __future__ import annotations

import dataclasses
import re
import time
import weakref
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from station.cell.config.cell_config import CellConfig
from station.cell.plan.assembly import Plan
from station.core.kinematics.forward import chain_frames
from station.core.kinematics.transforms import invert, pose_to_matrix
from station.errors import ConfigError
from station.io.robot.urdf_collision import LinkGeometry

__all__ = ["Shape", "CellShapes", "Clash", "CollisionReport", "cell_shapes", "default_radii", "check_path",
           "check_plan", "plan_path", "moves_clear", "poses_clear", "fcl_available", "TOUCH_MARGIN_MM", "head_shapes",
           "head_depth_mm"]

#: the least clearance [mm] of the probes' bodies (their tips excepted) from the cube they touch,
#: during that touch (approach, above the point, touch, retract): the tips press on its faces, the
#: bodies behind them must not (every other move keeps [plan] collision_margin_mm from that cube too)
TOUCH_MARGIN_MM = 0.5

#: pairs whose bounding spheres come within this [mm] get the tighter bound (a segment in a box): a
#: loose bound far away would only make the path's bisection halve stretches that are clear
NEAR_MM = 100.0

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
    (edges), "cylinder" (radius, height), "sphere" (radius) or "mesh" (``mesh``: vertices (m, 3) [mm]
    and triangles (k, 3) about its centre; size = the radius and length of a cylinder along local z
    that holds it); ``local`` (4, 4) its centre in the frame it rides on: ``frame`` (an index into the
    chain's frames; -1: the robot base, fixed); ``group`` what it belongs to ("link:A2", "head",
    "cube:3", "obstacle:column"); ``name`` for people."""

    name: str
    kind: str
    size: tuple[float, ...]
    local: np.ndarray
    frame: int
    group: str
    mesh: tuple[np.ndarray, np.ndarray] | None = field(default=None, compare=False, repr=False)


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
    out = [s for s in out if s.kind == "capsule"]
    geometry = spec.geometry if spec is not None else ()
    if not geometry:
        return out, names
    urdf = {g: [_urdf_shape(x) for x in geometry if x.link == g[len("link:"):]] for g in dict.fromkeys(
        [f"link:{n}" for n in names])}
    # a link with <collision> elements: those instead of its capsules, in the chain's order
    return [s for g, own in urdf.items() for s in (own or [c for c in out if c.group == g])], names


def _urdf_shape(g: LinkGeometry) -> Shape:
    """A URDF ``<collision>`` (:class:`station.io.robot.urdf_collision.LinkGeometry`) as a shape; a
    mesh whose file was not found is refused (the check never leaves a link out)."""
    name = f"link {g.link} ({g.urdf_link}'s {g.kind})"
    if g.kind != "mesh":
        return Shape(name, g.kind, g.size, g.local, g.frame, f"link:{g.link}")
    if g.missing is not None:
        raise ConfigError(f"{g.missing}: the mesh file is not found, so link {g.urdf_link!r} cannot be checked for "
                          f"collisions (the check does not leave it out). Put the file where the URDF names it "
                          f"(package://PKG/REL: REL in a folder PKG beside the URDF or in a folder above it, or in "
                          f"the folder PKG itself; a plain path: relative to the URDF), or delete that <collision> "
                          f"element: a link without one gets the station's capsule (docs/collision.md)")
    v, faces = g.vertices, g.faces
    assert v is not None and faces is not None  # a mesh that was found has both
    centre = (v.min(axis=0) + v.max(axis=0)) / 2
    v = v - centre
    local = g.local.copy()
    local[:3, 3] = g.local[:3, :3] @ centre + g.local[:3, 3]
    size = (float(np.max(np.hypot(v[:, 0], v[:, 1]))), 2 * float(np.max(np.abs(v[:, 2]))))
    return Shape(name, "mesh", size, local, g.frame, f"link:{g.link}", (v, faces))


def bounding_capsule(s: Shape) -> tuple[float, float]:
    """Half the length and the radius of a capsule along the shape's local z that holds it [mm] (the
    screen's lower bounds and the path's levers take every moving shape as that capsule)."""
    if s.kind in ("capsule", "cylinder", "mesh"):
        return s.size[1] / 2, s.size[0]
    if s.kind == "box":
        return s.size[2] / 2, float(np.hypot(s.size[0] / 2, s.size[1] / 2))
    return 0.0, s.size[0]


def head_shapes(cfg: CellConfig) -> list[Shape]:
    """The probes and the mount, riding on the last frame (the head frame MKKS). Each probe is two
    capsules of its tip's radius: its plunger ("tip", from the free tip, half the stroke beyond the
    mount point, back to the tip pressed fully in, half the stroke behind it: what presses on the
    face at a touch) and its body ("head", from there back by the stroke: what must never touch the
    cube)."""
    from station.core.probe.geometry import default_probe_head

    head = cfg.head if cfg.head is not None else default_probe_head(cube_edge_mm=cfg.cube_edge_mm)
    last = len(cfg.model.transforms) - 1
    out = []
    for i in range(head.n_probes):
        mount, d = head.mount_points[i], head.directions[i]
        r, stroke = float(head.tip_radii[i]), float(head.strokes[i])
        # the plunger travels the whole stroke: its tip, pressed fully in, lies half the stroke
        # behind the mount point, and the body begins there (with the body one tip diameter behind
        # the mount point, a probe reading 1.4 mm in on a turned head put its body into the cube)
        neck = mount - d * (stroke / 2 + r)
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
    for s in head_shapes(cfg):
        half = s.local[:3, 2] * (s.size[1] / 2 if s.kind == "capsule" else 0.0)
        for end in (s.local[:3, 3] + half, s.local[:3, 3] - half):
            low = max(low, float((c - end) @ up) + s.size[0])
    return low


def _body_shapes(cfg: CellConfig) -> tuple[list[Shape], tuple[str, ...]]:
    """The cubes and their pillars in the body frame, and each measuring point's cube (its group)."""
    e = cfg.cube_edge_mm
    centre = np.eye(4)
    centre[:3, 3] = [e / 2, e / 2, -e / 2]  # the cube lies in x, y >= 0, z <= 0 of its corner frame
    # the corners of one cube give its centre only to within the CMM's and the file's rounding (init's
    # template: 0.1 mm apart; an edge stated 0.5 mm off: 0.7 mm), so a centre within a quarter edge of
    # a known one is that cube (two cubes' centres are at least an edge apart, or they overlap); a
    # rounded key split one cube in two, and the touch of one corner then clashed with the "other"
    tol = 0.25 * e
    cubes: list[tuple[np.ndarray, str]] = []
    of_point = []
    for pid, M in zip(cfg.point_ids, cfg.body_points):
        C = M @ centre
        k = next((i for i, (D, _) in enumerate(cubes) if np.linalg.norm(D[:3, 3] - C[:3, 3]) <= tol), None)
        if k is None:
            cubes.append((C, pid))
            k = len(cubes) - 1
        of_point.append(f"cube:{k}")
    out = []
    for k, (C, pid) in enumerate(cubes):
        out.append(Shape(f"cube of {pid}", "box", (e, e, e), C, -2, f"cube:{k}"))
        bottom = C[2, 3] - e / 2
        if bottom > 1e-6:  # a pillar from z = 0 to the cube's underside
            P = C.copy()
            P[2, 3] = bottom / 2
            out.append(Shape(f"pillar of {pid}", "box", (e, e, bottom), P, -2, f"cube:{k}"))
    return out, tuple(of_point)


def _obstacle_shapes(cfg: CellConfig) -> list[Shape]:
    return [Shape(f"obstacle {o.name!r}", o.shape, o.size, o.pose, -2 if o.frame == "body" else -1,
                  f"obstacle:{o.name}") for o in cfg.obstacles]


# --- the shapes of a cell ---------------------------------------------------------------------

def cell_shapes(cfg: CellConfig) -> tuple[CellShapes, tuple[str, ...]]:
    """Every shape of the cell (fixed ones placed in the robot's base frame) and each measuring
    point's cube group."""
    links, names = _link_shapes(cfg)
    head = head_shapes(cfg)
    last = f"link:{names[-1]}"
    if any(s.group == last for s in links):
        # the mount stands in for the last link's reach; where the URDF gives that link's own shapes,
        # it is part of that link (its start, on the last joint's axis, lies in the link before)
        head = [dataclasses.replace(s, group=last) if s.name == "head mount" else s for s in head]
    body, point_cube = _body_shapes(cfg)
    base_from_body = invert(pose_to_matrix(cfg.model.nominal[:6]))
    fixed = [Shape(s.name, s.kind, s.size, base_from_body @ s.local if s.frame == -2 else s.local, -1, s.group)
             for s in (*body, *_obstacle_shapes(cfg))]
    chain = [g for g in dict.fromkeys(s.group for s in links)] + ["head"]
    allowed = {frozenset(p) for p in zip(chain, chain[1:])}
    allowed |= _joined_over_a_short_link(links + head, chain)
    allowed |= {frozenset(("tip", *(p - {"head"}))) for p in list(allowed) if "head" in p and len(p) == 2}  # the tips ride on the head
    allowed |= {frozenset(("tip", "head")), frozenset(("tip", chain[-2]))}  # the tips ride on the head
    spec = cfg.robot_collision
    allowed |= {frozenset((f"link:{a}", f"link:{b}")) for a, b in (spec.allowed_pairs if spec is not None else ())}
    base = f"link:{names[0]}"  # the base stands where it stands: nothing fixed is checked against it
    allowed |= {frozenset((base, s.group)) for s in fixed}
    return CellShapes(tuple(links + head), tuple(fixed), frozenset(allowed), _levers(cfg, links + head),
                      cfg.plan.collision_margin_mm), point_cube


def _joined_over_a_short_link(links: list[Shape], chain: list[str]) -> set[frozenset[str]]:
    """The pairs of links two apart in the chain whose capsules meet at the link between them by
    construction: that link shorter than the two radii together (the IRB 2600's 150 mm shoulder
    offset between its base and upper arm, each 92 mm thick by default, always overlapped; a KR 6's
    80 mm flange link between its forearm and the head's mount). As a zero-length link joins its
    neighbours, so does a short one."""
    # only a link of capsules: a URDF link's own shapes (boxes, meshes) do not meet by construction
    length = {g: sum(s.size[1] for s in links if s.group == g and s.kind == "capsule") for g in chain
              if all(s.kind in ("capsule", "sphere") for s in links if s.group == g)}
    radius = {g: max((bounding_capsule(s)[1] for s in links if s.group == g), default=0.0) for g in chain}
    return {frozenset((a, c)) for a, b, c in zip(chain, chain[1:], chain[2:])
            if b in length and a in radius and c in radius and length[b] <= radius[a] + radius[c]}


def _levers(cfg: CellConfig, moving: list[Shape]) -> np.ndarray:
    """Per joint, an upper bound of how far any point of a moving shape lies from the joint's axis
    [mm] (1 for a prismatic joint: a point moves as far as the joint): the length of every link
    beyond it plus the head's reach from the flange plus the largest radius (a capsule's surface
    lies that far off its axis)."""
    tr = cfg.model.transforms
    p = cfg.model.nominal.reshape(-1, 6)
    seg = np.linalg.norm(p[:, :3], axis=1)
    reach = max((float(np.linalg.norm(s.local[:3, 3])) + s.size[-1] / 2 for s in moving if s.group == "head"),
                default=0.0)
    reach += max((s.size[0] for s in moving if s.kind in ("capsule", "sphere")), default=0.0)
    # a URDF link's shape may stand off its link's line: its centre's distance plus its bound
    reach = max([reach, *(float(np.linalg.norm(s.local[:3, 3])) + sum(bounding_capsule(s)) for s in moving
                          if s.kind in ("box", "cylinder", "mesh"))])
    out, j = [], 0
    for t, spec in enumerate(tr):
        if spec.joint is None:
            continue
        out.append(1.0 if spec.joint == "prismatic" else float(np.sum(seg[t + 1:])) + reach)
        j += 1
    return np.array(out)


def fcl_shape(fcl: Any, s: Shape, grow: float = 0.0) -> Any:
    """``s`` as an fcl geometry, ``grow`` mm fatter (a mesh cannot be grown: only with 0)."""
    r = s.size
    if s.kind == "capsule":
        return fcl.Capsule(r[0] + grow, r[1])
    if s.kind == "sphere":
        return fcl.Sphere(r[0] + grow)
    if s.kind == "cylinder":
        return fcl.Cylinder(r[0] + grow, r[1] + 2 * grow)
    if s.kind == "mesh" and s.mesh is not None:  # a BVH of its triangles (cannot be grown: grow is 0)
        m = fcl.BVHModel()
        v, faces = s.mesh
        m.beginModel(len(v), len(faces))
        m.addSubModel(np.ascontiguousarray(v, dtype=float), np.ascontiguousarray(faces, dtype=np.int32))
        m.endModel()
        return m
    return fcl.Box(*(v + 2 * grow for v in r))


class _Checker:
    """The checked pairs, a cheap screen of every sample in numpy (a lower bound of each pair's
    distance: two bounding spheres, then a moving capsule's segment boxed in the other's frame), and
    fcl's exact distance (the depth where they overlap) of each pair the screen leaves within its
    watch distance (so the plan's closest approach is reported even where nothing clashes)."""

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


def plan_path(cfg: CellConfig, plan: Plan, with_upload: bool = True) -> list[tuple[np.ndarray, str, int]]:
    """Every pose a run commands, in order: (joints, what it is, the measuring point it touches),
    the via poses between two measurements included (:func:`station.cell.plan.vias.travel_vias`: a
    depart and the stages of a long move belong to the measurement the head leaves, an arrive to the
    one it comes to). The first move, from wherever the robot stands to the first approach, is not
    known before the run."""
    from station.cell.plan.measurement_plan import all_motion_poses, retract_offset, retracted
    from station.cell.plan.via_memo import memo_travel_vias
    from station.cell.plan.vias import lifted_many

    steps = plan.run_steps(cfg.plan.verification_cycles, with_oracle=False, with_upload=with_upload)
    if not steps:
        return []
    lifts: list = [None] * len(steps)
    back = None
    if not cfg.model.is_scara:  # the retract poses (each step's approach and retract) and their lifts at once
        from station.cell.plan.articulated import retract_poses

        back, _ok = retract_poses(cfg, np.array([s.q for s in steps]))
        up, reached = lifted_many(cfg, back)
        lifts = [u if r else None for u, r in zip(up, reached)]
    out: list[tuple[np.ndarray, str, int]] = []
    last = None  # the previous step's label, point and lift
    for k, s in enumerate(steps):
        q = s.q
        name = f"step {s.index + 1} ({s.label})"
        if back is None:
            moves = all_motion_poses(cfg, q, s.direction)
            leave = retracted(cfg, q)
        else:  # an arm's approach and retract are both its retract pose (all_motion_poses, retracted)
            moves, leave = [back[k], q + retract_offset(cfg), q], back[k]
        if last is not None:
            for v, what in memo_travel_vias(cfg, out[-1][0], moves[0], None if cfg.model.is_scara else (last[2], lifts[k])):
                if what == "arrive":  # the descent to the approach is part of the next touch
                    out.append((v, f"{name}: {what}", s.point))
                else:  # the depart and the stages of a long move, away from any cube
                    out.append((v, f"{last[0]}: {what}", last[1] if what == "depart" else -1))
        names: tuple[str, ...] = ("approach", "above the point", "touch")
        if back is None and s.kind.is_verification:
            # a SCARA's verification touch is a Cartesian target the controller reaches straight
            # from the approach (station/cell/run/runner.py _touch): no pose above the point
            moves, names = [moves[0], moves[2]], ("approach", "touch")
        for what, qq in zip(names, moves):
            out.append((np.asarray(qq, dtype=float), f"{name}: {what}", s.point))
        out.append((np.asarray(leave, dtype=float), f"{name}: retract", s.point))
        last = (name, s.point, lifts[k])
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
    touch. Labels as :func:`plan_path` writes them ("step N (…): what")."""
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


#: the labels of the via poses (station/cell/plan/vias.py)
_VIA_NAMES = ("depart", "arrive", "arm upright", "turned upright", "first")


def check_plan(cfg: CellConfig, plan: Plan, with_upload: bool = True) -> CollisionReport:
    """Refuse (ConfigError, exit 2) a plan any of whose poses or paths collides, naming the pair, the
    step and the clearance; the report of a clear plan. Without python-fcl it refuses too (the
    station does not skip the check)."""
    _fcl()
    poses = plan_path(cfg, plan, with_upload)
    report = check_path(cfg, poses)
    report = dataclasses.replace(report, vias=sum(1 for p in poses if p[1].endswith(_VIA_NAMES)))
    if report.clash is not None:
        raise ConfigError(f"the plan collides: {report.clash.describe()} ({report.clashing_moves} poses or moves "
                          f"collide in all); nothing was moved. Move the obstacle or the body, change [limits] or "
                          f"[plan], or state the robot's link radii in its file's [collision] table "
                          f"(docs/collision.md)")
    return report
