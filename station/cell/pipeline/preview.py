"""The plan preview: everything that can be known about a run before the robot moves.

Per step: the order, the joints, the margin to the soft limits, the clearance of the travel
height above the highest measuring point; for the design: the identifiable parameter set and its
condition, the minimum of valid identification poses the run needs, and the attainable accuracy
predicted by linear propagation of the measurement noise (parameter uncertainty only: no probe
noise, repeatability or backlash of the verification itself; the body's CMM uncertainty is included
when the body report gives one).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from station.cell.config.cell_config import CellConfig
from station.cell.pipeline.calibration import MIN_VALID_FRACTION, min_valid_identification
from station.cell.plan.articulated import IdentificationDesign
from station.cell.plan.measurement_plan import Plan, all_motion_poses, build_plan, retracted, travel_joints
from station.cell.plan.steps import PlannedStep, StepKind
from station.core.identification.base_frame import base_frame_note
from station.core.identification.identifiability import analyze
from station.core.kinematics.forward import forward, scara_reach_margin
from station.core.measurement.measurements import residuals_and_jacobian, synthetic_set
from station.core.measurement.uncertainty import body_sandwich, linear_uncertainty, pose_accuracy
from station.core.units import ARCSEC, DEG
from station.io.robot.formats import SPEED_HINT


@dataclass(frozen=True)
class StepPreview:
    step: PlannedStep
    limit_margin: tuple[float, ...]  # per joint: distance to the nearer soft limit [deg | mm]
    reach_margin_mm: float | None = None  # SCARA: wrist axis inside the stretched / folded arm [mm]


@dataclass(frozen=True)
class PlanPreview:
    cell: str
    robot: str
    steps: tuple[StepPreview, ...]
    rejected: tuple[tuple[str, int, str], ...]
    n_identification: int
    n_verification_targets: int
    min_valid_identification: int
    travel_clearance_mm: float | None  # travel height above the highest point's target height
    identifiable: tuple[str, ...]
    condition: float
    sigma_position_um: tuple[float, float, float]  # predicted σ over the held-out poses: min, mean, max
    sigma_orientation_arcsec: tuple[float, float, float]
    settle_s_total: float
    joint_types: tuple[str, ...] = ()
    #: motion time [s] at [plan].speed from the robot file's joint speeds (None: not given there)
    motion_s_estimate: float | None = None
    #: an articulated arm's identification design: how many poses and why, σ at the held-out targets
    design: IdentificationDesign | None = None
    #: [identification] model: "geometric", or the error terms beyond geometry chosen after the measurement
    error_model: str = "geometric"
    #: which directions are the set-up's and what the base frame is tied to, in words (issue 36)
    base_frame: str | None = None

    def to_json(self) -> dict[str, Any]:
        return {
            "cell": self.cell, "robot": self.robot,
            "steps": [{"order": i + 1, "index": p.step.index, "kind": p.step.kind.value, "point_id": p.step.point_id,
                       "elbow": p.step.elbow, "direction": p.step.direction, "cycle": p.step.cycle,
                       "joints": list(p.step.joints), "limit_margin": list(p.limit_margin),
                       "reach_margin_mm": p.reach_margin_mm}
                      for i, p in enumerate(self.steps)],
            "rejected": [{"point_id": pid, "elbow": e, "reason": why} for pid, e, why in self.rejected],
            "n_identification": self.n_identification, "n_verification_targets": self.n_verification_targets,
            "min_valid_identification": self.min_valid_identification,
            "travel_clearance_mm": self.travel_clearance_mm,
            "identifiable": list(self.identifiable), "condition": self.condition, "base_frame": self.base_frame,
            "predicted_sigma_position_um": dict(zip(("min", "mean", "max"), self.sigma_position_um)),
            "predicted_sigma_orientation_arcsec": dict(zip(("min", "mean", "max"), self.sigma_orientation_arcsec)),
            "predicted_accuracy_includes": "parameter uncertainty from the measurement noise only",
            "settle_s_total": self.settle_s_total,
            "motion_s_estimate": self.motion_s_estimate,
            "identification_design": None if self.design is None else dataclasses.asdict(self.design),
            "error_model": self.error_model,
            "motion_estimate_basis": "each move at the slowest joint's maximum speed × [plan].speed, no acceleration",
            "units": {"joints": "rad | mm", "limit_margin": "deg | mm", "reach_margin_mm": "mm"},
        }


def _margins(cfg: CellConfig, q: np.ndarray) -> tuple[float, ...]:
    lo, hi = cfg.soft_limits[:, 0], cfg.soft_limits[:, 1]
    m = np.minimum(q - lo, hi - q)
    scale = np.array([1 / DEG if k == "revolute" else 1.0 for k in cfg.model.joint_types])
    return tuple(float(v) for v in m * scale)


def _reach(cfg: CellConfig, steps: tuple[PlannedStep, ...]) -> list[float | None]:
    """Per step the reach margin [mm] of a SCARA (None for other robots: their configurations'
    margins are the soft-limit margins and the IK's singularity check)."""
    if not cfg.model.is_scara or not steps:
        return [None] * len(steps)
    T = forward(cfg.model, np.array([s.q for s in steps]), setup=False)
    return [float(v) for v in scara_reach_margin(cfg.model, T)]


def motion_seconds(cfg: CellConfig, steps: tuple[PlannedStep, ...]) -> float | None:
    """Motion time [s] of ``steps`` from the robot file's joint speeds at ``[plan].speed``: every
    move a measurement makes (approach, above the point, touch, retract) at the speed of its
    slowest joint, without acceleration, so a real robot takes somewhat longer. None when the
    robot file gives no speeds."""
    v = cfg.model.max_speed
    if v is None or not steps:
        return None
    vmax = np.asarray(v, dtype=float) * cfg.plan.speed
    path = []
    for s in steps:
        q = np.asarray(s.q, dtype=float)
        path += [*all_motion_poses(cfg, q, s.direction), retracted(cfg, q)]
    dq = np.abs(np.diff(np.array(path), axis=0))
    return float(np.sum(np.max(dq / vmax, axis=1)))


def preview(cfg: CellConfig, with_upload: bool = True) -> PlanPreview:
    """The preview of the run ``station calibrate`` would make with ``cfg`` (nothing moves).
    Raises the plan's :class:`~station.errors.ConfigError` when no point is reachable."""
    plan: Plan = build_plan(cfg)
    steps = plan.run_steps(cfg.plan.verification_cycles, with_oracle=False, with_upload=with_upload)
    ident_q = np.array([s.q for s in plan.identification if s.kind is StepKind.IDENTIFICATION])
    sig = cfg.identification.pose_sigma()
    data = synthetic_set(cfg.model, "pose", ident_q, cfg.model.nominal, sigma=sig)
    a = analyze(cfg.model, data, prefer=cfg.identification.prefer, fix=cfg.identification.fix,
                exclude=cfg.identification.exclude)  # dependencies read once: the base frame's words
    _, J = residuals_and_jacobian(cfg.model, data, cfg.model.nominal)
    idx = a.chosen_indices()
    if cfg.body_sigma is not None and np.any(cfg.body_sigma > 0):
        # the body's CMM σ is shared by every measurement of a point: the same sandwich as the run's
        points = np.array([s.point for s in plan.identification if s.kind is StepKind.IDENTIFICATION])
        heads = forward(cfg.model, ident_q, setup=True)
        data = data.with_body(points, cfg.body_sigma, heads[:, :3, 3] - cfg.body_points[points, :3, 3])
        fit = data.fit_sigma()
        unc = body_sandwich((J / fit[:, None])[:, idx], tuple(a.chosen), data, fit)
    else:
        unc = linear_uncertainty((J / data.sigma[:, None])[:, idx], tuple(a.chosen))
    q_ver = np.array([t.joints for t in plan.verification]) if plan.verification else ident_q
    acc = pose_accuracy(cfg.model, cfg.model.nominal, idx, unc.covariance, q_ver, setup=False)
    pos = np.linalg.norm(acc.sigma[:, :3], axis=1) * 1e3
    ori = np.linalg.norm(acc.sigma[:, 3:], axis=1) / ARCSEC
    travel = travel_joints(cfg)
    prism = [j for j, k in enumerate(cfg.model.joint_types) if k == "prismatic"]
    clearance = None
    if prism and ident_q.size:
        j = prism[0]
        clearance = float(travel[j] - max(float(s.q[j]) for s in steps))
    n_ident = sum(1 for s in steps if s.kind is StepKind.IDENTIFICATION)
    return PlanPreview(
        cell=cfg.name, robot=cfg.model.name,
        steps=tuple(StepPreview(s, _margins(cfg, s.q), r) for s, r in zip(steps, _reach(cfg, steps))),
        rejected=plan.rejected,
        n_identification=n_ident, n_verification_targets=len(plan.verification),
        min_valid_identification=min_valid_identification(n_ident), travel_clearance_mm=clearance,
        identifiable=tuple(a.chosen), condition=float(a.chosen_condition),
        sigma_position_um=(float(pos.min()), float(pos.mean()), float(pos.max())),
        sigma_orientation_arcsec=(float(ori.min()), float(ori.mean()), float(ori.max())),
        settle_s_total=float(len(steps) * cfg.plan.settle_s), joint_types=tuple(cfg.model.joint_types),
        motion_s_estimate=motion_seconds(cfg, steps), design=getattr(plan, "design", None),
        error_model=cfg.identification.model, base_frame=base_frame_note(cfg.model, a))


def describe(p: PlanPreview) -> list[str]:
    """The preview as lines for people."""
    lines = [f"plan for {p.cell} ({p.robot}): {len(p.steps)} steps, {p.n_identification} identification, "
             f"{p.n_verification_targets} held-out targets"]
    lines.append(f"  a run needs at least {p.min_valid_identification} valid identification poses "
                 f"({MIN_VALID_FRACTION:.0%} of those planned)")
    lines.append(f"  identifiable: {len(p.identifiable)} parameters, condition {p.condition:.1f}")
    if p.base_frame is not None:
        lines.append(f"  {p.base_frame}")
    lines.append(f"  predicted accuracy after correction (parameter uncertainty only): position σ "
                 f"{p.sigma_position_um[0]:.1f}–{p.sigma_position_um[2]:.1f} µm, orientation σ "
                 f"{p.sigma_orientation_arcsec[0]:.1f}–{p.sigma_orientation_arcsec[2]:.1f}″")
    if p.design is not None:
        d = p.design
        lines.append(f"  {d.describe()}")
        lines.append(f"  predicted accuracy at the {p.n_verification_targets} held-out targets (body frame, as the "
                     f"verification measures them): position σ {d.sigma_held_um[0]:.1f}–{d.sigma_held_um[2]:.1f} µm, "
                     f"RMS {d.sigma_held_um[1]:.1f} µm")
    if p.error_model != "geometric":  # the terms are chosen from the measurements (docs/error-terms.md)
        lines.append(f"  error model: {p.error_model} (terms beyond geometry, fitted after the measurement; the "
                     f"predicted accuracy above is the geometric model's)")
    if p.travel_clearance_mm is not None:
        lines.append(f"  travel height: {p.travel_clearance_mm:.1f} mm above the highest target")
    if p.motion_s_estimate is None:
        lines.append(f"  settling: {p.settle_s_total:.0f} s in all; motion time is not estimated "
                     f"(the robot file gives no joint speeds: {SPEED_HINT})")
    else:
        total = p.motion_s_estimate + p.settle_s_total
        lines.append(f"  estimated duration: {total / 60:.1f} min ({p.motion_s_estimate:.0f} s of motion at the "
                     f"robot file's joint speeds × [plan].speed, no acceleration; {p.settle_s_total:.0f} s settling)")
    if p.steps:
        tight = min(p.steps, key=lambda s: min(s.limit_margin))
        j = int(np.argmin(tight.limit_margin))
        unit = "°" if p.joint_types[j:j + 1] == ("revolute",) else " mm"
        lines.append(f"  smallest margin to a soft limit: {tight.limit_margin[j]:.2f}{unit} (joint {j + 1}) at step "
                     f"{tight.step.index + 1} ({tight.step.point_id} elbow {tight.step.elbow:+d})")
        reach = [s for s in p.steps if s.reach_margin_mm is not None]
        if reach:
            r = min(reach, key=lambda s: s.reach_margin_mm or 0.0)
            lines.append(f"  smallest reach margin (stretched or folded arm): {r.reach_margin_mm:.1f} mm at step "
                         f"{r.step.index + 1} ({r.step.point_id} elbow {r.step.elbow:+d})")
    for pid, elbow, why in p.rejected:
        why = why.split(": ", 1)[1] if why.startswith(pid) else why
        pose = "elbow" if "prismatic" in p.joint_types else "configuration"  # a six-axis arm has no elbow sign
        lines.append(f"  NOT measured: {pid} {pose} {elbow:+d}: {why}")
    lines.append(f"  {'order':>5}  {'kind':22}  {'point':10}  {'elbow':>5}  {'limit':>7}  {'reach':>7}  joints")
    for i, s in enumerate(p.steps):
        st = s.step
        q = ", ".join(f"{v / DEG:.2f}°" if k == "revolute" else f"{v:.1f} mm"
                      for v, k in zip(st.joints, p.joint_types))
        margin = "–" if s.reach_margin_mm is None else f"{s.reach_margin_mm:.0f} mm"
        lines.append(f"  {i + 1:>5}  {st.kind.value:22}  {st.point_id:10}  {st.elbow:+5d}  "
                     f"{min(s.limit_margin):7.1f}  {margin:>7}  {q}")
    return lines
