"""The cell's collision shapes (issue 40), all in the robot's base frame (docs/collision.md):

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

A shape is a primitive or a mesh riding on one frame of the chain (or fixed); :func:`fcl_shape` makes
it python-fcl's geometry. The check of poses and paths between them stands above
(:mod:`station.cell.plan.collision`); the vias and the SCARA's travel height read the head's shapes
here (:func:`head_shapes`, :func:`head_depth_mm`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from station.cell.config.cell_config import CellConfig
from station.cell.plan.assembly import nominal_contact
from station.core.kinematics.transforms import invert, pose_to_matrix
from station.core.probe.geometry import default_probe_head
from station.errors import ConfigError
from station.io.robot.urdf_collision import LinkGeometry

__all__ = ["Shape", "CellShapes", "cell_shapes", "default_radii", "head_shapes", "head_depth_mm", "bounding_capsule",
           "fcl_shape", "DEFAULT_RADIUS_FRACTION"]

#: default link radius as a fraction of the robot's size (the sum of its link offsets): 4 % gives
#: 58 mm on the PUMA 560's 1.45 m and 57 mm on a 600 mm SCARA with its 820 mm column, about an
#: industrial arm's half-width (a PUMA's forearm is ~110 mm across)
DEFAULT_RADIUS_FRACTION = 0.04


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

