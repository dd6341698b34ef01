"""``station recheck``: a short check of a few poses against a baseline calibration (issue 13).

A recheck is a run like a calibration: the same run database, runner, motion guard, resume
(fingerprint), events and typed steps (:attr:`StepKind.RECHECK`). It

1. plans a few poses (``[recheck].poses``, 10 by default) chosen with the identification core to be
   sensitive to what drifts: greedy D-optimality on the Jacobian columns of the joint offsets,
   the arm lengths and the head's x, y (a bumped tool) at the baseline's model, spread over the
   elbows; the first pose is measured once more at the end (the repeat tells whether the cell
   itself is still moving);
2. measures them with joint moves approached exactly as the calibration did (the controller's
   correction table is not touched, and not used);
3. compares each measured head pose with the pose the baseline's identified model predicts for
   the joints read (µm, arc seconds), and identifies the drift of the offsets, lengths and head
   linearly, with σ (measurement noise scaled by the fit's χ², and the baseline's own σ);
4. decides: ``SUCCESS`` (within tolerance), ``DRIFTED`` (RMS drift above ``tolerance_um``, or a
   parameter moved by more than 3σ and more than its tolerance — recalibrate) or
   ``RECHECK_UNTRUSTED`` (too few valid readings, or the repeated pose moved).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from station.cell.config.cell_config import CellConfig
from station.cell.plan.measurement_plan import Target, build_plan, order_by_travel
from station.cell.plan.steps import PlannedStep, StepKind
from station.cell.records.fingerprint import baseline_fingerprint, check_same_cell, current_like, fingerprint
from station.cell.records.reading.stored_config import stored_config
from station.cell.records.run_records import MeasurementRecord, RunDatabaseError
from station.cell.records.rundb import RunDB
from station.cell.records.summary import RunSummary
from station.cell.run.devices import CellController, ProbeHead
from station.cell.run.facts.events import Event, Notice, PhaseChanged, RunFinished, RunStarted
from station.cell.run.runcontrol import RunControl
from station.cell.run.runner import Runner, approach_and_read
from station.cell.run.warmup import run_warmup
from station.core.kinematics.forward import forward
from station.core.kinematics.transforms import invert, rotation_log
from station.core.units import ARCSEC
from station.errors import ConfigError, Outcome, RunAborted

#: share of the planned recheck poses that must be valid for a verdict
MIN_VALID_FRACTION = 0.8
#: a parameter moved when |Δ| exceeds this many σ (and its tolerance)
SIGMAS = 3.0
#: lever [mm] that turns a position tolerance into a joint-offset tolerance
LEVER_MM = 500.0
#: the baseline's accuracy times this is the default position tolerance
TOLERANCE_FACTOR = 3.0


# --------------------------------------------------------------------------------------------
# the baseline
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Baseline:
    """What a recheck compares with: a calibration run's identified model and accuracy."""

    run_id: int
    created_utc: str
    params: np.ndarray  # (n_params,) the identified model [mm, rad] (with terms: the geometry fitted with them)
    sigma: Mapping[str, float]  # σ of the identified parameters by name
    after_rms_um: float | None  # the baseline's verification after correction
    residual_rms_um: float | None  # its identification residual (with terms: the fit with them)
    outcome: str | None
    #: ``Δq(q)`` of the error terms the baseline kept (issue 30): the robot commanded ``q`` stands at
    #: ``q + Δq(q)``; None: the baseline's model is geometric
    joint_delta: Callable[[np.ndarray], np.ndarray] | None = None
    terms: tuple[str, ...] = ()  # the kept families, for the report

    def standing(self, q: np.ndarray) -> np.ndarray:
        """``(n, g)`` joints where the baseline's model says a robot that read ``q`` stands."""
        return q if self.joint_delta is None else q + self.joint_delta(q)

    @property
    def accuracy_um(self) -> float:
        """The accuracy the baseline showed: the larger of its verification RMS after correction
        and its identification residual RMS (whatever it stored), at least 1 µm."""
        vals = [v for v in (self.after_rms_um, self.residual_rms_um) if v is not None and math.isfinite(v)]
        return max([1.0, *vals])


def _is_recheck(db: RunDB, run_id: int) -> bool:
    plan = db.run(run_id).plan
    return bool(plan) and all(rec.get("kind") == StepKind.RECHECK.value for rec in plan)


def load_baseline(db: RunDB, run_id: int, cfg: CellConfig) -> Baseline:
    """The calibration ``run_id`` as a baseline (ConfigError when it has no identified model). A
    calibration that kept error terms beyond geometry (result ``error_model``) is compared with that
    model, terms and all: the geometric fit alone would count what the terms explain as drift."""
    run = db.run(run_id)
    if _is_recheck(db, run_id):
        raise ConfigError(f"run {run_id} is a recheck, not a calibration; give a calibration run as --baseline")
    ident = db.load_result(run_id, "identification", default=None)
    if ident is None:
        raise ConfigError(f"run {run_id} has no identified model (it stopped before the identification); "
                          f"give a calibration that reached its end as --baseline")
    stored = db.load_result(run_id, "summary", default=None)
    summary = RunSummary.from_json(stored) if stored else None
    names = list(ident.get("chosen", []))
    sig = dict(zip(names, (float(s) for s in ident.get("sigma", []))))
    from station.cell.pipeline.terms import stored_error_model

    terms = stored_error_model(cfg, db.load_result(run_id, "error_model", default=None))
    residual = summary.identification.rms_residual_um if summary and summary.identification else None
    return Baseline(run_id=run_id, created_utc=run.created_utc,
                    params=np.asarray(ident["params"] if terms is None else terms.params, dtype=float),
                    sigma=sig,
                    after_rms_um=summary.after.rms_um if summary and summary.after else None,
                    residual_rms_um=residual if terms is None or terms.rms_residual_um is None else terms.rms_residual_um,
                    outcome=summary.outcome.name if summary else None,
                    joint_delta=None if terms is None else terms.joint_delta(cfg),
                    terms=() if terms is None else terms.families)


def check_baseline_cell(db: RunDB, run_id: int, cfg: CellConfig) -> None:
    """Refuse a baseline measured on another cell (ConfigError naming what changed); the
    recheck's own settings, the warm-up and a simulated drift may differ."""
    run = db.run(run_id)
    fp = db.load_result(run_id, "fingerprint", default=None)
    # with the files' contents stored, their paths do not count (a moved or copied cell folder)
    stored = baseline_fingerprint(run.config_toml, by_content=fp is not None)
    current = baseline_fingerprint(cfg.source_text, by_content=fp is not None)
    if fp is not None:  # what the files the configuration names held (robot, body report, head)
        now = fingerprint(cfg)
        for key in ("robot model", "body points", "probe head"):
            if key in fp or key in now:
                stored[key], current[key] = fp.get(key, ""), now.get(key, "")
    changed = sorted(k for k in stored.keys() | current.keys() if stored.get(k) != current.get(k))
    if changed:
        raise ConfigError(f"baseline run {run_id} was calibrated on a different cell: {', '.join(changed)} changed "
                          f"since. A recheck against it would compare two cells; give the baseline of this cell "
                          f"with --baseline RUN, or calibrate this cell first")


def find_baseline(db: RunDB, cfg: CellConfig) -> int:
    """The latest successful calibration of this cell (same baseline fingerprint) in ``db``."""
    others = []
    for run in db.runs():
        stored = db.load_result(run.id, "summary", default=None)
        if not stored or stored.get("outcome") != "SUCCESS" or _is_recheck(db, run.id):
            continue
        try:
            check_baseline_cell(db, run.id, cfg)
        except ConfigError:
            others.append(run.id)
            continue
        return run.id
    more = (f" (runs {', '.join(map(str, others))} are successful calibrations of another cell or configuration)"
            if others else "")
    raise ConfigError(f"no successful calibration of this cell in the run database{more}; calibrate first "
                      f"('station calibrate CONFIG'), or name the baseline with --baseline RUN")


# --------------------------------------------------------------------------------------------
# what drifts, and the plan
# --------------------------------------------------------------------------------------------

def drift_parameters(cfg: CellConfig) -> list[int]:
    """Indices of the parameters a recheck identifies: every joint offset (yaw of a revolute
    joint's transform, z of a prismatic one), the arm lengths (the in-plane translation of each
    joint transform after the first that is not zero) and the head's x and y (a bumped tool).
    The head's z is left out: it merges with the prismatic joint's offset."""
    m = cfg.model
    idx = []
    for j, t in enumerate(m.joint_transforms):
        idx.append(6 * t + (5 if m.joint_types[j] == "revolute" else 2))
    for t in m.joint_transforms[1:]:
        xy = np.abs(np.asarray(m.nominal[6 * t: 6 * t + 2], dtype=float))
        if xy.max() > 1.0:
            idx.append(6 * t + int(np.argmax(xy)))
    k = m.n_params - 6
    idx += [k, k + 1]
    return sorted(set(idx))


def describe_parameter(cfg: CellConfig, name: str) -> tuple[str, str]:
    """(what an engineer calls it, kind: 'offset' | 'length' | 'tool')."""
    m = cfg.model
    i = m.param_index(name)
    for j, t in enumerate(m.joint_transforms):
        if i == 6 * t + (5 if m.joint_types[j] == "revolute" else 2):
            return f"joint {j + 1} offset ({name})", "offset"
    if i >= m.n_params - 6:
        return f"tool {name[-1]} ({name})", "tool"
    arms = [6 * t + int(np.argmax(np.abs(m.nominal[6 * t: 6 * t + 2]))) for t in m.joint_transforms[1:]]
    if i in arms:
        return f"arm {arms.index(i) + 1} length ({name})", "length"
    return name, "length"


def _pose_error(T_meas: np.ndarray, T_pred: np.ndarray) -> np.ndarray:
    """(…, 6): measured − predicted position [mm] and rotation vector [rad], world frame."""
    dp = T_meas[..., :3, 3] - T_pred[..., :3, 3]
    dr = rotation_log(T_meas[..., :3, :3] @ np.swapaxes(T_pred[..., :3, :3], -1, -2))
    return np.concatenate([dp, dr], axis=-1)


def drift_jacobian(cfg: CellConfig, params: np.ndarray, q: np.ndarray, idx: Sequence[int]) -> np.ndarray:
    """(n, 6, k): change of the pose error per unit change of each drift parameter (central
    differences of the forward kinematics at ``params``)."""
    q = np.atleast_2d(q)
    out = np.zeros((len(q), 6, len(idx)))
    T0 = forward(cfg.model, q, params=params, setup=True)
    for c, i in enumerate(idx):
        h = 1e-6
        p1 = np.array(params, dtype=float)
        p1[i] += h
        T1 = forward(cfg.model, q, params=p1, setup=True)
        out[:, :, c] = _pose_error(T1, T0) / h
    return out


def _candidates(cfg: CellConfig) -> list[Target]:
    plan = build_plan(cfg)
    seen: dict[tuple[int, int], Target] = {}
    for st in plan.identification:
        key = (st.point, st.elbow)
        if key not in seen and st.direction > 0:
            seen[key] = Target(st.point, st.point_id, st.elbow, cfg.body_points[st.point], st.q)
    for t in plan.verification:
        seen.setdefault((t.point, t.elbow), t)
    return [seen[k] for k in sorted(seen)]


def plan_recheck(cfg: CellConfig, params: np.ndarray, n: int | None = None) -> tuple[PlannedStep, ...]:
    """The recheck's steps: ``n`` poses (``[recheck].poses``) chosen by greedy D-optimality on
    the drift parameters' Jacobian at ``params``, an equal share per elbow, ordered for short
    travel, and the first pose once more at the end (cycle 1)."""
    n = int(n or cfg.recheck.poses)
    cands = _candidates(cfg)
    if len(cands) < 3:
        raise ConfigError("fewer than 3 measuring poses are reachable; a recheck needs at least 3")
    n = min(n, len(cands))
    idx = drift_parameters(cfg)
    J = drift_jacobian(cfg, params, np.array([c.joints for c in cands]), idx)
    J = J / cfg.identification.pose_sigma()[None, :, None]
    elbows = sorted({c.elbow for c in cands}, reverse=True)
    quota = {e: math.ceil(n / len(elbows)) for e in elbows}
    info = 1e-9 * np.eye(len(idx))
    chosen: list[int] = []
    while len(chosen) < n:
        best, best_val = None, -np.inf
        for i, c in enumerate(cands):
            if i in chosen or quota[c.elbow] <= 0:
                continue
            sign, val = np.linalg.slogdet(info + J[i].T @ J[i])
            if sign > 0 and val > best_val:
                best, best_val = i, val
        if best is None:
            break
        chosen.append(best)
        quota[cands[best].elbow] -= 1
        info = info + J[best].T @ J[best]
    targets = order_by_travel([cands[i] for i in sorted(chosen)])
    steps = [PlannedStep(k, StepKind.RECHECK, t.point, t.point_id, t.elbow, 1, 0, tuple(float(v) for v in t.joints))
             for k, t in enumerate(targets)]
    first = steps[0]
    steps.append(dataclasses.replace(first, index=len(steps), cycle=1))
    return tuple(steps)


# --------------------------------------------------------------------------------------------
# the analysis (pure: the statistics test calls it in-process)
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Tolerances:
    position_um: float
    offset_arcsec: float
    length_um: float
    repeat_um: float
    derived: bool  # from the baseline's accuracy (position_um not configured)

    @classmethod
    def for_(cls, cfg: CellConfig, baseline: Baseline) -> Tolerances:
        r = cfg.recheck
        pos = r.tolerance_um or TOLERANCE_FACTOR * baseline.accuracy_um
        return cls(position_um=pos,
                   offset_arcsec=r.offset_tolerance_arcsec or pos * 1e-3 / LEVER_MM / ARCSEC,
                   length_um=r.length_tolerance_um or pos,
                   repeat_um=r.repeat_tolerance_um or pos,
                   derived=not r.tolerance_um)


@dataclass(frozen=True)
class PoseDrift:
    point_id: str
    elbow: int
    position_um: float
    angle_arcsec: float


@dataclass(frozen=True)
class ParameterDrift:
    """Δ of a drift parameter since the baseline, in µm (lengths, tool) or arc seconds (offsets)."""

    name: str
    label: str
    kind: str
    delta: float
    sigma: float
    unit: str
    tolerance: float
    moved: bool


@dataclass(frozen=True)
class RecheckResult:
    outcome: Outcome
    poses: tuple[PoseDrift, ...]
    n_planned: int
    n_valid: int
    rms_um: float | None
    max_um: float | None
    rms_arcsec: float | None
    max_arcsec: float | None
    repeat_um: float | None
    fit_rms_normalized: float | None
    parameters: tuple[ParameterDrift, ...]
    tolerances: Tolerances
    reasons: tuple[str, ...]

    @property
    def moved(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parameters if p.moved)

    def to_json(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d["outcome"] = self.outcome.name
        d["moved"] = list(self.moved)
        return _plain(d)


def _heads(cfg: CellConfig, records: Sequence[MeasurementRecord]) -> list[tuple[MeasurementRecord, np.ndarray]]:
    index = {pid: i for i, pid in enumerate(cfg.point_ids)}
    return [(r, cfg.body_points[index[r.point_id]] @ invert(r.pose)) for r in records
            if r.ok and r.pose is not None and r.joints_read is not None]


def analyse_recheck(cfg: CellConfig, steps: Sequence[PlannedStep], records: Sequence[MeasurementRecord],
                    baseline: Baseline, tol: Tolerances) -> RecheckResult:
    """Drift per pose and overall, the drift of the offsets, lengths and head with σ, and the
    decision (see the module)."""
    by_index = {st.index: st for st in steps}
    main = [(r, T) for r, T in _heads(cfg, records) if by_index[r.step_index].cycle == 0]
    repeats = [(r, T) for r, T in _heads(cfg, records) if by_index[r.step_index].cycle > 0]
    n_planned = sum(1 for st in steps if st.cycle == 0)
    needed = max(3, math.ceil(MIN_VALID_FRACTION * n_planned))
    reasons: list[str] = []
    poses: list[PoseDrift] = []
    rms = mx = rms_a = mx_a = fit_chi = None
    params: list[ParameterDrift] = []
    repeat = None
    if main:
        q = baseline.standing(np.array([r.joints_read for r, _ in main]))  # like with like: the baseline's model
        T_meas = np.array([T for _, T in main])
        T_pred = forward(cfg.model, q, params=baseline.params, setup=True)
        e = _pose_error(T_meas, T_pred)
        pos_um = np.linalg.norm(e[:, :3], axis=1) * 1e3
        ang_as = np.linalg.norm(e[:, 3:], axis=1) / ARCSEC
        for (r, _), p, a in zip(main, pos_um, ang_as):
            st = by_index[r.step_index]
            poses.append(PoseDrift(st.point_id, st.elbow, float(p), float(a)))
        rms, mx = float(np.sqrt(np.mean(pos_um**2))), float(pos_um.max())
        rms_a, mx_a = float(np.sqrt(np.mean(ang_as**2))), float(ang_as.max())
        # the drift of the offsets, lengths and head: a linear identification at the baseline
        idx = drift_parameters(cfg)
        sig = cfg.identification.pose_sigma()
        J = (drift_jacobian(cfg, baseline.params, q, idx) / sig[None, :, None]).reshape(-1, len(idx))
        y = (e / sig).ravel()
        if len(y) > len(idx):
            U, S, Vt = np.linalg.svd(J, full_matrices=False)
            keep = S > S[0] * 1e-8
            delta = Vt[keep].T @ ((U[:, keep].T @ y) / S[keep])
            dof = max(len(y) - int(keep.sum()), 1)
            fit_chi = float(np.sqrt(np.sum((y - J @ delta) ** 2) / dof))
            cov = (Vt[keep].T / S[keep] ** 2) @ Vt[keep] * max(1.0, fit_chi**2)
            for c, i in enumerate(idx):
                name = cfg.model.param_names[i]
                label, kind = describe_parameter(cfg, name)
                s = math.sqrt(cov[c, c] + baseline.sigma.get(name, 0.0) ** 2)
                if i % 6 >= 3:  # roll, pitch, yaw: an angle
                    scale, unit, lim = 1.0 / ARCSEC, "″", tol.offset_arcsec
                else:
                    scale, unit, lim = 1e3, "µm", tol.length_um
                d, s = float(delta[c]) * scale, s * scale
                params.append(ParameterDrift(name, label, kind, d, s, unit, lim,
                                             bool(abs(d) > SIGMAS * s and abs(d) > lim)))
    if repeats and main:
        first = {(r.point_id, r.label.split(" cycle")[0]): T for r, T in main}
        diffs = [np.linalg.norm(T[:3, 3] - first[(r.point_id, r.label.split(" cycle")[0])][:3, 3]) * 1e3
                 for r, T in repeats if (r.point_id, r.label.split(" cycle")[0]) in first]
        repeat = float(max(diffs)) if diffs else None
    outcome = Outcome.SUCCESS
    if len(main) < needed:
        reasons.append(f"only {len(main)} of {n_planned} recheck poses are valid, {needed} are needed")
    if repeat is not None and repeat > tol.repeat_um:
        reasons.append(f"the first pose measured again at the end moved by {repeat:.1f} µm (more than "
                       f"{tol.repeat_um:.1f} µm): the cell is still moving (warm-up?) or the measurement "
                       f"does not repeat")
    if reasons:
        outcome = Outcome.RECHECK_UNTRUSTED
    else:
        if rms is not None and rms > tol.position_um:
            reasons.append(f"RMS drift {rms:.1f} µm exceeds the tolerance {tol.position_um:.1f} µm")
        for p in params:
            if p.moved:
                reasons.append(f"{p.label} moved by {p.delta:+.1f} ± {p.sigma:.1f} {p.unit} "
                               f"(tolerance {p.tolerance:.1f} {p.unit})")
        if reasons:
            outcome = Outcome.DRIFTED
    return RecheckResult(outcome, tuple(poses), n_planned, len(main), rms, mx, rms_a, mx_a, repeat, fit_chi,
                         tuple(params), tol, tuple(reasons))


# --------------------------------------------------------------------------------------------
# the run
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class RecheckSummary:
    """How a recheck ended: the ``--json`` object and what ``station runs`` reads back."""

    outcome: Outcome
    run_id: int | None
    cell: str
    robot: str
    baseline: Baseline
    result: RecheckResult | None
    db: str | None = None
    warmup: Mapping[str, Any] | None = None
    robot_time_s: float | None = None
    notes: tuple[str, ...] = field(default=())

    @property
    def exit_code(self) -> int:
        return int(self.outcome)

    def replace(self, **changes: Any) -> RecheckSummary:
        return dataclasses.replace(self, **changes)

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {"outcome": self.outcome.name, "exit_code": self.exit_code, "run_id": self.run_id,
                               "kind": "recheck", "cell": self.cell, "robot": self.robot}
        if self.db is not None:
            out["db"] = self.db
        b = self.baseline
        out["baseline"] = {"run_id": b.run_id, "created_utc": b.created_utc, "outcome": b.outcome,
                           "after_rms_um": b.after_rms_um, "residual_rms_um": b.residual_rms_um,
                           "accuracy_um": b.accuracy_um,
                           # the model the recheck compares with: geometric, or with the terms it kept
                           "error_terms": list(b.terms)}
        if self.result is not None:
            out["recheck"] = self.result.to_json()
        if self.warmup is not None:
            out["warmup"] = _plain(dict(self.warmup))
        if self.robot_time_s is not None:
            out["robot_time_s"] = self.robot_time_s
        if self.notes:
            out["notes"] = list(self.notes)
        out["units"] = {"lengths": "µm (keys *_um; parameters: see their unit)", "angles": "arc seconds (*_arcsec)",
                        "times": "s (keys *_s)"}
        return out


def _plain(obj: Any) -> Any:
    if isinstance(obj, Mapping):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, Outcome):
        return obj.name
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    return obj


@dataclass(frozen=True)
class RecheckOptions:
    baseline: int | None = None  # None: the latest successful calibration of this cell
    poses: int | None = None  # None: [recheck].poses


def run_recheck(cfg: CellConfig, probe: ProbeHead, controller: CellController, db: RunDB,
                emit: Callable[[Event], None], control: RunControl | None = None,
                options: RecheckOptions = RecheckOptions(), resume_run: int | None = None,
                seed: int | None = None, devices_info: dict[str, str] | None = None) -> RecheckSummary:
    """Plan (or resume), warm up if configured, measure, compare with the baseline, decide.
    Raises the typed error of whatever stopped it (everything measured is on disk)."""
    control = control or RunControl()
    runner = Runner(cfg, probe, controller, emit, control)
    if resume_run is None:
        base_id = options.baseline if options.baseline is not None else find_baseline(db, cfg)
        check_baseline_cell(db, base_id, cfg)
        baseline = load_baseline(db, base_id, cfg)
        emit(PhaseChanged("plan", f"recheck against run {base_id}"))
        steps = plan_recheck(cfg, baseline.params, options.poses)
        run_id = db.create_run(cfg.source_text, [st.to_record() for st in steps], seed=seed,
                               note=f"recheck of run {base_id}")
        db.save_result(run_id, "fingerprint", fingerprint(cfg))
        db.save_result(run_id, "recheck_baseline", {"run_id": base_id})
        resumed = 0
    else:
        run_id = resume_run
        if not _is_recheck(db, run_id):
            raise ConfigError(f"run {run_id} is a calibration; resume it with 'station calibrate CONFIG --resume {run_id}'")
        stored_fp = db.load_result(run_id, "fingerprint", default=None) or fingerprint(stored_config(db, run_id))
        check_same_cell(stored_fp, current_like(stored_fp, cfg), run_id)
        try:
            steps = tuple(PlannedStep.from_record(rec) for rec in db.run(run_id).plan)
        except (KeyError, ValueError, TypeError) as exc:
            raise RunDatabaseError(f"run {run_id}: the stored plan is not readable ({exc}); start a new recheck") from None
        base_id = int(db.load_result(run_id, "recheck_baseline")["run_id"])
        baseline = load_baseline(db, base_id, cfg)
        resumed = len(db.completed_steps(run_id, ok_only=True))
    if devices_info:
        db.save_result(run_id, "devices", devices_info)
    emit(RunStarted(run_id, len(steps), resumed, kind="recheck"))
    runner.progress.start(len(steps), resumed)
    db.log(run_id, "info", f"recheck {'resumed' if resume_run else 'started'} against run {base_id}: "
                           f"{len(steps)} steps, {resumed} on disk")
    try:
        warm = None
        if cfg.warmup is not None and len(db.completed_steps(run_id, ok_only=True)) < len(steps):
            warm = run_warmup(cfg, runner, db, run_id, steps[0], emit)
        emit(PhaseChanged("measure", "recheck poses"))
        db.set_status(run_id, "measuring")
        runner.measure_steps(db, run_id, steps, {StepKind.RECHECK}, len(steps),
                             lambda st: approach_and_read(cfg, st.q, st.direction, cycle=st.cycle))
        db.set_status(run_id, "measured")
        emit(PhaseChanged("verify", "comparing with the baseline"))
        tol = Tolerances.for_(cfg, baseline)
        result = analyse_recheck(cfg, steps, db.measurements(run_id, kind=StepKind.RECHECK.value), baseline, tol)
        db.save_result(run_id, "recheck", result.to_json())
        db.set_status(run_id, "verified")
    except Exception as exc:
        db.log(run_id, "error", f"{type(exc).__name__}: {exc}")
        db.set_status(run_id, "aborted" if isinstance(exc, RunAborted) else "failed")
        raise
    for reason in result.reasons:
        emit(Notice("warning" if result.outcome is not Outcome.SUCCESS else "info", reason))
    summary = RecheckSummary(result.outcome, run_id, cfg.name, cfg.model.name, baseline, result,
                             warmup=warm or db.load_result(run_id, "warmup", default=None),
                             robot_time_s=float(sum(runner.timing.values())))
    db.save_result(run_id, "summary", summary.to_json())
    runner.progress.finish()
    emit(RunFinished(RunSummary(outcome=result.outcome, run_id=run_id, cell=cfg.name, robot=cfg.model.name,
                                notes=result.reasons)))
    return summary
