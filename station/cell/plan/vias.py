"""Via poses between the measurements of an articulated arm (issue 40): the head leaves one
measuring point straight up to a travel height, moves there in joint space, and comes straight down
over the next, so that no joint move between two targets drags the head through a cube.

A SCARA needs no lift: its quill already rises to the travel height before every lateral move
(:func:`station.cell.plan.measurement_plan.retracted`). Where an obstacle stands taller than that
height (a column in the workspace), its lateral move goes around it: one arm joint first, then the
other (:func:`_scara_around`). An articulated arm's retract only backs the
head off its corner by ``[plan] clearance_mm``; a joint-space move from there to the next corner
passed the head through the neighbouring cubes (the PUMA 560 example: 195 moves, up to 87 mm deep).

The vias are a function of the two poses alone (:func:`travel_vias`), so that the plan's collision
check (:func:`station.cell.plan.run_path.plan_path`) and the runner command the same ones:

* **depart**: the head lifted along the body's +z from where it stands, its orientation kept, until
  its lowest point (a free probe tip, a probe's body, the mount) lies ``[plan] clearance_mm`` plus
  the collision margin above the highest cube (:func:`travel_height_mm`);
* **arrive**: the same over the next target's approach pose.

Between two poses at the same corner (the head turned or tilted about the corner, the contact
within ``clearance_mm``) the move stays direct: the head hardly moves.
"""

from __future__ import annotations

import weakref

import numpy as np

from station.cell.config.cell_config import CellConfig
from station.cell.plan.arm_motion import LIMIT_MARGIN_RAD, follow_ik, preload_offset, retract_poses
from station.cell.plan.assembly import nominal_contact
from station.cell.plan.collision import check_path, moves_clear, poses_clear
from station.cell.plan.collision_shapes import default_radii, head_shapes
from station.core.kinematics.forward import chain_frames, forward
from station.core.kinematics.transforms import invert, pose_to_matrix
from station.errors import UnreachableError

__all__ = ["travel_vias", "travel_height_mm", "head_low_mm", "lifted", "lifted_many", "clear_candidates", "fold_note", "LONG_MOVE_RAD"]

# Computed once per configuration object (weak keys: the entry goes with the configuration).
_HEIGHT: weakref.WeakKeyDictionary[CellConfig, float] = weakref.WeakKeyDictionary()
_HEAD: weakref.WeakKeyDictionary[CellConfig, np.ndarray] = weakref.WeakKeyDictionary()


def _head_points(cfg: CellConfig) -> np.ndarray:
    """(k, 4) the ends of the head's collision capsules in the head frame (homogeneous) and, in the
    last column's place, nothing: the radii come from :func:`_head_radii`."""
    hit = _HEAD.get(cfg)
    if hit is not None:
        return hit
    rows = []
    for s in head_shapes(cfg):
        half = s.local[:3, 2] * (s.size[1] / 2 if s.kind == "capsule" else 0.0)
        for end in (s.local[:3, 3] + half, s.local[:3, 3] - half):
            rows.append([*end, s.size[0]])  # x, y, z [mm] and the radius
    out = np.array(rows)
    out.setflags(write=False)
    _HEAD[cfg] = out
    return out


def head_low_mm(cfg: CellConfig, q: np.ndarray) -> np.ndarray:
    """The head's lowest point [mm] along the body's z (the body frame KKS) at joints ``q (n, g)``."""
    pts = _head_points(cfg)
    T = forward(cfg.model, np.asarray(q, dtype=float).reshape(-1, cfg.model.n_joints), setup=True)
    z = T[:, 2, :3] @ pts[:, :3].T + T[:, 2, 3:4]  # (n, k)
    return np.min(z - pts[:, 3], axis=1)


def travel_height_mm(cfg: CellConfig) -> float:
    """The height [mm, body frame z] the head's lowest point travels at: the highest cube's top
    (every corner of every cube, whatever its frame's tilt) plus ``[plan] clearance_mm`` plus the
    collision margin."""
    hit = _HEIGHT.get(cfg)
    if hit is not None:
        return hit
    e = cfg.cube_edge_mm
    corners = np.array([[x, y, z, 1.0] for x in (0.0, e) for y in (0.0, e) for z in (0.0, -e)])
    top = float(np.max((cfg.body_points @ corners.T)[:, 2])) if len(cfg.body_points) else 0.0
    out = top + cfg.plan.clearance_mm + cfg.plan.collision_margin_mm
    _HEIGHT[cfg] = out
    return out


def lifted_many(cfg: CellConfig, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`lifted` of every row of ``Q (n, g)`` at once: the joints ``(n, g)`` and a mask ``(n,)``
    of the rows the arm reaches."""
    Q = np.asarray(Q, dtype=float).reshape(-1, cfg.model.n_joints)
    rise = np.maximum(travel_height_mm(cfg) - head_low_mm(cfg, Q), 0.0)
    out, ok = Q.copy(), np.ones(len(Q), dtype=bool)
    up = rise > 0.0
    if np.any(up):
        z = invert(pose_to_matrix(cfg.model.nominal[:6]))[:3, 2]  # the body's z in the base frame
        T = forward(cfg.model, Q[up], setup=False)
        T[:, :3, 3] += rise[up, None] * z
        out[up], ok[up] = follow_ik(cfg.model, T, Q[up])
    return out, ok


def lifted(cfg: CellConfig, q: np.ndarray) -> np.ndarray | None:
    """Joints ``(g,)`` with the head raised from ``q`` along the body's +z until its lowest point is
    at :func:`travel_height_mm`, its orientation kept (by IK from ``q``); ``q`` itself when it is
    there already; None when the arm cannot reach it."""
    sol, ok = lifted_many(cfg, np.asarray(q, dtype=float)[None])
    return sol[0] if ok[0] else None


def _contact_mm(cfg: CellConfig, q: np.ndarray) -> np.ndarray:
    return (forward(cfg.model, np.asarray(q, dtype=float)[None], setup=True)[0] @ nominal_contact(cfg))[:3, 3]


#: a move at the travel height in which some revolute joint turns more than this [rad] is a long one
#: (a change of arm configuration: shoulder, elbow or wrist flipped): its joint-space path is checked,
#: and where it collides the joints move a group at a time (:func:`_staged`)
LONG_MOVE_RAD = np.deg2rad(60.0)


def _groups(cfg: CellConfig) -> list[tuple[int, ...]]:
    """The joint groups a long move may move first, the others after: each of the first three
    joints alone, the wrist (the rest) together."""
    g = cfg.model.n_joints
    return [(j,) for j in range(min(3, g))] + ([tuple(range(3, g))] if g > 3 else [])


def _upright(cfg: CellConfig, q: np.ndarray) -> np.ndarray:
    """``q`` with joints 2 and 3 where they hold the wrist (the frame after the fourth joint, else the
    tool) highest above the base (a grid of 5° inside the soft limits): the arm stretched upwards.
    A change of shoulder configuration turns there, over the shoulder's singularity, instead of
    folding the elbow past the shoulder (the PUMA 560's head mount then met the shoulder's capsule)."""
    lim = cfg.soft_limits
    grid = [np.arange(lim[j, 0] + np.deg2rad(5.0), lim[j, 1] - np.deg2rad(5.0) + 1e-9, np.deg2rad(5.0)) for j in (1, 2)]
    g2, g3 = (v.ravel() for v in np.meshgrid(*grid, indexing="ij"))
    Q = np.repeat(np.asarray(q, dtype=float)[None], g2.size, axis=0)
    Q[:, 1], Q[:, 2] = g2, g3
    joints = [t for t, spec in enumerate(cfg.model.transforms) if spec.joint is not None]
    frame = joints[3] if len(joints) > 3 else -1
    z = chain_frames(cfg.model, Q, setup=False)[:, frame, 2, 3]
    return Q[int(np.argmax(z))]


def _staged(cfg: CellConfig, a: np.ndarray, b: np.ndarray) -> list[tuple[np.ndarray, str]]:
    """The vias of a long move from ``a`` to ``b`` at the travel height: none when the direct move is
    clear (:func:`station.cell.plan.collision.moves_clear`), else the first clear of, in this fixed
    order (the plan and the runner choose the same): through the arm stretched upwards
    (:func:`_upright`), or one joint group (:func:`_groups`) first and the others after. Raises
    :class:`UnreachableError` when none is clear."""
    rev = np.array([t == "revolute" for t in cfg.model.joint_types])
    if not np.any(np.abs(b - a)[rev] > LONG_MOVE_RAD) or moves_clear(cfg, [a, b]):
        return []  # a short move at the travel height: the plan's check checks it with the rest
    revolute_arm = cfg.model.n_joints >= 3 and all(t == "revolute" for t in cfg.model.joint_types[:3])
    if revolute_arm:  # up, turn (joint 1, the wrist), down
        up_a = _upright(cfg, a)
        up_b = b.copy()
        up_b[1:3] = up_a[1:3]
        if moves_clear(cfg, [a, up_a, up_b, b]):
            return [(up_a, "arm upright"), (up_b, "turned upright")]
    for grp in _groups(cfg):
        v = a.copy()
        v[list(grp)] = b[list(grp)]
        if moves_clear(cfg, [a, v, b]):
            return [(v, f"joint{'s' if len(grp) > 1 else ''} {', '.join(str(j + 1) for j in grp)} first")]

    clash = check_path(cfg, [(a, "depart: travel", -1), (b, "arrive: travel", -1)]).clash
    why = "" if clash is None else f" (straight: {clash.describe()})"
    raise UnreachableError(f"no collision-free way found at the travel height from joints "
                           f"{np.round(np.degrees(a), 1).tolist()} to {np.round(np.degrees(b), 1).tolist()} deg "
                           f"(straight, through the arm upright, or one joint group first){why}; the motion was not "
                           f"commanded. Move the obstacle or the body, or leave out that arm configuration ([limits])")


def fold_note(cfg: CellConfig, a: np.ndarray, b: np.ndarray) -> str:
    """Why no way from joints ``a`` to ``b`` can be clear, where that is the arm's geometry: joint 3
    must turn through the fold (the wrist, the frame after the fourth joint, nearest joint 2's axis,
    on a 0.1° grid over joint 3's soft range) and the wrist lies there inside the upper arm's
    capsule. "" otherwise. The PUMA 560 example's file admits the fold and not the stretched arm: its
    shoulder-back configuration cannot be reached whatever the vias (tests/cell/test_puma_fold.py)."""
    model = cfg.model
    if model.n_joints < 4 or not all(t == "revolute" for t in model.joint_types[:3]):
        return ""
    lo, hi = cfg.soft_limits[2]
    q3 = np.arange(lo, hi + 1e-12, np.deg2rad(0.1))
    Q = np.repeat(np.asarray(a, dtype=float)[None], q3.size, axis=0)
    Q[:, 2] = q3
    joints = [t for t, spec in enumerate(model.transforms) if spec.joint is not None]
    F = chain_frames(model, Q, setup=False)
    axis, origin, wrist = F[:, joints[1], :3, 2], F[:, joints[1], :3, 3], F[:, joints[3], :3, 3]
    d = np.linalg.norm(np.cross(wrist - origin, axis), axis=1)
    k = int(np.argmin(d))
    spec = cfg.robot_collision
    radii = spec.radius_mm if spec is not None and spec.radius_mm is not None else default_radii(cfg)
    if d[k] >= radii[2] or (a[2] - q3[k]) * (b[2] - q3[k]) > 0:
        return ""  # the wrist clears the shoulder at the fold, or the move does not pass it
    circle = np.deg2rad(np.arange(-180.0, 180.0, 0.1))  # the stretched arm: the wrist farthest from the axis
    Q = np.repeat(Q[:1], circle.size, axis=0)
    Q[:, 2] = circle
    F = chain_frames(model, Q, setup=False)
    far = float(circle[int(np.argmax(np.linalg.norm(np.cross(F[:, joints[3], :3, 3] - F[:, joints[1], :3, 3],
                                                               F[:, joints[1], :3, 2]), axis=1)))])
    inside = any(lo <= far + t <= hi for t in (-2 * np.pi, 0.0, 2 * np.pi))
    return (f". Every way from one to the other turns joint 3 through {np.rad2deg(q3[k]):.1f}°, where the forearm "
            f"folds back onto the upper arm and the wrist lies {d[k]:.1f} mm from joint 2's axis, inside the "
            f"shoulder: no via clears it. Joint 3's soft range [{np.rad2deg(lo):.0f}°, {np.rad2deg(hi):.0f}°] holds "
            f"the fold{'' if inside else f' and not the stretched arm ({np.rad2deg(far):.0f}°)'}, where a real "
            f"arm's range leaves out the fold: check joint 3's limits in the robot file against the data sheet")


def _scara_around(cfg: CellConfig, a: np.ndarray, b: np.ndarray) -> list[tuple[np.ndarray, str]]:
    """The vias of a SCARA's lateral move at the travel height from ``a`` to ``b``: none when the
    direct joint move is clear, else the first clear of joint 1 first, joint 2 first, or the swing
    with the elbow at another angle (a fixed order, so the plan and the runner choose the same).
    None of them clear: the direct move, which the plan's check refuses where it collides."""
    if np.allclose(a, b, atol=1e-9, rtol=0) or moves_clear(cfg, [a, b]):
        return []
    for j in (0, 1):
        v = a.copy()
        v[j] = b[j]
        if moves_clear(cfg, [a, v, b]):
            return [(v, f"joint {j + 1} first")]
    # the reach changed for the swing: the elbow (joint 2) folded or opened to another angle, joint 1
    # turned there, the elbow back (the head passes inside or outside the obstacle), nearest first
    lo, hi = cfg.soft_limits[1] + np.array([1.0, -1.0]) * np.deg2rad(3.0)
    for e in sorted(np.arange(lo, hi + 1e-9, np.deg2rad(10.0)), key=lambda x: abs(x - a[1])):
        v1, v2 = a.copy(), b.copy()
        v1[1] = v2[1] = e
        if moves_clear(cfg, [a, v1, v2, b]):
            return [(v1, "elbow to swing"), (v2, "swung")]
    # none clear with the full margin from everything: the direct move, judged by the plan's check
    # with the touch's rules (a tip may pass over the cube it touches next), which refuses what collides
    return []


def travel_vias(cfg: CellConfig, q_from: np.ndarray, q_to: np.ndarray,
                lifts: tuple[np.ndarray | None, np.ndarray | None] | None = None) -> list[tuple[np.ndarray, str]]:
    """The via poses (joints, what it is) of the move from ``q_from`` to ``q_to`` (both the head's
    poses off a measuring point: a retract and the next approach): for a SCARA those around an
    obstacle (:func:`_scara_around`), none within one corner, else depart, the stages of a long move (:func:`_staged`) and arrive. Raises
    :class:`UnreachableError` when a via is out of reach or a long move finds no clear way.
    ``lifts``: :func:`lifted` of both, when known (the plan computes them all at once)."""
    q_from, q_to = np.asarray(q_from, dtype=float), np.asarray(q_to, dtype=float)
    if cfg.model.is_scara:
        return _scara_around(cfg, q_from, q_to)
    if float(np.linalg.norm(_contact_mm(cfg, q_from) - _contact_mm(cfg, q_to))) <= 2 * cfg.plan.clearance_mm:
        return []
    ends = []
    for k, (q, name) in enumerate(((q_from, "depart"), (q_to, "arrive"))):
        v = lifted(cfg, q) if lifts is None else lifts[k]
        if v is None:
            raise UnreachableError(f"the {name} pose, the head lifted to {travel_height_mm(cfg):.0f} mm over the body "
                                   f"(the highest cube, [plan] clearance_mm and the collision margin), is not "
                                   f"reachable from joints {np.round(np.degrees(q), 2).tolist()} deg; the motion "
                                   f"was not commanded. Lower the body or reduce [plan] clearance_mm")
        ends.append(v)
    out = [] if np.allclose(ends[0], q_from, atol=1e-9, rtol=0) else [(ends[0], "depart")]
    out += _staged(cfg, ends[0], ends[1])
    return out + ([] if np.allclose(ends[1], q_to, atol=1e-9, rtol=0) else [(ends[1], "arrive")])


def clear_candidates(cfg: CellConfig, cands: list, orient: list[int]
                     ) -> tuple[list, list[int], list[tuple[str, int, str]]]:
    """The candidates (:class:`~station.cell.plan.assembly.Target`, with their head orientations
    ``orient``) a run can measure without a collision, and the others (point, configuration code,
    why): a candidate whose touch or pose short of it clashes (the pose design draws only from
    clear ones) or whose lifted via is out of reach or the soft limits, and every candidate of an arm
    configuration the lifted head cannot travel to from
    the first configuration's (:func:`travel_vias`: the PUMA 560's shoulder-back configuration
    folds the elbow past the shoulder, its head mount through the shoulder's capsule)."""
    if not cands:
        return cands, orient, []
    q = np.array([t.joints for t in cands])
    pts = np.array([t.point for t in cands])
    why = poses_clear(cfg, np.concatenate([q, q - preload_offset(cfg)]), np.concatenate([pts, pts]))
    rejected = []
    keep = []
    for i, t in enumerate(cands):
        w = why[i] or why[len(cands) + i]
        if w is not None:
            rejected.append((t.point_id, t.elbow, f"{t.point_id} configuration {t.elbow:+d}: collides: {w}"))
        else:
            keep.append(i)
    back, _ok = retract_poses(cfg, q)
    up, reached = lifted_many(cfg, back)  # every candidate's depart and arrive: reached, inside the limits
    # as every planned pose, LIMIT_MARGIN_RAD inside the soft limits: a located or corrected target
    # moves its lift a little (a PUMA-like arm 3 mm off: an arrive 0.97° beyond joint 3's limit)
    m = LIMIT_MARGIN_RAD * np.array([t == "revolute" for t in cfg.model.joint_types])
    lim = cfg.soft_limits
    inside = reached & np.all((up >= lim[:, 0] + m) & (up <= lim[:, 1] - m), axis=1)
    for i in [i for i in keep if not inside[i]]:
        t = cands[i]
        rejected.append((t.point_id, t.elbow, f"{t.point_id} configuration {t.elbow:+d}: the head lifted to "
                         f"{travel_height_mm(cfg):.0f} mm over the body from its retract pose (the via to and from "
                         f"it) is {'outside the soft limits' if reached[i] else 'out of reach'}"))
        keep.remove(i)
    first: dict[int, int] = {}
    for i in keep:
        first.setdefault(cands[i].elbow, i)
    codes = list(first)
    if len(codes) > 1:
        unreachable = {}
        for c in codes[1:]:
            try:
                travel_vias(cfg, back[first[codes[0]]], back[first[c]])
            except UnreachableError as exc:
                unreachable[c] = str(exc) + fold_note(cfg, back[first[codes[0]]], back[first[c]])
        for i in list(keep):
            c = cands[i].elbow
            if c in unreachable:
                rejected.append((cands[i].point_id, c, f"{cands[i].point_id} configuration {c:+d}: its arm "
                                 f"configuration cannot be reached from {codes[0]:+d} without a collision: "
                                 f"{unreachable[c]}"))
                keep.remove(i)
    return [cands[i] for i in keep], [orient[i] for i in keep], rejected
