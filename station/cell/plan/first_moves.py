"""The moves a run commands that the plan does not hold, checked before motion (issue 40): the first
move, from wherever the robot stands to the first touch, and the search touches of locating the
body (:mod:`station.cell.plan.locating`, ``station/cell/run/locate.py``). Both go through the plan's
collision check (:func:`station.cell.plan.collision.check_path`: the same shapes, margin, path
sampling and touch rules); a clash is refused before anything moves, naming the pair, the move and
the clearance.

**The first move** is what the runner commands at the start of a touch (``_touch`` in
``station/cell/run/runner.py``) from the joints the controller reports: the retract to the travel
height from there (from a touch, where a run stopped at a safe point left the head, with that
touch's rules: its probes' tips on its cube), the travel vias (:func:`station.cell.plan.vias.travel_vias`) to the first step's
approach, then that step's approach, the pose above the point, the touch and the retract. Where
the robot stands is known only at the start of ``calibrate`` (it reads the joints); ``station
plan`` checks it from ``[conformance] park_joints`` when the file gives them (where the robot is
parked), and says that it did not check it otherwise.

**The search touches** move the head from a planned touch along its faces' normals by up to the
search's bound (``[plan] locate_steps`` steps of the search's step, never beyond ``[robot]
setup_uncertainty_mm`` or ``[plan] clearance_mm``). Every corner of that box of offsets is checked,
each touch from the planned touch's retract (the search's moves go out from there and back), for
each of the measuring points locating touches (the plan's first, then the farthest from those
chosen), against what does not move with the body: the robot itself and the obstacles in the base
frame. The body (its cubes, the obstacles in its frame) is left out: the search moves a face's
offset towards where that face reads, so relative to the body a search touch stands no farther off
than the first touch of a body anywhere within the set-up's uncertainty, which every touch of the
plan shares (the arc example's search at its full offsets came 1.7 mm from the neighbouring cube
of a body that moves with the head's target).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from itertools import product

import numpy as np

from station.cell.config.cell_config import CellConfig
from station.cell.plan.arm_motion import follow_ik, retract_poses
from station.cell.plan.assembly import Plan
from station.cell.plan.collision import CollisionReport, check_path
from station.cell.plan.locating import coverage
from station.cell.plan.measurement_plan import above_offset, approach_pose, retracted
from station.cell.plan.steps import PlannedStep, StepKind
from station.cell.plan.vias import travel_vias
from station.errors import ConfigError, UnreachableError

__all__ = ["N_LOCATE", "locate_steps", "touch_poses", "first_move_path", "check_first_move", "face_directions",
           "shifted_joints", "search_offsets", "locating_paths", "check_locating_moves"]

#: measuring points touched to locate the body (each gives the whole set-up; three average it)
N_LOCATE = 3

Pose = tuple[np.ndarray, str, int]


def locate_steps(cfg: CellConfig, steps: Sequence[PlannedStep]) -> list[PlannedStep]:
    """:data:`N_LOCATE` identification steps of the first pass: the plan's first, then each time
    the one farthest from those chosen (spread points give the yaw by their positions)."""
    first = [st for st in steps if st.kind is StepKind.IDENTIFICATION and st.cycle == 0]
    out = first[:1]
    xy = cfg.body_points[:, :2, 3]
    while first and len(out) < min(N_LOCATE, len(first)):
        far = max(first, key=lambda st: min(float(np.linalg.norm(xy[st.point] - xy[o.point])) for o in out))
        if far in out:
            break
        out.append(far)
    return out


def touch_poses(cfg: CellConfig, Q: np.ndarray, st: PlannedStep, names: Sequence[str]) -> list[Pose]:
    """What the runner commands for a touch at each row of ``Q`` (``_touch``): the approach, the pose
    above the point, the touch, and the retract the next touch starts with; labelled as
    :func:`station.cell.plan.run_path.plan_path` labels a step's poses (``name: what``). An
    articulated arm's approach and retract are its retract pose, computed for all rows at once."""
    Q = np.asarray(Q, dtype=float).reshape(-1, cfg.model.n_joints)
    if cfg.model.is_scara:
        back = np.array([approach_pose(cfg, q, st.direction, st.cycle) for q in Q])
        leave = np.array([retracted(cfg, q) for q in Q])
    else:
        back, ok = retract_poses(cfg, Q)
        if not np.all(ok):
            k = int(np.flatnonzero(~ok)[0])
            raise UnreachableError(f"the retract pose of {names[k]} is out of the robot's reach; nothing was moved. "
                                   f"Reduce [plan] clearance_mm or move the body")
        leave = back
    out: list[Pose] = []
    for name, a, q, r in zip(names, back, Q, leave):
        moves = (a, q + above_offset(cfg, st.cycle), q, r)
        out += [(np.asarray(m, dtype=float), f"{name}: {what}", st.point)
                for m, what in zip(moves, ("approach", "above the point", "touch", "retract"))]
    return out


def _step_name(st: PlannedStep) -> str:
    return f"step {st.index + 1} ({st.label})"


def first_move_path(cfg: CellConfig, here: np.ndarray, st: PlannedStep) -> list[Pose]:
    """The first move's poses: where the robot stands, the retract to the travel height from there,
    the vias to ``st``'s approach and ``st``'s touch."""
    here = np.asarray(here, dtype=float)
    up = retracted(cfg, here)
    k = _touching(cfg, here)
    if k is None:
        out: list[Pose] = [(here, "the first move: where the robot stands", -1)]
        if not np.allclose(up, here, atol=1e-9, rtol=0):
            out.append((up, "the first move: retract to travel height", -1))
    else:  # a run stopped at a safe point stands at its last touch: its retract is that touch's
        name = f"the first move from the touch of {cfg.point_ids[k]}"
        out = [(here, f"{name}: touch", k), (up, f"{name}: retract", k)]
    touch = touch_poses(cfg, st.q, st, [_step_name(st)])
    out += [(v, f"the first move: {what}", -1) for v, what in travel_vias(cfg, up, touch[0][0])]
    return out + touch


def _touching(cfg: CellConfig, q: np.ndarray) -> int | None:
    """The measuring point the head touches at ``q`` (its nominal contact within half the clearance
    of it, as :func:`station.cell.plan.arm_motion.retract_from` tells a touch), None: none."""
    from station.cell.plan.assembly import nominal_contact
    from station.core.kinematics.forward import forward

    contact = forward(cfg.model, np.asarray(q, dtype=float)[None], setup=True)[0] @ nominal_contact(cfg)
    d = np.linalg.norm(cfg.body_points[:, :3, 3] - contact[:3, 3], axis=1)
    return None if d.size == 0 or float(d.min()) > 0.5 * cfg.plan.clearance_mm else int(np.argmin(d))


def check_first_move(cfg: CellConfig, here: np.ndarray, st: PlannedStep, where: str) -> CollisionReport:
    """Refuse (:class:`UnreachableError`, exit 4: nothing was commanded) a first move from ``here``
    (``where``: how it is known, e.g. "the joints the controller reports") to ``st`` that collides;
    its report where it is clear."""
    report = check_path(cfg, first_move_path(cfg, here, st))
    if report.clash is not None:
        raise UnreachableError(f"the first move from {where} ({_degrees(cfg, here)}) collides: "
                               f"{report.clash.describe()}; nothing was moved. Jog the robot clear of the body and "
                               f"the obstacles (to [conformance] park_joints, where the file gives them) and start "
                               f"again (docs/collision.md)")
    return report


def _degrees(cfg: CellConfig, q: np.ndarray) -> str:
    """The joints as people read them: deg for a revolute joint, mm for a prismatic one."""
    parts = [f"{np.degrees(v):.1f} deg" if t == "revolute" else f"{v:.1f} mm"
             for v, t in zip(np.asarray(q, dtype=float), cfg.model.joint_types)]
    return "joints " + ", ".join(parts)


def face_directions(cfg: CellConfig) -> np.ndarray:
    """``(3, 3)`` per face (top, x, y) the mean direction of its probes in MKKS (unit; zero for a
    face without probes): the normals the search moves the head along."""
    from station.core.probe.geometry import default_probe_head

    g = cfg.head if cfg.head is not None else default_probe_head(cube_edge_mm=cfg.cube_edge_mm)
    out = np.zeros((3, 3))
    for f in range(3):
        d = np.asarray(g.directions)[np.asarray(g.faces) == f]
        if len(d):
            v = d.mean(axis=0)
            out[f] = v / np.linalg.norm(v)
    return out


def shifted_joints(cfg: CellConfig, q: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The joints ``(k, g)`` that put the head ``t`` (k, 3) [mm, head frame MKKS] from where ``q``
    puts it, in ``q``'s configuration (a SCARA's elbow; an arm's followed from ``q``), and a mask
    ``(k,)`` of the rows the inverse kinematics reached."""
    from station.core.kinematics.forward import forward, scara_ik

    q = np.asarray(q, dtype=float)
    t = np.asarray(t, dtype=float).reshape(-1, 3)
    shift = np.tile(np.eye(4), (len(t), 1, 1))
    shift[:, :3, 3] = t
    T = forward(cfg.model, q[None], setup=False)[0] @ shift
    if cfg.model.is_scara:
        out = scara_ik(cfg.model, T, 1 if q[1] > 0 else -1, setup=False, check_limits=False)
        return out, np.all(np.isfinite(out), axis=1)
    return follow_ik(cfg.model, T, np.repeat(q[None], len(t), axis=0))


def search_offsets(cfg: CellConfig) -> np.ndarray:
    """``(k, 3)`` the corners of the box of offsets [mm] along the faces' normals (top, x, y) the
    search may move the head to: each face at minus, none or plus its bound; ``(0, 3)`` for a search
    of no steps."""
    cov = coverage(cfg)
    bound = min(cov.limit, cov.step * cov.steps)
    if bound <= 0.0:
        return np.zeros((0, 3))
    corners = np.array([c for c in product((-bound, 0.0, bound), repeat=3) if any(c)])
    return corners


def locating_paths(cfg: CellConfig, steps: Sequence[PlannedStep]) -> list[list[Pose]]:
    """Per measuring point that locates the body, every search touch's poses (see the module), each
    from its planned touch's retract ([]: no search)."""
    out: list[list[Pose]] = []
    offsets = search_offsets(cfg)
    if not len(offsets):
        return out
    for st in locate_steps(cfg, steps):
        back = retracted(cfg, st.q)
        shifted, ok = shifted_joints(cfg, st.q, offsets @ face_directions(cfg))
        names = [f"search touch at {st.point_id} (top {o[0]:+.2f} mm, x {o[1]:+.2f} mm, y {o[2]:+.2f} mm)"
                 for o in offsets]
        if not np.all(ok):
            raise ConfigError(f"the {names[int(np.flatnonzero(~ok)[0])]} is out of the robot's reach: the search "
                              f"for the body could not be commanded there. Reduce [robot] setup_uncertainty_mm or "
                              f"[plan] locate_steps")
        touches = touch_poses(cfg, shifted, st, names)
        poses: list[Pose] = []
        for k, name in enumerate(names):  # each from the planned retract (the search goes out and back)
            poses.append((back, f"{name}: from the planned retract", st.point))
            poses += touches[4 * k:4 * k + 4]
        out.append(poses)
    return out


def _without_the_body(cfg: CellConfig) -> CellConfig:
    """``cfg`` without what moves with the body (its cubes, the obstacles in its frame): what a
    search touch is checked against (see the module)."""
    keep = tuple(o for o in cfg.obstacles if o.frame != "body")
    return dataclasses.replace(cfg, point_ids=(), body_points=cfg.body_points[:0], obstacles=keep)


def _least(report: CollisionReport) -> float:
    return float("inf") if report.closest is None else report.closest.clearance_mm


def check_locating_moves(cfg: CellConfig, plan: Plan) -> CollisionReport | None:
    """Refuse (ConfigError, exit 2) a search for the body any of whose touches collides (see the
    module), naming the pair, the touch and the clearance; the report where they are clear (None:
    no search, ``[plan] locate_steps = 0``)."""
    steps = plan.run_steps(cfg.plan.verification_cycles, False)
    fixed = _without_the_body(cfg)
    reports = [check_path(fixed, [(q, label, -1) for q, label, _ in poses]) for poses in locating_paths(cfg, steps)]
    if not reports:
        return None
    report = min(reports, key=lambda r: (r.clash is None, _least(r)))
    if report.clash is not None:
        raise ConfigError(f"a search touch of locating the body collides: {report.clash.describe()}; nothing was "
                          f"moved. Give [robot].setup more exactly and reduce [robot] setup_uncertainty_mm or "
                          f"[plan] locate_steps, or move the obstacle (docs/collision.md)")
    return report
