"""The measurement plan for an articulated arm (a six-axis robot; issue 9).

A SCARA fixes the head's orientation at a cube corner up to the wrist angle; an articulated arm
can reach the same corner with the head turned, and in several arm configurations. The wrist
parameters become observable only when the head's orientation varies, so at every cube corner
the plan visits:

* several **head orientations** (:func:`head_orientations`): the nominal contact, rotations
  about the corner's space diagonal and tilts about two axes normal to it, all about the corner
  itself and well inside the probes' capture range (a few degrees: each probe then reads a
  millimetre or two of its ±5 mm stroke at the nominal pose);
* every **arm configuration** the robot file's limits allow (shoulder front/back, elbow up/down,
  wrist flipped or not: :func:`station.core.kinematics.ik.configuration`), each solved by
  :func:`station.core.kinematics.ik.solve_ik` on the full nominal model, which chooses deterministically
  and away from the limits and the wrist singularity; a candidate must also stay
  :data:`~station.cell.plan.arm_motion.LIMIT_MARGIN_RAD` inside the cell's soft limits.

Motion per measurement (:mod:`station.cell.plan.arm_motion`: :func:`~station.cell.plan.arm_motion.retract_pose`,
:func:`~station.cell.plan.arm_motion.preload_offset`): the head retracts along the
corner's diagonal, away from the cube, by ``[plan] clearance_mm``; from there it moves to the
target short of ``[plan] approach_deg`` in every joint, then to the target, so that each joint
arrives from one side (backlash becomes a repeatable offset). Every motion pose of every candidate
passes the :class:`~station.cell.limits.motion_guard.MotionGuard` before anything moves.

Candidates with the nominal head orientation are the verification pool: the held-out targets
(:func:`held_out_spread`, issue 22) are spread over it by farthest-point sampling in joint space,
every configuration and corner kind, at least :data:`MIN_HELD_OUT` of them (with the eight every
fourth in point order held out before, all fell on the same corner of each cube, and the RMS of
so few scattered by ±15 % between the after and the oracle passes). The other candidates are
identification candidates, chosen by the greedy I-optimal
:func:`station.core.identification.pose_design.select_i_optimal` (the mean predicted position variance over
every nominal contact: the working poses the verification samples) until the stopping rule
(:data:`NOISE_FRACTION`) is met or ``[plan] select`` reached (:class:`IdentificationDesign` says
which), then ordered to keep robot time short (:func:`order_for_time`: nearest neighbour in joint
space, configuration changes last, 2-opt on the largest joint move), the held-out targets too; the
verification passes do every cycle of one configuration before the next
(:meth:`ArticulatedPlan.run_steps`: with the targets spread over the joint space, the changes of
configuration were most of the robot time).

The step's ``elbow`` field holds the configuration code (:func:`configuration_code`): its sign is
the elbow (up +, down −), its magnitude ``1 + 2·wrist flipped + 4·shoulder back``; ``+1`` is the
usual front, elbow up, wrist not flipped configuration. Cartesian commands carry its sign only;
the controller keeps the configuration of the joints it stands at.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from station.cell.config.cell_config import CellConfig
from station.cell.limits.motion_guard import MotionGuard
from station.cell.plan.arm_motion import LIMIT_MARGIN_RAD, OUTWARD_DIAGONAL, motion_poses, retract_poses
from station.cell.plan.assembly import Plan, Target, assemble_plan, head_targets_world, nominal_contact
from station.cell.plan.steps import PlannedStep, StepKind
from station.cell.plan.vias import clear_candidates
from station.core.kinematics.model import RobotModel
from station.core.kinematics.transforms import invert, pose_to_matrix, rotation_exp
from station.errors import ConfigError, UnreachableError

__all__ = ["head_orientations", "configuration_code", "articulated_candidates", "build_articulated_plan",
           "order_by_travel", "order_for_time", "ArticulatedPlan", "IdentificationDesign", "NOISE_FRACTION"]

#: rotations about the corner's diagonal [deg] (each probe moves ≤ 0.3 mm/deg)
DIAGONAL_TURNS_DEG = (-4.0, 4.0)
#: tilts about the two axes normal to the diagonal [deg] (each probe moves ≤ 0.7 mm/deg)
TILTS_DEG = (-2.0, 2.0)
#: the fewest held-out targets of a plan (where the body offers :data:`MAX_HELD_OUT_FRACTION`⁻¹
#: times as many). The after / oracle comparison is two passes' RMS of independent noise: each
#: reading's error lies mostly along one direction (the noise of the joint at the longest lever),
#: so the ratio scatters by about 1/√(targets × cycles): 10 % at 36 × 3, 13 % at 20 × 3, against a
#: correction error of a few % (issue 22: 20 held-out targets left the worst of ten seeds at 1.16
#: on the irb2600, 36 cost no more robot time where the targets lie closer together)
MIN_HELD_OUT = 36
#: at most this fraction of the nominal contacts is held out: the identification keeps the rest and
#: every turned head (6 of the 7 orientations at every corner), so its design hardly changes
MAX_HELD_OUT_FRACTION = 0.75
#: the stopping rule of the identification poses: enough once the correction's predicted σ at the
#: working poses (every repeat counted) is this fraction of one measurement's σ; the held-out RMS
#: then exceeds the measurement noise's own by √(1 + 1/16) − 1 ≈ 3 %, and every further pose (robot
#: time) would buy less than that
NOISE_FRACTION = 0.25


def head_orientations(cfg: CellConfig) -> np.ndarray:
    """``(m, 4, 4)`` pose of MPKS in MKKS for every head orientation the plan visits at a corner
    (rotations about the corner itself); index 0 is the nominal contact."""
    M0 = nominal_contact(cfg)
    d = OUTWARD_DIAGONAL
    n1 = np.cross(d, [0.0, 0.0, 1.0])
    n1 /= np.linalg.norm(n1)
    n2 = np.cross(d, n1)
    out = [M0]
    for axis, angles in ((d, DIAGONAL_TURNS_DEG), (n1, TILTS_DEG), (n2, TILTS_DEG)):
        for a in angles:
            R = np.eye(4)
            R[:3, :3] = rotation_exp(axis * np.deg2rad(a))
            out.append(M0 @ R)
    return np.stack(out)


# --- arm configurations -----------------------------------------------------------------------

def configuration_code(conf) -> int:
    """The step's ``elbow`` field for a configuration ``(shoulder, elbow, wrist)`` (signs; 0 counts
    as +): sign = elbow, magnitude ``1 + 2·(wrist = −1) + 4·(shoulder = −1)``."""
    shoulder, elbow, wrist = (int(v) for v in conf)
    return (-1 if elbow < 0 else 1) * (1 + 2 * (wrist < 0) + 4 * (shoulder < 0))


def _within(cfg: CellConfig, q: np.ndarray) -> np.ndarray:
    """``(n,)``: rows of ``q (n, g)`` inside the soft limits with :data:`LIMIT_MARGIN_RAD` (revolute)."""
    rev = np.array([t == "revolute" for t in cfg.model.joint_types])
    m = LIMIT_MARGIN_RAD * rev
    lim = cfg.soft_limits
    return np.all(np.isfinite(q), axis=-1) & np.all((q >= lim[:, 0] + m) & (q <= lim[:, 1] - m), axis=-1)


def _too_close(cfg: CellConfig, q: np.ndarray) -> str:
    """Why ``_within`` refused ``q``: the joint, the side and the margin (docs: every "too close"
    names them)."""
    from station.cell.limits.joint_text import nearest_limit

    need = LIMIT_MARGIN_RAD * np.array([t == "revolute" for t in cfg.model.joint_types])
    near = nearest_limit(q, cfg.soft_limits, cfg.model.joint_types, need)
    return "too close to the soft limits" + ("" if near is None else f": {near.describe(float(need[near.joint - 1]))}")


def _configurations(model: RobotModel) -> tuple:
    """The configurations to try: the eight named ones of a six-axis arm (six revolute joints),
    else one (the solver's choice)."""
    from station.core.kinematics.ik import ALL_ARM_CONFIGS

    six_r = model.n_joints == 6 and all(t == "revolute" for t in model.joint_types)
    return ALL_ARM_CONFIGS if six_r else (None,)


# --- the plan ---------------------------------------------------------------------------------

def articulated_candidates(cfg: CellConfig):
    """(candidates, orientations, rejected): a :class:`station.cell.plan.assembly.Target` for every point ×
    head orientation × configuration whose every motion pose passes the guard, the orientation
    index of each (0 = nominal), and (point id, configuration code, reason) of those rejected.
    Inverse kinematics: :func:`station.core.kinematics.ik.solve_ik` on the nominal model per configuration
    (its deterministic choice), the turned heads near the nominal head's solution."""
    from station.core.kinematics.ik import solve_ik

    model = cfg.model
    guard = MotionGuard(cfg.soft_limits, joint_types=cfg.model.joint_types)
    R_inv = invert(pose_to_matrix(model.nominal[:6]))
    Ms = head_orientations(cfg)
    m = len(Ms)
    T0 = R_inv[None] @ head_targets_world(cfg)
    cands: list = []
    orient: list[int] = []
    rejected: list[tuple[str, int, str]] = []
    for conf in _configurations(model):
        r0 = solve_ik(model, T0, configuration=conf)
        code = 1 if conf is None else configuration_code(conf.as_array())
        inside0 = _within(cfg, np.nan_to_num(r0.joints))
        pts = [j for j in range(len(T0)) if r0.ok[j] and inside0[j]]
        for j in sorted(set(range(len(T0))) - set(pts)):  # named as a SCARA's plan names them, never dropped unseen
            why = r0.reason[j] or _too_close(cfg, r0.joints[j])
            rejected.append((cfg.point_ids[j], code, f"{cfg.point_ids[j]} configuration {code:+d}: {why}"))
        if not pts:
            continue
        heads = cfg.body_points[pts][:, None] @ invert(Ms)[None]  # (p, m, 4, 4) KKS←MKKS
        near = np.repeat(r0.joints[pts], m, axis=0)
        rk = solve_ik(model, R_inv[None] @ heads.reshape(-1, 4, 4), configuration=conf, near=near)
        inside = _within(cfg, rk.joints)
        retract, reached = retract_poses(cfg, np.nan_to_num(rk.joints))
        for a, j in enumerate(pts):
            pid = cfg.point_ids[j]
            for k in range(m):
                i = a * m + k
                what = f"{pid} configuration {code:+d} orientation {k}"
                if not (rk.ok[i] and inside[i]):
                    why = rk.reason[i] or _too_close(cfg, rk.joints[i])
                    rejected.append((pid, code, f"{what}: {why}"))
                    continue
                q = rk.joints[i]
                try:
                    if not reached[i]:
                        raise UnreachableError(f"{what}: the retract pose {cfg.plan.clearance_mm:g} mm off the point "
                                               f"is not reachable")
                    for qq in motion_poses(cfg, q, retract=retract[i]):
                        guard.check_joints(qq, what)
                except UnreachableError as exc:
                    rejected.append((pid, code, str(exc)))
                    continue
                cands.append(Target(j, pid, code, heads[a, k], q))
                orient.append(k)
    return cands, orient, rejected


def order_by_travel(targets: list, weight_mm_per_rad: float = 500.0) -> list:
    """Greedy nearest neighbour in joint space (rad weighted as ``weight_mm_per_rad``, mm as mm),
    a change of configuration counted as a long move."""
    if not targets:
        return targets
    g = len(targets[0].joints)
    w = np.full(g, weight_mm_per_rad)
    q = np.array([t.joints for t in targets])
    codes = np.array([t.elbow for t in targets])
    left = list(range(len(targets)))
    order = [left.pop(0)]
    while left:
        cur = order[-1]
        d = np.sum(np.abs(q[left] - q[cur]) * w, axis=1) + np.where(codes[left] == codes[cur], 0.0, 1e5)
        order.append(left.pop(int(np.argmin(d))))
    return [targets[i] for i in order]


def _shortened(q: np.ndarray, order: list[int]) -> list[int]:
    """``order`` (indices into ``q (n, g)``, an open path from its first element) improved by 2-opt
    under the move time's metric: the largest joint change (every joint taken as fast), which
    the nearest-neighbour tour's summed changes only approximate."""
    path = list(order)
    x = q[path]
    D = np.max(np.abs(x[:, None] - x[None]), axis=-1)
    n = len(path)
    idx = np.arange(n)
    improved = True
    while improved and n > 3:
        improved = False
        for i in range(1, n - 1):
            # reverse idx[i..j]: edges (i-1, i), (j, j+1) become (i-1, j), (i, j+1)
            j = np.arange(i + 1, n)
            nxt = np.minimum(j + 1, n - 1)
            tail = j + 1 < n
            old = D[idx[i - 1], idx[i]] + np.where(tail, D[idx[j], idx[nxt]], 0.0)
            new = D[idx[i - 1], idx[j]] + np.where(tail, D[idx[i], idx[nxt]], 0.0)
            gain = old - new
            k = int(np.argmax(gain))
            if gain[k] > 1e-9:
                idx[i:j[k] + 1] = idx[i:j[k] + 1][::-1]
                improved = True
    return [path[i] for i in idx]


def order_for_time(targets: list) -> list:
    """:func:`order_by_travel`, then each configuration's run shortened by :func:`_shortened`."""
    targets = order_by_travel(targets)
    if len(targets) < 4:
        return targets
    q = np.array([t.joints for t in targets])
    out: list[int] = []
    start = 0
    for end in range(1, len(targets) + 1):
        if end == len(targets) or targets[end].elbow != targets[start].elbow:
            out += _shortened(q, list(range(start, end)))
            start = end
    return [targets[i] for i in out]


def design_terms(cfg: CellConfig):
    """The error terms the identification poses are designed to determine (``[identification]
    model``; issue 30), as a :class:`station.core.terms.error_model.TermSpec`, or None for the geometric
    model. Named families are designed for as named; ``auto`` for the candidates it scores first,
    compliance and the first harmonic of every revolute joint: a design blind to them would leave
    the selection nothing to find. Drift and backlash describe a run, not a pose: no columns."""
    ident = cfg.identification
    if ident.terms == ("geometric",):
        return None
    from station.core.terms.error_model import GravityModel, TermSpec
    from station.core.terms.selection import expand_families

    names = ("compliance", "cyclic") if ident.terms == ("auto",) else ident.terms
    families = tuple(f for f in expand_families(cfg.model, tuple(n for n in names if n not in ("drift", "backlash"))))
    if not families:
        return None
    return TermSpec(families, ident.gravity or GravityModel(), ident.gear_ratios)


def _design_jacobians(cfg: CellConfig, q_cand: np.ndarray, q_work: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Noise-weighted pose Jacobians ``(c, 6, p)`` of the candidates and position Jacobians
    ``(m, 3, p)`` [mm per parameter unit] at the working poses, over the minimal parameter set the
    candidates identify (the run's: the same prefer / fix / exclude)."""
    from station.core.identification.identifiability import analyze
    from station.core.measurement.measurements import residuals_and_jacobian, synthetic_set

    sig = cfg.identification.pose_sigma()
    data = synthetic_set(cfg.model, "pose", q_cand, cfg.model.nominal, sigma=sig)
    a = analyze(cfg.model, data, prefer=cfg.identification.prefer, fix=cfg.identification.fix,
                exclude=cfg.identification.exclude, describe=False)
    idx = a.chosen_indices()
    spec = design_terms(cfg)
    if spec is not None:  # [identification] model: the terms' columns beside the geometry's (issue 30)
        from station.core.terms.design import design_jacobians

        J, G, _names = design_jacobians(cfg.model, cfg.model.nominal, idx, spec, q_cand, q_work, sig)
        return J, G
    _, J = residuals_and_jacobian(cfg.model, data, cfg.model.nominal)
    J = (J / data.sigma[:, None])[:, idx].reshape(len(q_cand), 6, -1)
    work = synthetic_set(cfg.model, "pose", q_work, cfg.model.nominal, sigma=sig)
    _, G = residuals_and_jacobian(cfg.model, work, cfg.model.nominal)
    G = G[:, idx].reshape(len(q_work), 6, -1)[:, :3]
    return J, G


def held_out_spread(cfg: CellConfig, nominal: list) -> set[int]:
    """Indices (into ``nominal``, the nominal-orientation candidates) of the held-out targets:
    as many as ``[plan] verification_every`` asks, at least :data:`MIN_HELD_OUT` (a held-out RMS
    of fewer poses is too noisy to judge the correction by) and never more than
    :data:`MAX_HELD_OUT_FRACTION`, spread over the joint space by farthest-point sampling, every
    configuration before any twice."""
    from station.core.identification.pose_design import spread_indices

    n = len(nominal)
    want = max(-(-n // max(cfg.plan.verification_every, 1)), MIN_HELD_OUT)
    want = min(want, int(MAX_HELD_OUT_FRACTION * n)) if n >= 2 else 0
    q = np.array([t.joints for t in nominal]) * 500.0  # rad weighted as mm at a 0.5 m lever
    return set(spread_indices(q, want, np.array([t.elbow for t in nominal])))


@dataclass(frozen=True)
class IdentificationDesign:
    """How many identification poses the plan takes and why (``station plan`` says it).
    ``n_poses`` of ``n_candidates``, at most ``cap`` (``[plan] select``); ``n_parameters`` identifiable,
    ``min_poses`` (⌈2p/6⌉: every parameter determined twice over by the pose rows); ``noise_um``: σ of
    one measured position, ``target_um`` = :data:`NOISE_FRACTION` of it; ``sigma_work_um``: the
    predicted σ of the correction (RMS over the working poses, body frame, every repeat counted),
    ``sigma_held_um`` (min, mean, max) at the held-out targets; ``stopped_by``: "noise" (the rule was
    met), "cap" or "candidates" (it was not, the poses ran out first)."""

    n_poses: int
    n_candidates: int
    cap: int
    n_parameters: int
    min_poses: int
    repeats: int
    noise_um: float
    target_um: float
    sigma_work_um: float
    sigma_held_um: tuple[float, float, float]
    stopped_by: str

    def describe(self) -> str:
        why = {"noise": f"enough: the predicted σ at the working poses reached {self.target_um:.1f} µm "
                        f"(1/{1 / NOISE_FRACTION:g} of the {self.noise_um:g} µm measurement σ), more poses buy "
                        f"less than 3 % of the held-out RMS",
               "cap": f"[plan] select = {self.cap} reached before the predicted σ came down to "
                      f"{self.target_um:.1f} µm (1/{1 / NOISE_FRACTION:g} of the {self.noise_um:g} µm measurement σ)",
               "candidates": f"every candidate taken before the predicted σ came down to {self.target_um:.1f} µm"}
        return (f"{self.n_poses} identification poses of {self.n_candidates} candidates × {self.repeats} repeats "
                f"(I-optimal; at least {self.min_poses} for the {self.n_parameters} identifiable parameters): "
                f"{why[self.stopped_by]}; predicted σ {self.sigma_work_um:.1f} µm at the working poses")


@dataclass(frozen=True)
class ArticulatedPlan(Plan):
    """The plan of an articulated arm: :class:`~station.cell.plan.assembly.Plan` with the
    verification grouped by arm configuration, and the identification design's account."""

    design: IdentificationDesign | None = None

    def run_steps(self, cycles: int, with_oracle: bool, with_upload: bool = True) -> tuple[PlannedStep, ...]:
        """As :meth:`Plan.run_steps`, but each pass (before / after / oracle) does every cycle of one
        arm configuration's targets before the next configuration (:func:`_cycles`), and every
        other pass takes the configurations in reverse: a change of configuration (a long move:
        shoulder or wrist flipped) then comes once per configuration and pass, not once per
        cycle, and the passes join where they end. The order within a pass does not enter the
        figures."""
        steps = list(self.identification)
        kinds = [StepKind.VERIFY_BEFORE]
        if with_upload:
            kinds += [StepKind.VERIFY_AFTER] + ([StepKind.REFERENCE] if with_oracle else [])
        groups: list[list[Target]] = []
        for t in self.verification:
            if groups and groups[-1][0].elbow == t.elbow:
                groups[-1].append(t)
            else:
                groups.append([t])
        last: Target | None = None
        for k, kind in enumerate(kinds):
            for group in (groups if k % 2 == 0 else groups[::-1]):
                for cycle, order in enumerate(_cycles(group, cycles, last)):
                    for t in order:
                        steps.append(PlannedStep(len(steps), kind, t.point, t.point_id, t.elbow, 1, cycle,
                                                 tuple(float(v) for v in t.joints)))
                    last = order[-1]
        return tuple(steps)


def _cycles(group: list, cycles: int, last) -> list[list]:
    """The visiting order of each cycle over one configuration's targets (``group``, a short open
    path) entered from ``last`` (the target just read, or None): there and back (no long move
    from the path's end to its start), each cycle beginning at the end the robot stands at, its
    first two swapped when the first is ``last``: every reading of a target then comes from a
    separate visit, another target read in between (ISO 9283's cycles), at the cost of one short
    move and back."""
    out = []
    for _ in range(cycles):
        order = group[::-1] if last is group[-1] and len(group) > 1 else list(group)
        if len(order) > 1 and order[0] is last:
            order = [order[1], order[0], *order[2:]]
        out.append(order)
        last = order[-1]
    return out


def _select_identification(cfg: CellConfig, ident: list, q_work: np.ndarray, held_local: set[int]
                           ) -> tuple[list, IdentificationDesign]:
    """The I-optimal identification poses under the stopping rule (:data:`NOISE_FRACTION`), at
    most ``[plan] select``, and the design's account."""
    from station.core.identification.pose_design import select_i_optimal

    J, G = _design_jacobians(cfg, np.array([t.joints for t in ident]), q_work)
    c, r, p = J.shape
    repeats = max(cfg.plan.repeats, 1)
    noise_mm = float(cfg.identification.pose_sigma()[0])
    target = NOISE_FRACTION * noise_mm
    cap = cfg.plan.select if cfg.plan.select else c
    # the criterion weighs one measurement per pose; the repeats divide its variance
    design = select_i_optimal(J, G, min(cap, c), enough=target**2 * repeats)
    chosen = sorted(design.chosen)
    C = np.linalg.inv(1e-9 * np.eye(p) + sum(J[i].T @ J[i] for i in chosen)) / repeats
    sig = np.sqrt(np.maximum(np.einsum("msp,pq,msq->m", G, C, G), 0.0)) * 1e3
    held = sig[sorted(held_local)] if held_local else sig
    mean_var = float(np.mean(sig**2))
    met = design.mean_variance.size > 0 and float(design.mean_variance[-1]) <= target**2 * repeats
    stopped = "noise" if met else ("cap" if len(chosen) >= cap else "candidates")
    account = IdentificationDesign(
        n_poses=len(chosen), n_candidates=c, cap=cap, n_parameters=p, min_poses=-(-2 * p // r), repeats=repeats,
        noise_um=noise_mm * 1e3, target_um=target * 1e3, sigma_work_um=float(np.sqrt(mean_var)),
        sigma_held_um=(float(held.min()), float(np.sqrt(np.mean(held**2))), float(held.max())), stopped_by=stopped)
    return [ident[i] for i in chosen], account


def _start_with(verification: list, elbow: int) -> tuple:
    """The held-out targets (grouped by configuration) with the group of ``elbow`` first: the
    verification begins in the configuration the identification ends in."""
    first = [t for t in verification if t.elbow == elbow]
    return tuple(first + [t for t in verification if t.elbow != elbow])


def build_articulated_plan(cfg: CellConfig) -> ArticulatedPlan:
    """The :class:`ArticulatedPlan` of an articulated arm (see the module docstring)."""
    if cfg.plan.both_directions:
        raise ConfigError("plan.both_directions: the reversal measurement is planned for SCARA robots only; "
                          "set it to false for an articulated arm")
    cands, orient, rejected = articulated_candidates(cfg)
    cands, orient, clashing = clear_candidates(cfg, cands, orient)
    rejected = [*rejected, *clashing]
    if not cands:
        raise ConfigError("no measuring point is reachable within the soft limits; check [robot].setup and [limits]")
    nominal = [i for i, k in enumerate(orient) if k == 0]
    held_local = held_out_spread(cfg, [cands[i] for i in nominal])
    held = {nominal[i] for i in held_local}
    # each verification pass visits the spread targets in travel order, as the identification does
    verification = order_for_time([c for i, c in enumerate(cands) if i in held])
    ident = [c for i, c in enumerate(cands) if i not in held]
    account = None
    if cfg.plan.select and ident:
        # I-optimal over the working poses (every nominal contact, held-out ones included): the
        # accuracy the verification judges, not only the parameters' volume (D-optimality)
        q_work = np.array([cands[i].joints for i in nominal])
        ident, account = _select_identification(cfg, ident, q_work, held_local)
        cfg = dataclasses.replace(cfg, plan=dataclasses.replace(cfg.plan, select=0))
    plan = assemble_plan(cfg, ident, (), list(rejected), order_for_time)
    last = plan.identification[-1].elbow if plan.identification else verification[0].elbow if verification else 1
    return ArticulatedPlan(plan.identification, _start_with(verification, last), plan.rejected, account)
