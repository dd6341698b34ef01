"""The simulated controller's own collision check (issue 40): every commanded motion, its target
and the joint-space path to it, against the cell as the controller holds it.

A real controller with a safety option (ABB SafeMove, KUKA SafeOperation, FANUC DCS) refuses a
motion its cell model says collides; the simulated one does the same, so that a planning slip of
the station fails the end-to-end tests instead of passing through the cubes unseen. The check is
independent of the station's (``station/cell/plan/collision.py``, not imported): its own shapes,
built here from the user's files as the simulator reads them, its own kinematics (the robot
file's chain walked as :mod:`simulators.truth_kinematics` documents it, batched), its own
sampling. Only the collision library is shared: python-fcl decides every pair the numpy screen
cannot rule out (a lower bound of each pair's distance: a capsule's segment boxed in the other
shape's frame).

The cell as the controller holds it, in the robot base frame (mm): the robot file's NOMINAL
chain, ``[robot] setup`` as the body's place, the body's cubes as its CMM report gives them,
``[[obstacle]]`` as the cell file draws them - a safety controller is configured with the drawn
layout, not the truth. Shapes, each a little inside the station's envelope (docs/collision.md),
so that a plan the station clears with its margin is never refused for the envelope's
difference, while a real crash (a head through a cube, a wrist through a column) is:

* links: per link a capsule along its transform's offset, first along the joint axis, then
  across (a DH link's d, then its a); radius the robot file's ``[collision] radius_mm``, else
  :data:`LINK_RADIUS_FRACTION` of the robot's size (the station assumes 4 %);
* head: per probe its plunger (the tip ball over its whole stroke: it touches the cubes, that is
  its job, so it is never checked against them) and its housing (behind the plunger's travel, by
  half the stroke); the mount from the flange to the head frame (radius a fifth of the probes'
  farthest mount point; the station takes a quarter);
* body: every cube (from its measuring points' corner frames and the cube edge) and the pillar
  under it down to z = 0 of the body frame; no plate, as the body file gives none (the station's
  model has none either: a plate or a table is an ``[[obstacle]]`` of the cell file);
* obstacles: ``[[obstacle]]`` boxes and cylinders (axis along their z) in the body or base frame.

Never checked: a link and its neighbour in the chain (zero-length links skipped), the pairs the
robot file's ``[collision] allowed_pairs`` names, the head and the last link, the base link and
anything fixed (it stands where it stands). Margin 0: shapes that overlap collide. A path is
sampled in joint space (the controller interpolates linearly in joint space) at a step that moves
no point of the arm by more than :data:`STEP_MM`; stretches of :data:`COARSE` steps that no pair
can cross (every pair's lower bound at both ends beyond the stretch's motion) are skipped.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from simulators.truth_kinematics import inverse, pose_matrix

__all__ = ["Part", "Hit", "CellCollision", "LINK_RADIUS_FRACTION", "STEP_MM", "COARSE"]

#: link radius as a fraction of the robot's size (the sum of its transforms' offsets) when the
#: robot file states none: slimmer than the station's 4 %, so only a planning slip is refused
LINK_RADIUS_FRACTION = 0.03
#: the largest distance [mm] any point of the arm moves between two checked samples of a path
STEP_MM = 2.0
#: a path is first looked at every COARSE-th sample (conservative advancement, ``check_move``)
COARSE = 10
#: pairs whose bounding spheres come within this [mm] get the tighter bound (a segment in a box);
#: farther ones keep the spheres' gap, a lower bound too (no stretch lets a point move this far)
NEAR_MM = 100.0


@dataclass(frozen=True)
class Part:
    """One shape: ``kind`` "capsule" (radius, length; axis along local z), "sphere" (radius), "box"
    (edges) or "cylinder" (radius, height); ``local`` (4, 4) its centre in the frame it rides on,
    ``frame`` (the chain's frame after transform ``frame``; -1: fixed in the robot base frame);
    ``group`` what it belongs to ("link:A2", "plunger", "head", "cube", "obstacle:NAME")."""

    name: str
    kind: str
    size: tuple[float, ...]
    local: np.ndarray
    frame: int
    group: str


@dataclass(frozen=True)
class Hit:
    """A collision the check found: the two parts, the overlap depth [mm] (fcl's penetration depth),
    where along the motion (0: where the robot stands, 1: the target) and the joints there."""

    a: str
    b: str
    depth_mm: float
    fraction: float
    joints: tuple[float, ...]

    def describe(self) -> str:
        where = "at the target" if self.fraction >= 1.0 else f"{100 * self.fraction:.0f} % along the path"
        return f"{self.a} hits {self.b} {where} ({self.depth_mm:.1f} mm deep)"


def _capsule(name: str, a: np.ndarray, b: np.ndarray, r: float, frame: int, group: str) -> Part | None:
    """A capsule from ``a`` to ``b`` (3,) in ``frame``; None where they coincide."""
    d = np.asarray(b, float) - np.asarray(a, float)
    length = float(np.linalg.norm(d))
    if length < 1e-9:
        return None
    z = d / length
    helper = np.array([0.0, 0.0, 1.0]) if abs(z[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    local = np.eye(4)
    local[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    local[:3, 3] = (np.asarray(a, float) + np.asarray(b, float)) / 2
    return Part(name, "capsule", (float(r), length), local, frame, group)


def _box(name: str, centre: np.ndarray, size: tuple[float, ...], group: str) -> Part:
    return Part(name, "box", tuple(float(v) for v in size), centre, -1, group)


class CellCollision:
    """The controller's collision model of one cell. ``kinds``: per transform of the robot file
    None, "revolute" or "prismatic"; ``params`` (6 · transforms,) its nominal numbers [mm, rad]
    (the set-up transform first, left out: the controller works in the base frame)."""

    def __init__(self, kinds: tuple[str | None, ...], params: np.ndarray, moving: list[Part], fixed: list[Part],
                 skip: set[frozenset[str]], step_mm: float = STEP_MM):
        import fcl

        self._fcl = fcl
        self.kinds = tuple(kinds)
        p = np.asarray(params, dtype=float).reshape(len(kinds), 6)
        self._statics = pose_matrix(p[1:])
        self.moving, self.fixed = tuple(moving), tuple(fixed)
        self.step_mm = float(step_mm)
        self.levers = self._levers(p)

        def checked(x: Part, y: Part) -> bool:
            return x.group != y.group and frozenset((x.group, y.group)) not in skip

        mv, fx = self.moving, self.fixed
        self._mm = [(i, j) for i in range(len(mv)) for j in range(i + 1, len(mv)) if checked(mv[i], mv[j])]
        self._mf = [(i, j) for i in range(len(mv)) for j in range(len(fx)) if checked(mv[i], fx[j])]
        self._half = np.array([m.size[1] / 2 if m.kind == "capsule" else 0.0 for m in mv])
        self._radius = np.array([m.size[0] for m in mv])
        self._extent = [self._half_extent(s) for s in (*mv, *fx)]
        self._fixed_inv = [inverse(s.local) for s in fx]
        # the screen's pairs as index arrays, the second's frame and half extents per pair: one
        # numpy expression per kind of pair and per sample batch (a loop over the fixed parts, or
        # per-pair lists, cost 7 ms a move, most of a run's check)
        mm = np.array(self._mm, dtype=int).reshape(-1, 2)
        mf = np.array(self._mf, dtype=int).reshape(-1, 2)
        self._mm_i, self._mm_j = mm.T
        self._mm_half = np.array([self._extent[k] for k in self._mm_j]).reshape(-1, 3)
        self._mf_i, self._mf_j = mf.T
        inv = np.array(self._fixed_inv).reshape(-1, 4, 4)
        self._mf_R, self._mf_t = inv[self._mf_j, :3, :3], inv[self._mf_j, :3, 3]
        self._mf_half = np.array([self._extent[len(mv) + k] for k in self._mf_j]).reshape(-1, 3)
        self._frame_of = np.array([m.frame for m in mv], dtype=int)
        self._local = np.array([m.local for m in mv]).reshape(-1, 4, 4)
        # bounding spheres: a moving part's about its centre, a fixed one's about its box's
        self._ball = self._half + self._radius
        self._fixed_centre = np.array([s.local[:3, 3] for s in fx]).reshape(-1, 3)
        self._fixed_ball = np.array([np.linalg.norm(self._extent[len(mv) + k]) for k in range(len(fx))])
        self._objs = [fcl.CollisionObject(self._geometry(s), self._tf(s.local)) for s in (*mv, *fx)]
        #: moves checked and samples checked since the start (what the benchmark divides by)
        self.moves_checked = 0
        self.samples_checked = 0
        self.seconds = 0.0

    # ------------------------------------------------------------------ building
    @classmethod
    def from_config(cls, cfg: Any, step_mm: float = STEP_MM) -> "CellCollision":
        """The model of the cell a parsed cell configuration describes (read by its attributes:
        ``model``, ``head``, ``cube_edge_mm``, ``body_points``, ``obstacles``, ``robot_collision``)."""
        from station.core.probe.geometry import default_probe_head

        model = cfg.model
        kinds = tuple(t.joint for t in model.transforms)
        p = np.asarray(model.nominal, dtype=float).reshape(-1, 6)
        names = [t.name for t in model.transforms]
        spec = getattr(cfg, "robot_collision", None)
        links, groups = _links(kinds, names, p, getattr(spec, "radius_mm", None))
        head = cfg.head if getattr(cfg, "head", None) is not None else default_probe_head(cube_edge_mm=cfg.cube_edge_mm)
        moving = links + _head_parts(head, pose_matrix(p[-1]), len(kinds) - 1)
        base_from_body = inverse(pose_matrix(p[0]))
        fixed = _body_parts(np.asarray(cfg.body_points, dtype=float), float(cfg.cube_edge_mm), base_from_body)
        for o in getattr(cfg, "obstacles", ()):
            local = np.asarray(o.pose, dtype=float)
            if o.frame == "body":
                local = base_from_body @ local
            fixed.append(Part(f"obstacle {o.name!r}", o.shape, tuple(float(v) for v in o.size), local, -1,
                              f"obstacle:{o.name}"))
        skip = {frozenset(pair) for pair in zip(groups, groups[1:])}  # neighbours in the chain
        skip |= _two_apart([*groups, "head"])
        skip |= {frozenset((groups[-1], "head")), frozenset((groups[-1], "plunger")), frozenset(("head", "plunger")),
                 frozenset(("plunger", "cube"))}  # the plungers touch the cubes: that is their job
        skip |= {frozenset((f"link:{a}", f"link:{b}")) for a, b in (getattr(spec, "allowed_pairs", None) or ())}
        skip |= {frozenset((groups[0], f.group)) for f in fixed}  # the base stands where it stands
        return cls(kinds, p.ravel(), moving, fixed, skip, step_mm)

    def _levers(self, p: np.ndarray) -> np.ndarray:
        """Per joint, how far [mm] any moving part may lie from its axis (1 for a prismatic joint):
        the offsets of every transform beyond it plus the head's reach from the tool frame."""
        seg = np.linalg.norm(p[:, :3], axis=1)
        last = len(self.kinds) - 1
        reach = max((float(np.linalg.norm(m.local[:3, 3])) + m.size[-1] / 2 for m in self.moving
                     if m.frame == last), default=0.0)
        return np.array([1.0 if k == "prismatic" else float(np.sum(seg[t + 1:])) + reach
                         for t, k in enumerate(self.kinds) if k is not None])

    def _geometry(self, s: Part):
        fcl, r = self._fcl, s.size
        if s.kind == "capsule":
            return fcl.Capsule(r[0], r[1])
        if s.kind == "sphere":
            return fcl.Sphere(r[0])
        if s.kind == "cylinder":
            return fcl.Cylinder(r[0], r[1])
        return fcl.Box(*r)

    @staticmethod
    def _half_extent(s: Part) -> np.ndarray:
        """Half extents of a box around the part in its own frame."""
        r = s.size
        if s.kind == "capsule":
            return np.array([r[0], r[0], r[0] + r[1] / 2])
        if s.kind == "sphere":
            return np.full(3, r[0])
        if s.kind == "cylinder":
            return np.array([r[0], r[0], r[1] / 2])
        return np.asarray(r, dtype=float) / 2

    def _tf(self, T: np.ndarray):
        return self._fcl.Transform(np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(T[:3, 3]))

    # ------------------------------------------------------------------ kinematics
    def frames(self, Q: np.ndarray) -> np.ndarray:
        """``(n, transforms, 4, 4)``: base ← the frame after each transform (its joint moved), for
        joints ``Q`` ``(n, g)``; frame 0 is the base itself."""
        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        n = len(Q)
        T = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
        out = [T]
        j = 0
        for kind, S in zip(self.kinds[1:], self._statics):
            T = T @ S
            if kind is not None:
                motion = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
                if kind == "revolute":
                    c, s = np.cos(Q[:, j]), np.sin(Q[:, j])
                    motion[:, 0, 0], motion[:, 0, 1], motion[:, 1, 0], motion[:, 1, 1] = c, -s, s, c
                else:
                    motion[:, 2, 3] = Q[:, j]
                T = T @ motion
                j += 1
            out.append(T)
        return np.stack(out, axis=1)

    # ------------------------------------------------------------------ the check
    def samples(self, q0: np.ndarray, q1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The joints checked on the move from ``q0`` to ``q1`` (the target last) and each one's
        fraction of the way."""
        q0, q1 = np.asarray(q0, dtype=float), np.asarray(q1, dtype=float)
        n = max(1, int(np.ceil(float(np.sum(np.abs(q1 - q0) * self.levers)) / self.step_mm)))
        f = np.arange(1, n + 1) / n
        return q0 + (q1 - q0) * f[:, None], f

    def check_move(self, q0: np.ndarray, q1: np.ndarray) -> Hit | None:
        """The first collision on the joint-space path from ``q0`` (where the robot stands) to
        ``q1`` (the target, included), or None: the motion is clear. Conservative advancement: a
        stretch whose ends' lower bounds add up to more than twice what any point can move along it
        cannot hold a contact (each bound falls at most by the relative motion, at most twice
        that). Every :data:`COARSE`-th sample first, and only the stretches left are checked
        sample by sample."""
        t0 = time.perf_counter()
        Q, f = self.samples(q0, q1)
        try:
            return self.check_joints(*self._near_stretches(np.asarray(q0, dtype=float), Q, f))
        finally:
            self.moves_checked += 1
            self.seconds += time.perf_counter() - t0

    def _near_stretches(self, q0: np.ndarray, Q: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The samples of ``Q`` (and their fractions) in the stretches (see :meth:`check_move`) where
        some pair may come closer than the stretch lets any point move."""
        # how far any point of a moving part moves per sample: a revolute joint's step times its
        # lever grown by the thickest part's radius (its surface, not its axis), a prismatic one's
        grow = np.array([0.0 if k == "prismatic" else float(self._radius.max()) for k in self.kinds if k is not None])
        lever = self.levers + grow
        if len(Q) <= 2 * COARSE:  # one look at every sample costs less than a look at the ends first
            return Q, f
        stops = np.unique(np.append(np.arange(COARSE - 1, len(Q), COARSE), len(Q) - 1))
        anchors = np.vstack([q0[None], Q[stops]])
        closest = self._closest(anchors)
        motion = np.abs(np.diff(anchors, axis=0)) @ lever
        near = closest[:-1] + closest[1:] <= 2.0 * motion
        starts = np.concatenate([[0], stops[:-1] + 1])
        keep = np.concatenate([np.arange(a, b + 1) for a, b, n in zip(starts, stops, near) if n] or [np.arange(0)])
        return Q[keep.astype(int)], f[keep.astype(int)]

    def _closest(self, Q: np.ndarray) -> np.ndarray:
        """(n,) every pair's least lower bound [mm] at each of the joints ``Q`` (n, g)."""
        return self._gaps(self._placed(Q)).min(axis=1, initial=np.inf)

    def _placed(self, Q: np.ndarray) -> np.ndarray:
        """(n, moving, 4, 4): every moving part's pose in the base frame at joints ``Q`` (n, g)."""
        return self.frames(Q)[:, self._frame_of] @ self._local  # (n, moving, 4, 4) in one product

    def check_joints(self, Q: np.ndarray, fractions: np.ndarray | None = None, chunk: int = 2048) -> Hit | None:
        """The first collision among the joint samples ``Q`` ``(n, g)``, in their order, or None."""
        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        f = np.ones(len(Q)) if fractions is None else np.asarray(fractions, dtype=float)
        self.samples_checked += len(Q)
        for start in range(0, len(Q), chunk):
            W = self._placed(Q[start:start + chunk])
            near = self._gaps(W) <= 0.0
            for k in np.flatnonzero(near.any(axis=1)):
                hit = self._exact(W[k], near[k])
                if hit is not None:
                    a, b, depth = hit
                    n = start + k
                    return Hit(a, b, depth, float(f[n]), tuple(float(v) for v in Q[n]))
        return None

    def _gaps(self, W: np.ndarray) -> np.ndarray:
        """(n, pairs) a lower bound [mm] of each pair's distance (moving-moving, then moving-fixed);
        not positive: they may overlap. The first of a pair is its axis segment grown by its
        radius, the second is boxed in its own frame."""
        c, z = W[..., :3, 3], W[..., :3, 2]
        half = self._half[None, :, None] * z
        out = []
        if self._mm:
            i, j = self._mm_i, self._mm_j
            gap = np.linalg.norm(c[:, i] - c[:, j], axis=-1) - self._ball[i] - self._ball[j]
            k, p = np.nonzero(gap < NEAR_MM)  # bounding spheres first; the near pairs boxed
            a, b = i[p], j[p]
            Rt = np.swapaxes(W[k, b, :3, :3], -1, -2)
            p0, p1 = ((Rt @ (c[k, a] + sgn * half[k, a] - c[k, b])[..., None])[..., 0] for sgn in (1.0, -1.0))
            gap[k, p] = np.maximum(gap[k, p], _box_gap(p0, p1, self._mm_half[p]) - self._radius[a])
            out.append(gap)
        if self._mf:  # in each fixed part's frame: x_part = R x + t
            i, f = self._mf_i, self._mf_j
            gap = np.linalg.norm(c[:, i] - self._fixed_centre[f], axis=-1) - self._ball[i] - self._fixed_ball[f]
            k, p = np.nonzero(gap < NEAR_MM)
            a = i[p]
            R, t = self._mf_R[p], self._mf_t[p]
            p0, p1 = ((R @ (c[k, a] + sgn * half[k, a])[..., None])[..., 0] + t for sgn in (1.0, -1.0))
            gap[k, p] = np.maximum(gap[k, p], _box_gap(p0, p1, self._mf_half[p]) - self._radius[a])
            out.append(gap)
        return np.concatenate(out, axis=1) if out else np.zeros((len(W), 0))

    def _exact(self, W: np.ndarray, near: np.ndarray) -> tuple[str, str, float] | None:
        """fcl's verdict on the pairs the screen left (one sample): the first that collides."""
        fcl, nm = self._fcl, len(self._mm)
        for p in np.flatnonzero(near):
            if p < nm:
                i, j = self._mm[p]
                a, b, Wb, ob = self.moving[i], self.moving[j], W[j], self._objs[j]
            else:
                i, j = self._mf[p - nm]
                a, b, Wb, ob = self.moving[i], self.fixed[j], None, self._objs[len(self.moving) + j]
            oa = self._objs[i]
            oa.setTransform(self._tf(W[i]))
            if Wb is not None:
                ob.setTransform(self._tf(Wb))
            result = fcl.CollisionResult()
            if fcl.collide(oa, ob, fcl.CollisionRequest(enable_contact=True), result):
                depth = max((float(ct.penetration_depth) for ct in result.contacts), default=0.0)
                return a.name, b.name, depth
        return None


def _two_apart(chain: list[str]) -> set[frozenset[str]]:
    """The pairs of links two apart in the chain (joined over one link). A safety controller's cell
    model checks the arm against the cell and the tool against the arm's far links; capsules along
    the link offsets are too crude across one joint: the IRB 2600's base and upper arm, 150 mm apart
    over its shoulder offset, met at a shoulder of -59° (the station leaves such pairs out where the
    link between is shorter than its own, fatter capsules' radii together)."""
    return {frozenset((a, c)) for a, c in zip(chain, chain[2:])}


def _box_gap(p0: np.ndarray, p1: np.ndarray, half: np.ndarray) -> np.ndarray:
    """A lower bound [mm] of the distance from the segments ``p0``-``p1`` (..., 3) to the centred box
    of ``half`` extents: how far the segment's bounding box lies from it."""
    lo, hi = np.minimum(p0, p1), np.maximum(p0, p1)
    return np.linalg.norm(np.maximum(0.0, np.maximum(lo - half, -half - hi)), axis=-1)


def _links(kinds: tuple[str | None, ...], names: list[str], p: np.ndarray,
           radii: Any) -> tuple[list[Part], list[str]]:
    """The links' capsules and their groups in chain order (the base link first). The link after
    transform t rides on its frame and reaches transform t + 1's origin, first along the frame's z
    then across; the last joint's reach to the head frame is the head's mount."""
    size = float(np.sum(np.linalg.norm(p[1:, :3], axis=1)))
    link_names = [names[0]] + [n for n, k in zip(names, kinds) if k is not None]
    if radii is None:
        radii = [LINK_RADIUS_FRACTION * size] * len(link_names)
    parts: list[Part] = []
    groups: list[str] = []
    link = 0
    for t in range(len(kinds) - 2):
        if t > 0 and kinds[t] is None:
            continue
        off = p[t + 1, :3]
        knee = np.array([0.0, 0.0, off[2]])
        group = f"link:{link_names[link]}"
        pieces = [c for c in (_capsule(f"link {link_names[link]}", np.zeros(3), knee, radii[link], t, group),
                              _capsule(f"link {link_names[link]}", knee, off, radii[link], t, group)) if c is not None]
        if pieces:
            parts += pieces
            groups.append(group)
        link += 1
    return parts, groups


def _head_parts(head: Any, K: np.ndarray, frame: int) -> list[Part]:
    """Each probe's plunger and housing and the mount, riding on the head frame (MKKS)."""
    parts: list[Part | None] = []
    for i in range(head.n_probes):
        b, d = np.asarray(head.mount_points[i], float), np.asarray(head.directions[i], float)
        d = d / np.linalg.norm(d)
        r, s = float(head.tip_radii[i]), float(head.strokes[i])
        # the tip ball's centre travels from b + d·s/2 (free) to b − d·s/2 (pressed in fully)
        parts.append(_capsule(f"probe {head.label(i)}'s plunger", b + d * s / 2, b - d * s / 2, max(r, 0.1),
                              frame, "plunger"))
        parts.append(_capsule(f"probe {head.label(i)}'s housing", b - d * (s / 2 + 2 * r), b - d * (s + 2 * r),
                              max(r, 0.1), frame, "head"))
    flange = inverse(K)[:3, 3]  # the flange's origin in MKKS
    r_mount = 0.2 * float(np.max(np.linalg.norm(np.asarray(head.mount_points, float), axis=1)))
    parts.append(_capsule("the head's mount", flange, np.zeros(3), r_mount, frame, "head"))
    return [m for m in parts if m is not None]


def _body_parts(points: np.ndarray, edge: float, base_from_body: np.ndarray) -> list[Part]:
    """The cubes (one per distinct cube among the measuring points' corner frames; the cube lies in
    x, y >= 0, z <= 0 of a corner's frame) and their pillars down to z = 0, in the base. No plate:
    the body file gives none (a guessed one, the cubes' footprint grown by half an edge, refused the
    PUMA 560 example's robot where it stood at q = 0, 254 mm through it); a plate is an [[obstacle]]."""
    centre = np.eye(4)
    centre[:3, 3] = [edge / 2, edge / 2, -edge / 2]
    cubes: dict[tuple[float, ...], np.ndarray] = {}
    for M in points:
        C = M @ centre
        cubes.setdefault(tuple(np.round(C[:3, 3], 0)), C)
    parts = []
    for k, C in enumerate(cubes.values()):
        parts.append(_box(f"cube {k + 1} of the body", base_from_body @ C, (edge, edge, edge), "cube"))
        bottom = float(C[2, 3]) - edge / 2
        if bottom > 1e-6:
            P = C.copy()
            P[2, 3] = bottom / 2
            parts.append(_box(f"the pillar of cube {k + 1}", base_from_body @ P, (edge, edge, bottom), "cube"))
    return parts
