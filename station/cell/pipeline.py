"""Calibrate → correct → upload → verify, end to end, for a nightly script or an operator.

:func:`run_calibration` is the one pipeline; ``station calibrate`` and the terminal UI both call
it. It is resumable: the plan and every measurement live in the run database, so a run that was
interrupted (crash, kill, power cut) continues at the next missing step, and the results
(identification, table) are recomputed from what is on disk.

Verification measures held-out poses with Cartesian moves: before correction (no table active),
after (the station's table active) and — in simulation — with a table computed from the
simulator's true parameters (the oracle), each over several cycles for ISO 9283 AP and RP.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Callable

import numpy as np

from station.cell.config import CellConfig
from station.errors import IdentificationError
from station.cell.events import Event, Notice, PhaseChanged, RunFinished, RunStarted
from station.cell.plan import build_plan, head_targets_world, joints_for
from station.cell.runcontrol import RunControl
from station.cell.runner import Runner, approach_and_read
from station.core.transforms import invert, matrix_to_pose, pose_to_matrix

ARCSEC = np.pi / 180 / 3600


class Outcome(enum.IntEnum):
    """Exit codes of ``station calibrate`` (documented in README)."""

    SUCCESS = 0
    CONFIG_ERROR = 2
    IDENTIFICATION_FAILED = 3
    UNREACHABLE = 4
    DATABASE_ERROR = 5
    ABORTED = 6
    DEVICE_FAULT = 7
    SAFETY_STOP = 8
    UPLOAD_FAILED = 9
    TARGET_MISSED = 10


@dataclass(frozen=True)
class Options:
    upload: bool = True
    oracle_truth: object | None = None  # simulators.cell.CellTruth in simulation
    min_gain: float = 20.0  # required RMS improvement (before / after)


def full_plan(cfg: CellConfig, with_oracle: bool) -> list[dict]:
    """Identification steps, then verification before / after (/ oracle) × cycles × targets."""
    plan = build_plan(cfg)
    steps = plan.to_list()
    phases = ["verification_before", "verification_after"] + (["oracle"] if with_oracle else [])
    for kind in phases:
        for cycle in range(cfg.plan.verification_cycles):
            for t in plan.verification:
                steps.append({"index": len(steps), "kind": kind, "point": t.point,
                              "point_id": t.point_id, "elbow": t.elbow, "direction": 1,
                              "cycle": cycle, "joints": t.joints.tolist()})
    return steps


def _world_heads(cfg: CellConfig, records) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """Measured KKS←MKKS poses and joints of the valid identification records."""
    index = {pid: i for i, pid in enumerate(cfg.point_ids)}
    T, q, pts = [], [], []
    for r in records:
        if not r.ok or r.pose is None or r.joints_read is None:
            continue
        j = index[r.point_id]
        T.append(cfg.body_points[j] @ invert(r.pose))
        q.append(r.joints_read)
        pts.append(j)
    return np.array(T), np.array(q), pts


def reversal_error(cfg: CellConfig, forward_records, reverse_records) -> dict:
    """Position difference [µm] between approaching each pose from below and from above (the
    robot's reversal error, brief §8); empty without reversal measurements."""
    def heads(records):
        index = {pid: i for i, pid in enumerate(cfg.point_ids)}
        return {r.label: (cfg.body_points[index[r.point_id]] @ invert(r.pose))[:3, 3]
                for r in records if r.ok and r.pose is not None}

    fwd, rev = heads(forward_records), heads(reverse_records)
    d = np.array([np.linalg.norm(fwd[k] - rev[k]) for k in fwd.keys() & rev.keys()]) * 1e3
    if not d.size:
        return {}
    return {"n": int(d.size), "rms_um": float(np.sqrt(np.mean(d**2))), "max_um": float(d.max())}


def identify_run(cfg: CellConfig, records):
    """Identification from the run's stored measurements (pose or distance objective)."""
    from station.core.identification import identify
    from station.core.measurements import MeasurementSet

    T, q, pts = _world_heads(cfg, records)
    if len(T) < 5:
        raise IdentificationError(
            f"only {len(T)} valid measurements on disk; check the warnings of the measurement "
            f"phase (probes out of range, residuals) and re-run")
    sig = cfg.identification.pose_sigma()
    sp = sig[0]
    if cfg.identification.objective == "pose":
        data = MeasurementSet("pose", q, T, sig)
    else:
        pos = T[:, :3, 3]
        iu = np.array(np.triu_indices(len(pos), 1)).T
        iu = iu[[pts[i] != pts[j] for i, j in iu]]
        d = np.linalg.norm(pos[iu[:, 0]] - pos[iu[:, 1]], axis=1)
        data = MeasurementSet("distance", q, d, np.sqrt(2) * sp, iu)
    return identify(cfg.model, data, prefer=cfg.identification.prefer or None,
                    fix=cfg.identification.fix, exclude=cfg.identification.exclude)


def verification_errors(cfg: CellConfig, records) -> dict:
    """Per verification record: position error [mm] of the measured head against its target."""
    heads = head_targets_world(cfg)
    index = {pid: i for i, pid in enumerate(cfg.point_ids)}
    out = {}
    for r in records:
        if not r.ok or r.pose is None:
            continue
        j = index[r.point_id]
        meas = cfg.body_points[j] @ invert(r.pose)
        out.setdefault((r.point_id, r.label.split(" cycle")[0]), []).append(meas[:3, 3] - heads[j][:3, 3])
    return {k: np.array(v) for k, v in out.items()}


def _error_stats(errs: dict) -> dict:
    from station.core.iso9283 import iso9283_pose

    if not errs:
        return {"n": 0}
    all_e = np.concatenate(list(errs.values()))
    norms = np.linalg.norm(all_e, axis=1)
    ap, rp = [], []
    for e in errs.values():
        s = iso9283_pose(np.zeros(3), e)
        ap.append(s.AP)
        rp.append(s.RP)
    return {"n": int(len(norms)), "rms_um": float(np.sqrt(np.mean(norms**2)) * 1e3),
            "max_um": float(norms.max() * 1e3), "ap_max_um": float(max(ap) * 1e3),
            "rp_max_um": float(max(rp) * 1e3), "errors_um": (norms * 1e3).tolist()}


def run_calibration(cfg: CellConfig, probe, controller, db, emit: Callable[[Event], None],
                    control: RunControl | None = None, options: Options = Options(),
                    resume_run: int | None = None, seed: int | None = None) -> dict:
    """Measure → identify → correct → upload → verify. Returns the JSON-able summary; raises the
    typed error of whatever stopped it (everything measured so far is on disk)."""
    control = control or RunControl()
    emit(PhaseChanged("connect", "devices connected"))
    runner = Runner(cfg, probe, controller, emit, control)
    with_oracle = options.oracle_truth is not None and options.upload
    if resume_run is None:
        emit(PhaseChanged("plan"))
        plan = full_plan(cfg, with_oracle)
        run_id = db.create_run(cfg.source_text, plan, seed=seed)
        resumed = 0
    else:
        run_id = resume_run
        plan = list(db.run(run_id).plan)
        resumed = len(db.completed_steps(run_id))
    total = len(plan)
    emit(RunStarted(run_id, total, resumed))
    db.log(run_id, "info", f"run {'resumed' if resume_run else 'started'}: {total} steps, {resumed} on disk")
    summary: dict = {"run_id": run_id, "cell": cfg.name, "robot": cfg.model.name}
    try:
        return _pipeline(cfg, runner, db, run_id, plan, total, emit, options, with_oracle, summary)
    except Exception as exc:  # station and driver errors alike: log, mark the run, re-raise
        db.log(run_id, "error", f"{type(exc).__name__}: {exc}")
        db.set_status(run_id, "aborted" if type(exc).__name__ == "RunAborted" else "failed")
        raise


def oracle_params(cfg: CellConfig, truth) -> np.ndarray:
    """The simulator's true parameters as seen through the station's approach: every joint
    arrives from the same side, so half the reversal error is a constant joint offset (revolute
    joints from below, the quill from above), which belongs to the true model of this cell."""
    p = np.array(truth.params, dtype=float)
    for k, (t, kind) in enumerate(zip(cfg.model.joint_transforms, cfg.model.joint_types)):
        direction = 1.0 if kind == "revolute" else -1.0
        p[6 * t + (5 if kind == "revolute" else 2)] -= 0.5 * truth.backlash[k] * direction
    return p


def build_table_for(cfg: CellConfig, params: np.ndarray):
    """The correction table of ``params`` on the configured grid (the controller's nominal model)."""
    from station.core.correction_table import GridSpec, build_correction_table

    c = cfg.correction
    grid = GridSpec(x_range=c.x_mm[:2], x_step=c.x_mm[2], y_range=c.y_mm[:2], y_step=c.y_mm[2],
                    z_range=c.z_mm[:2], z_step=c.z_mm[2], yaw_step=np.deg2rad(c.yaw_step_deg),
                    elbows=tuple(cfg.plan.elbows))
    return build_correction_table(cfg.model, params, grid)


def _proc_for(cfg: CellConfig, R_world_base: np.ndarray | None):
    heads = head_targets_world(cfg)

    def make(st: dict):
        q = np.array(st["joints"])
        if st["kind"] in ("identification", "reversal"):
            return approach_and_read(cfg, q, st.get("direction", 1), cycle=st.get("cycle", 0))
        # Verification: a Cartesian target in the base frame, as a user of the robot gives it.
        T_base = invert(pose_to_matrix(R_world_base)) @ heads[st["point"]]
        q_nom = joints_for(cfg, heads[st["point"]], st["elbow"], R_world_base)[0]
        return approach_and_read(cfg, q_nom, 1, cartesian=(matrix_to_pose(T_base), st["elbow"]),
                                 cycle=st.get("cycle", 0))

    return make


def _pipeline(cfg, runner, db, run_id, plan, total, emit, options, with_oracle, summary):
    from station.core.correction_table import upload_verified

    emit(PhaseChanged("measure", "identification poses"))
    db.set_status(run_id, "measuring")
    runner.measure_steps(db, run_id, plan, {"identification", "reversal"}, total, _proc_for(cfg, None))
    db.set_status(run_id, "measured")

    records = db.measurements(run_id, kind="identification")
    reversal = reversal_error(cfg, records, db.measurements(run_id, kind="reversal"))
    if reversal:
        summary["reversal"] = reversal
        emit(Notice("info", f"reversal error (both approach directions): RMS {reversal['rms_um']:.1f} µm, "
                            f"max {reversal['max_um']:.1f} µm over {reversal['n']} poses"))
    emit(PhaseChanged("identify"))
    res = identify_run(cfg, records)
    db.save_result(run_id, "identification", {
        "params": res.params, "chosen": list(res.chosen), "sigma": res.uncertainty.sigma,
        "rms_normalized": res.rms_normalized, "outliers": list(res.outliers),
        "residuals": res.residuals})
    db.set_status(run_id, "identified")
    summary["identification"] = {
        "objective": res.kind, "n_measurements": int(res.residuals.shape[0]),
        "n_parameters": len(res.chosen), "rms_normalized": res.rms_normalized,
        "rms_residual_um": res.rms_position_mm() * 1e3, "outliers": list(res.outliers),
        "parameters": {n: {"value": float(v), "sigma": float(s)} for n, v, s in
                       zip(res.chosen, res.estimates, res.uncertainty.sigma)}}
    if res.outliers:
        emit(Notice("warning", f"suspected outliers among identification measurements: {list(res.outliers)}"))
    R_id = res.params[:6]

    emit(PhaseChanged("correct"))
    table = build_table_for(cfg, res.params)
    summary["correction"] = {"n_values": int(table.data.n_values),
                             "interpolation_bound_um": float(table.interpolation_bound_um),
                             "crc32": f"{table.data.crc32():08x}"}
    if table.interpolation_bound_um > cfg.correction.max_interpolation_um:
        raise IdentificationError(
            f"the correction grid interpolates with up to {table.interpolation_bound_um:.1f} µm, "
            f"above correction.max_interpolation_um = {cfg.correction.max_interpolation_um}; "
            f"use a finer grid (smaller steps)")

    emit(PhaseChanged("verify", "before correction"))
    controller = runner.controller
    if controller.status().table_active:
        controller.deactivate_table()
    runner.measure_steps(db, run_id, plan, {"verification_before"}, total, _proc_for(cfg, R_id))
    before = _error_stats(verification_errors(cfg, db.measurements(run_id, kind="verification_before")))
    summary["before"] = before

    if not options.upload:
        summary["upload"] = "skipped (--no-upload)"
        summary["outcome"] = Outcome.SUCCESS.name
        summary["exit_code"] = int(Outcome.SUCCESS)
        db.save_result(run_id, "summary", summary)
        emit(RunFinished(Outcome.SUCCESS.name, summary))
        return summary

    emit(PhaseChanged("upload"))
    rep = upload_verified(controller, table.data)
    db.set_status(run_id, "uploaded")
    summary["upload"] = {"crc32": f"{table.data.crc32():08x}", "verified": True,
                         "seconds": float(getattr(rep, "seconds", 0.0))}
    emit(PhaseChanged("verify", "after correction"))
    runner.measure_steps(db, run_id, plan, {"verification_after"}, total, _proc_for(cfg, R_id))
    after = _error_stats(verification_errors(cfg, db.measurements(run_id, kind="verification_after")))
    summary["after"] = after
    if with_oracle:
        truth = options.oracle_truth
        emit(PhaseChanged("verify", "oracle (true parameters)"))
        p_true = oracle_params(cfg, truth)
        oracle_table = build_table_for(cfg, p_true)
        upload_verified(controller, oracle_table.data)
        runner.measure_steps(db, run_id, plan, {"oracle"}, total, _proc_for(cfg, p_true[:6]))
        summary["oracle"] = _error_stats(verification_errors(cfg, db.measurements(run_id, kind="oracle")))
        controller.rollback_table()  # the station's own table is the one left active
    gain = before.get("rms_um", np.nan) / max(after.get("rms_um", np.nan), 1e-9)
    summary["gain"] = float(gain)
    if "oracle" in summary and summary["oracle"].get("n"):
        summary["after_vs_oracle"] = after["rms_um"] / summary["oracle"]["rms_um"]
    outcome = Outcome.SUCCESS if gain >= options.min_gain else Outcome.TARGET_MISSED
    summary["outcome"] = outcome.name
    summary["exit_code"] = int(outcome)
    db.set_status(run_id, "verified")
    db.save_result(run_id, "summary", summary)
    emit(RunFinished(outcome.name, summary))
    return summary
