"""Calibrate → correct → upload → verify, end to end, for a nightly script or an operator.

:func:`run_calibration` is the one pipeline; ``station calibrate`` and the terminal UI both reach
it through :func:`station.cell.session.run_calibration_session`. It is resumable: the plan and
every measurement live in the run database, so a run that was interrupted (crash, kill, power
cut) continues at the next missing step, and the results (identification, table) are recomputed
from what is on disk.

Verification measures held-out poses with Cartesian moves: before correction (no table active),
after (the station's table active) and — in simulation — with a table computed from the
simulator's true parameters (the oracle), each over several cycles for ISO 9283 AP and RP.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from station.cell.config import CellConfig, correction_grid, parse_text
from station.cell.devices import CellController, ProbeHead
from station.cell.events import Event, Notice, PhaseChanged, RunFinished, RunStarted
from station.cell.fingerprint import check_same_cell, fingerprint
from station.cell.plan import build_plan, head_targets_world, joints_for
from station.cell.questions import Confirm, KeepCorrection, UploadProposal
from station.cell.runcontrol import RunControl
from station.cell.rundb import MeasurementRecord, RunDatabaseError, RunDB
from station.cell.runner import Procedure, Runner, approach_and_read
from station.cell.steps import PlannedStep, StepKind
from station.cell.summary import (
    CompensationSummary,
    CorrectionSummary,
    ErrorStats,
    IdentificationSummary,
    ParameterEstimate,
    ReversalSummary,
    RunSummary,
    UploadSummary,
)
from station.cell.tools import check_tools, run_tools
from station.cell.upload import verified_upload
from station.core.correction_table import CorrectionTable, build_correction_table
from station.core.identification import BODY_NOTE_PREFIX, IdentificationResult, identify
from station.core.measurements import MeasurementSet
from station.core.table_grid import GridSpec
from station.core.transforms import invert, matrix_to_pose, pose_to_matrix
from station.errors import ConfigError, IdentificationError, Outcome, RunAborted

#: share of the planned identification poses that must be valid before anything is identified
MIN_VALID_FRACTION = 0.8
#: a fit whose normalised residual RMS exceeds this does not describe the data (σ settings, a
#: bad touch, a wrong robot file): it is refused, never turned into a correction
MAX_RMS_NORMALIZED = 3.0
#: share of residual rows flagged as outliers above which the data is not trusted
MAX_OUTLIER_FRACTION = 0.1


def min_valid_identification(n_planned: int) -> int:
    """Valid identification poses a run needs (the plan preview states it)."""
    return max(5, math.ceil(MIN_VALID_FRACTION * n_planned))


def check_identification(res: IdentificationResult) -> None:
    """Refuse an identification that must not become a correction (a model that fits garbage)."""
    if not res.converged:
        raise IdentificationError(f"the identification did not converge ({res.message}); no correction "
                                  f"was made. Check the robot file and the measurements' warnings")
    if not np.isfinite(res.rms_normalized) or res.rms_normalized > MAX_RMS_NORMALIZED:
        raise IdentificationError(
            f"the identified model leaves residuals {res.rms_normalized:.1f}× the expected measurement "
            f"noise (at most {MAX_RMS_NORMALIZED:g}× is accepted); the model does not describe the data. "
            f"Check [identification] sigma_*, the robot file, and the probes, then resume or re-run")
    n_rows = max(int(res.residuals.shape[0]), 1)
    if len(res.outliers) > MAX_OUTLIER_FRACTION * n_rows:
        raise IdentificationError(
            f"{len(res.outliers)} of {n_rows} measurements are outliers (more than {MAX_OUTLIER_FRACTION:.0%}); "
            f"the data is not trusted. Check the probe head and the body for debris, then re-run")


@dataclass(frozen=True)
class Options:
    upload: bool = True
    oracle_truth: Any = None  # simulators.cell.CellTruth in simulation
    confirm: Confirm | None = None  # the operator's yes/no before the upload and to keep it
    min_gain: float = 20.0  # required RMS improvement (before / after)


def _world_heads(cfg: CellConfig, records: Sequence[MeasurementRecord]) -> tuple[np.ndarray, np.ndarray, list[int]]:
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


def reversal_error(cfg: CellConfig, forward_records: Sequence[MeasurementRecord],
                   reverse_records: Sequence[MeasurementRecord]) -> ReversalSummary | None:
    """Position difference [µm] between approaching each pose from below and from above (the
    robot's reversal error, brief §8); None without reversal measurements."""
    index = {pid: i for i, pid in enumerate(cfg.point_ids)}

    def heads(records: Sequence[MeasurementRecord]) -> dict[tuple[str, str], np.ndarray]:
        # keyed by (point, label without the direction) so each reverse step meets its forward twin
        return {(r.point_id, r.label.replace(" reverse", "")): (cfg.body_points[index[r.point_id]] @ invert(r.pose))[:3, 3]
                for r in records if r.ok and r.pose is not None}

    fwd, rev = heads(forward_records), heads(reverse_records)
    d = np.array([np.linalg.norm(fwd[k] - rev[k]) for k in sorted(fwd.keys() & rev.keys())]) * 1e3
    if not d.size:
        return None
    return ReversalSummary(n=int(d.size), rms_um=float(np.sqrt(np.mean(d**2))), max_um=float(d.max()))


def identify_run(cfg: CellConfig, records: Sequence[MeasurementRecord]) -> IdentificationResult:
    """Identification from the run's stored measurements (pose or distance objective), with the
    body's CMM uncertainty (``cfg.body_sigma``) in the weights and the σ when it is not 0."""
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
    if cfg.body_sigma is not None and np.any(cfg.body_sigma > 0):
        # the CMM's σ of each measurement's body point: shared by all measurements of that point;
        # the lever runs from the point's origin to the measured head frame
        idx = np.asarray(pts, dtype=int)
        data = data.with_body(idx, cfg.body_sigma, T[:, :3, 3] - cfg.body_points[idx, :3, 3])
    return identify(cfg.model, data, prefer=cfg.identification.prefer or None,
                    fix=cfg.identification.fix, exclude=cfg.identification.exclude)


def verification_errors(cfg: CellConfig, steps: Sequence[PlannedStep],
                        records: Sequence[MeasurementRecord]) -> dict[tuple[str, int], np.ndarray]:
    """Per held-out pose (point id, elbow): the ``(n_cycles, 3)`` position errors [mm] of the
    measured head against its target, one row per valid cycle."""
    heads = head_targets_world(cfg)
    out: dict[tuple[str, int], list[np.ndarray]] = {}
    for r in records:
        if not r.ok or r.pose is None:
            continue
        st = steps[r.step_index]
        meas = cfg.body_points[st.point] @ invert(r.pose)
        out.setdefault((st.point_id, st.elbow), []).append(meas[:3, 3] - heads[st.point][:3, 3])
    return {k: np.array(v) for k, v in out.items()}


def oracle_params(cfg: CellConfig, truth: Any) -> np.ndarray:
    """The simulator's true parameters as seen through the station's approach: every joint
    arrives from the same side, so half the reversal error is a constant joint offset (revolute
    joints from below, the quill from above), which belongs to the true model of this cell."""
    p = np.array(truth.params, dtype=float)
    if not cfg.model.is_scara:  # a tilted joint frame: the zero offset is folded in as C·Rz(δ)
        from station.core.joint_offsets import apply_joint_offsets

        half = 0.5 * np.asarray(truth.backlash, dtype=float)
        return apply_joint_offsets(cfg.model, p, np.where(np.array(cfg.model.joint_types) == "revolute", -half, half))
    for k, (t, kind) in enumerate(zip(cfg.model.joint_transforms, cfg.model.joint_types)):
        direction = 1.0 if kind == "revolute" else -1.0
        p[6 * t + (5 if kind == "revolute" else 2)] -= 0.5 * truth.backlash[k] * direction
    return p


def grid_for(cfg: CellConfig) -> GridSpec:
    """The configured correction grid: the one the configuration was checked against."""
    return correction_grid(cfg.correction, tuple(cfg.plan.elbows))


def build_table_for(cfg: CellConfig, params: np.ndarray) -> CorrectionTable:
    """The correction table of ``params`` on the configured grid (the controller's nominal model)."""
    return build_correction_table(cfg.model, params, grid_for(cfg))


def _proc_for(cfg: CellConfig, R_world_base: np.ndarray | None) -> Callable[[PlannedStep], Procedure]:
    heads = head_targets_world(cfg)

    def make(st: PlannedStep) -> Procedure:
        if not st.kind.is_verification:
            return approach_and_read(cfg, st.q, st.direction, cycle=st.cycle)
        # Verification: a Cartesian target in the base frame, as a user of the robot gives it.
        assert R_world_base is not None, "verification needs the identified set-up"
        T_base = invert(pose_to_matrix(R_world_base)) @ heads[st.point]
        q_nom = joints_for(cfg, heads[st.point], st.elbow, R_world_base)[0]
        return approach_and_read(cfg, q_nom, 1, cartesian=(matrix_to_pose(T_base), st.elbow), cycle=st.cycle)

    return make


def config_source(cfg: CellConfig) -> str:
    """Where ``cfg`` was read, absolute (a label such as ``<simulated cell>`` as it is): a run
    stores it so that its relative robot, head and body files resolve beside the configuration
    when the run is resumed or reported from another directory."""
    if not cfg.source or cfg.source.startswith("<"):
        return cfg.source
    return str(Path(cfg.source).resolve())


def stored_config(db: RunDB, run_id: int) -> CellConfig:
    """The configuration run ``run_id`` was made with, read from its stored text; relative files
    resolve beside the configuration file it came from (:func:`config_source`)."""
    source = db.load_result(run_id, "config_source", default=None)
    return parse_text(db.run(run_id).config_toml, source or f"run {run_id}")


def stored_plan(db: RunDB, run_id: int) -> tuple[PlannedStep, ...]:
    """The run's plan as typed steps."""
    try:
        return tuple(PlannedStep.from_record(rec) for rec in db.run(run_id).plan)
    except (KeyError, ValueError, TypeError) as exc:
        raise RunDatabaseError(f"run {run_id}: the stored plan is not readable ({exc}); start a new run") from None


def run_calibration(cfg: CellConfig, probe: ProbeHead, controller: CellController, db: RunDB,
                    emit: Callable[[Event], None], control: RunControl | None = None,
                    options: Options = Options(), resume_run: int | None = None,
                    seed: int | None = None, devices_info: dict[str, str] | None = None) -> RunSummary:
    """Measure → identify → correct → upload → verify. Returns the run's summary; raises the
    typed error of whatever stopped it (everything measured so far is on disk)."""
    control = control or RunControl()
    check_tools(cfg)  # every [[tool]] can be corrected on this robot, before anything moves
    runner = Runner(cfg, probe, controller, emit, control)
    with_oracle = options.oracle_truth is not None and options.upload
    if resume_run is None:
        emit(PhaseChanged("plan"))
        steps = build_plan(cfg).run_steps(cfg.plan.verification_cycles, with_oracle, options.upload)
        run_id = db.create_run(cfg.source_text, [st.to_record() for st in steps], seed=seed)
        db.save_result(run_id, "config_source", config_source(cfg))
        db.save_result(run_id, "fingerprint", fingerprint(cfg))
        resumed = 0
    else:
        run_id = resume_run
        stored_fp = db.load_result(run_id, "fingerprint", default=None)
        if stored_fp is None:  # a run from before fingerprints: compare with its snapshot
            stored_fp = fingerprint(stored_config(db, run_id))
        check_same_cell(stored_fp, fingerprint(cfg), run_id)
        steps = stored_plan(db, run_id)
        planned_upload = any(st.kind is StepKind.VERIFY_AFTER for st in steps)
        if planned_upload != options.upload:
            raise ConfigError(f"run {run_id} was planned {'with' if planned_upload else 'without'} the upload; "
                              f"resume it {'without' if planned_upload else 'with'} --no-upload as it started, "
                              f"or start a new run")
        resumed = len(db.completed_steps(run_id, ok_only=True))
    if devices_info:  # the devices of the latest attempt, for the report
        db.save_result(run_id, "devices", devices_info)
    emit(RunStarted(run_id, len(steps), resumed))
    db.log(run_id, "info", f"run {'resumed' if resume_run else 'started'}: {len(steps)} steps, {resumed} on disk")
    summary = RunSummary(outcome=Outcome.SUCCESS, run_id=run_id, cell=cfg.name, robot=cfg.model.name)
    try:
        summary = _pipeline(cfg, runner, db, run_id, steps, emit, options, with_oracle, summary)
    except Exception as exc:  # station and driver errors alike: log, mark the run, re-raise
        db.log(run_id, "error", f"{type(exc).__name__}: {exc}")
        db.set_status(run_id, "aborted" if isinstance(exc, RunAborted) else "failed")
        raise
    db.save_result(run_id, "summary", summary.to_json())
    emit(RunFinished(summary))
    return summary


def _identification_summary(res: IdentificationResult) -> IdentificationSummary:
    return IdentificationSummary(
        objective=res.kind, n_measurements=int(res.residuals.shape[0]), n_parameters=len(res.chosen),
        rms_normalized=float(res.rms_normalized), rms_residual_um=float(res.rms_position_mm() * 1e3),
        outliers=tuple(int(i) for i in res.outliers),
        parameters=tuple(ParameterEstimate(n, float(v), float(s))
                         for n, v, s in zip(res.chosen, res.estimates, res.uncertainty.sigma)))


def _pipeline(cfg: CellConfig, runner: Runner, db: RunDB, run_id: int, steps: tuple[PlannedStep, ...],
              emit: Callable[[Event], None], options: Options, with_oracle: bool,
              summary: RunSummary) -> RunSummary:
    total = len(steps)

    def measure(kinds: set[StepKind], R: np.ndarray | None) -> None:
        runner.measure_steps(db, run_id, steps, kinds, total, _proc_for(cfg, R))

    def stats(kind: StepKind) -> ErrorStats | None:
        return ErrorStats.from_errors(verification_errors(cfg, steps, db.measurements(run_id, kind=kind.value)))

    if cfg.warmup is not None and len(db.completed_steps(run_id, ok_only=True)) < total:  # [warmup] (issue 13)
        from station.cell.warmup import run_warmup

        run_warmup(cfg, runner, db, run_id, steps[0], emit)
    emit(PhaseChanged("measure", "identification poses"))
    db.set_status(run_id, "measuring")
    measure({StepKind.IDENTIFICATION, StepKind.REVERSAL}, None)
    db.set_status(run_id, "measured")

    records = db.measurements(run_id, kind=StepKind.IDENTIFICATION.value)
    reversal = reversal_error(cfg, records, db.measurements(run_id, kind=StepKind.REVERSAL.value))
    if reversal is not None:
        summary = summary.replace(reversal=reversal)
        emit(Notice("info", f"reversal error (both approach directions): RMS {reversal.rms_um:.1f} µm, "
                            f"max {reversal.max_um:.1f} µm over {reversal.n} poses"))
    emit(PhaseChanged("identify"))
    n_planned = sum(1 for st in steps if st.kind is StepKind.IDENTIFICATION)
    n_valid = sum(1 for r in records if r.ok and r.pose is not None)
    needed = min_valid_identification(n_planned)
    if n_valid < needed:
        raise IdentificationError(
            f"only {n_valid} of {n_planned} identification poses are valid, {needed} are needed "
            f"({MIN_VALID_FRACTION:.0%}); no correction was identified. Fix what the warnings name, then resume: "
            f"the invalid poses are measured again")
    res = identify_run(cfg, records)
    check_identification(res)
    db.save_result(run_id, "identification", {
        "params": res.params, "chosen": list(res.chosen), "sigma": res.uncertainty.sigma,
        "rms_normalized": res.rms_normalized, "outliers": list(res.outliers),
        "residuals": res.residuals})
    db.set_status(run_id, "identified")
    summary = summary.replace(identification=_identification_summary(res))
    for note in (n for n in res.notes if n.startswith(BODY_NOTE_PREFIX)):  # the body's CMM σ is in the fit
        summary = summary.replace(notes=(*summary.notes, note))
        emit(Notice("info", note))
    if res.outliers:
        emit(Notice("warning", f"suspected outliers among identification measurements: {list(res.outliers)}"))
    R_id = res.params[:6]
    if not cfg.model.is_scara:  # an articulated arm: compensated targets, no table (issue 9)
        return _articulated_correction(cfg, runner, db, run_id, steps, emit, options, with_oracle, summary, res)

    emit(PhaseChanged("correct"))
    table = build_table_for(cfg, res.params)
    summary = summary.replace(correction=CorrectionSummary(
        n_values=int(table.data.n_values), interpolation_bound_um=float(table.interpolation_bound_um),
        crc32=f"{table.data.crc32():08x}"))
    if table.interpolation_bound_um > cfg.correction.max_interpolation_um:
        raise IdentificationError(
            f"the correction grid interpolates with up to {table.interpolation_bound_um:.1f} µm, "
            f"above correction.max_interpolation_um = {cfg.correction.max_interpolation_um}; "
            f"use a finer grid (smaller steps)")
    if cfg.tools:  # [[tool]]: each tool's own correction, stored as tool:<name>; the head's table is uploaded
        truth = options.oracle_truth
        summary = summary.replace(tools=run_tools(cfg, db, run_id, steps, res.params, table,
                                                  None if truth is None else oracle_params(cfg, truth), truth, emit))

    emit(PhaseChanged("verify", "before correction"))
    controller = runner.controller
    had_table = controller.status().table_active
    if had_table:
        controller.deactivate_table()
    runner.guard.table = None
    measure({StepKind.VERIFY_BEFORE}, R_id)
    summary = summary.replace(before=stats(StepKind.VERIFY_BEFORE))

    if not options.upload:
        return summary.replace(upload_skipped=True, outcome=Outcome.NOT_UPLOADED)
    proposal = UploadProposal(
        n_values=int(table.data.n_values), grid_shape=tuple(int(n) for n in table.data.grid_shape),
        interpolation_bound_um=float(table.interpolation_bound_um), crc32=f"{table.data.crc32():08x}",
        max_correction=tuple(float(v) for v in table.max_correction), joint_types=tuple(cfg.model.joint_types))
    if options.confirm is not None and not options.confirm(proposal):
        emit(Notice("info", "upload declined by the operator: the controller's table was not changed"))
        return summary.replace(upload_skipped=True, outcome=Outcome.NOT_UPLOADED,
                               notes=(*summary.notes, "upload declined by the operator"))

    upload = verified_upload(controller, table.data, emit)
    runner.guard.table = table.data  # Cartesian moves are now corrected by this table
    db.set_status(run_id, "uploaded")
    summary = summary.replace(upload=UploadSummary(crc32=f"{upload.crc32:08x}", seconds=upload.total_s))
    emit(PhaseChanged("verify", "after correction"))
    measure({StepKind.VERIFY_AFTER}, R_id)
    summary = summary.replace(after=stats(StepKind.VERIFY_AFTER))
    if with_oracle:
        emit(PhaseChanged("verify", "oracle (true parameters)"))
        p_true = oracle_params(cfg, options.oracle_truth)
        oracle_table = build_table_for(cfg, p_true).data
        verified_upload(controller, oracle_table, emit)
        runner.guard.table = oracle_table
        emit(PhaseChanged("verify", "oracle (true parameters)"))  # back from the upload's phase
        measure({StepKind.ORACLE}, p_true[:6])
        summary = summary.replace(oracle=stats(StepKind.ORACLE))
        controller.rollback_table()  # the station's own table is the one left active
        runner.guard.table = table.data
        emit(Notice("info", "rolled back to the station's table after the oracle check"))
    gain = summary.gain
    outcome = Outcome.SUCCESS if gain is not None and gain >= options.min_gain else Outcome.TARGET_MISSED
    db.set_status(run_id, "verified")
    if options.confirm is not None and summary.before is not None and summary.after is not None:
        keep = KeepCorrection(summary.before.rms_um, summary.after.rms_um, float(gain or 0.0),
                              f"{table.data.crc32():08x}")
        if not options.confirm(keep):
            if had_table and not with_oracle:  # the table that was active before this run comes back
                controller.rollback_table()
                what = "the controller's previous table is active again"
            else:  # there was none (or the oracle's table sits in between): no correction at all
                controller.deactivate_table()
                what = "no correction table is active"
            runner.guard.table = None
            emit(Notice("warning", f"rolled back by the operator: {what}"))
            return summary.replace(outcome=Outcome.NOT_UPLOADED,
                                   notes=(*summary.notes, "the new table was rolled back by the operator"))
    return summary.replace(outcome=outcome)


# --- articulated arms: compensated targets instead of a table (issue 9) -------------------------

def verification_orientation_errors(cfg: CellConfig, steps: Sequence[PlannedStep],
                                    records: Sequence[MeasurementRecord]) -> np.ndarray:
    """Orientation error [rad] ``(n,)`` of every valid verification record: the angle between the
    measured head frame and its target."""
    from station.core.transforms import rotation_log

    heads = head_targets_world(cfg)
    out = []
    for r in records:
        if not r.ok or r.pose is None:
            continue
        st = steps[r.step_index]
        meas = cfg.body_points[st.point] @ invert(r.pose)
        out.append(float(np.linalg.norm(rotation_log(heads[st.point][:3, :3].T @ meas[:3, :3]))))
    return np.array(out)


def articulated_targets(cfg: CellConfig, steps: Sequence[PlannedStep], params: np.ndarray | None,
                        R_world_base: np.ndarray) -> dict[tuple[int, int], tuple[np.ndarray, np.ndarray]]:
    """Per verification target (point, configuration code): the joints the controller will
    command and the Cartesian command (base frame, (6,)). ``params`` None: the plain target
    through the nominal IK (before correction); else the target compensated with ``params``
    (:func:`station.core.compensation.compensated_targets`, in the configuration of the planned
    joints). Raises :class:`UnreachableError` naming a target that cannot be compensated."""
    from station.core.compensation import compensated_targets
    from station.core.ik import configuration as arm_configuration
    from station.core.ik import solve_ik
    from station.errors import UnreachableError

    heads = head_targets_world(cfg)
    keys, near = [], []
    for st in steps:
        if st.kind.is_verification and (st.point, st.elbow) not in keys:
            keys.append((st.point, st.elbow))
            near.append(st.q)
    if not keys:
        return {}
    T_world = heads[[k[0] for k in keys]]
    q0 = np.array(near)
    if params is None:
        T_base = invert(pose_to_matrix(R_world_base))[None] @ T_world
        ik = solve_ik(cfg.model, T_base, configuration=arm_configuration(cfg.model, q0), near=q0)
        bad = [(i, r) for i, (ok, r) in enumerate(zip(ik.has_joints, ik.reason)) if not ok]
        joints, commands = ik.joints, T_base
    else:
        p = np.array(params, dtype=float)
        p[:6] = R_world_base
        comp = compensated_targets(cfg.model, p, T_world, q0=q0, setup=True, allow_singular=True)
        bad = [(i, r) for i, s, r in comp.failures()]
        joints, commands = comp.joints, comp.commands
    if bad:
        i, why = bad[0]
        pid = cfg.point_ids[keys[i][0]]
        raise UnreachableError(f"verification target {pid} (configuration {keys[i][1]:+d}): {why}; the motion was "
                               f"not commanded")
    return {k: (joints[i], matrix_to_pose(commands[i])) for i, k in enumerate(keys)}


def _articulated_proc(cfg: CellConfig, targets: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]]
                      ) -> Callable[[PlannedStep], Procedure]:
    def make(st: PlannedStep) -> Procedure:
        if not st.kind.is_verification:
            return approach_and_read(cfg, st.q, st.direction, cycle=st.cycle)
        q, pose = targets[(st.point, st.elbow)]
        # the controller keeps the configuration it stands in: only the elbow's sign is sent
        return approach_and_read(cfg, q, 1, cartesian=(pose, 1 if st.elbow > 0 else -1), cycle=st.cycle)

    return make


def joint_offset_figures(cfg: CellConfig, steps: Sequence[PlannedStep], records: Sequence[MeasurementRecord],
                         params: np.ndarray, reference: np.ndarray | None) -> dict[str, Any]:
    """The joint-zero-offset-only correction beside the full model, on the verification targets
    (:mod:`station.core.joint_offsets`): offsets fitted to the identified model over the
    identification joints; errors against ``reference`` (the simulator's truth) or, without one,
    predicted by the identified model."""
    from station.core.joint_offsets import fit_joint_offsets, offset_accuracy

    q = np.array([r.joints_read for r in records if r.ok and r.joints_read is not None])
    offsets = fit_joint_offsets(cfg.model, params, q)
    heads = head_targets_world(cfg)
    keys = sorted({(st.point, st.elbow) for st in steps if st.kind.is_verification})
    T_base = invert(pose_to_matrix(params[:6]))[None] @ heads[[k[0] for k in keys]]
    from station.core.ik import configuration as arm_configuration

    near = {(st.point, st.elbow): st.q for st in steps if st.kind.is_verification}
    conf = arm_configuration(cfg.model, np.array([near[k] for k in keys]))
    if reference is not None:
        # The base frame is not identifiable apart from the set-up (R and A1 merge): express the
        # reference robot in the identified base frame, so that both see the same targets.
        reference = np.array(reference, dtype=float)
        reference[6:12] = matrix_to_pose(invert(pose_to_matrix(params[:6])) @ pose_to_matrix(reference[:6])
                                         @ pose_to_matrix(reference[6:12]))
        reference[:6] = params[:6]
    acc = offset_accuracy(cfg.model, params, offsets.offsets, T_base, reference_params=reference, configuration=conf)
    return {"offsets": offsets.to_dict(), "accuracy": acc.to_dict()}


def _articulated_correction(cfg: CellConfig, runner: Runner, db: RunDB, run_id: int, steps: tuple[PlannedStep, ...],
                            emit: Callable[[Event], None], options: Options, with_oracle: bool,
                            summary: RunSummary, res: IdentificationResult) -> RunSummary:
    """Correct and verify an articulated arm: no table; the held-out targets are commanded as
    Cartesian targets, before correction as they are, after it compensated with the identified
    model (and, in simulation, with the true one: the oracle). Beside the full model: what
    joint-zero offsets alone would reach on the same targets, and the orientation errors."""
    total = len(steps)
    R_id = res.params[:6]
    ARCSEC_RAD = np.pi / 180.0 / 3600.0

    def measure(kind: StepKind, targets: dict) -> ErrorStats | None:
        runner.measure_steps(db, run_id, steps, {kind}, total, _articulated_proc(cfg, targets))
        recs = db.measurements(run_id, kind=kind.value)
        ang = verification_orientation_errors(cfg, steps, recs) / ARCSEC_RAD
        if ang.size:
            orient[kind.value] = {"rms_arcsec": float(np.sqrt(np.mean(ang**2))), "max_arcsec": float(ang.max())}
        return ErrorStats.from_errors(verification_errors(cfg, steps, recs))

    orient: dict[str, dict[str, float]] = {}
    emit(PhaseChanged("correct"))
    after_targets = articulated_targets(cfg, steps, res.params, R_id)  # every target compensable, before moving
    extra: dict[str, Any] = {"method": "compensated targets", "n_targets": len(after_targets)}
    p_true = oracle_params(cfg, options.oracle_truth) if options.oracle_truth is not None else None
    if cfg.tools:  # [[tool]]: each tool's own compensated targets, stored as tool:<name>
        summary = summary.replace(tools=run_tools(cfg, db, run_id, steps, res.params, None, p_true,
                                                  options.oracle_truth, emit))
    try:
        extra["joint_offsets_only"] = joint_offset_figures(
            cfg, steps, db.measurements(run_id, kind=StepKind.IDENTIFICATION.value), res.params, p_true)
    except Exception as exc:  # noqa: BLE001 - a figure beside the result must not stop the run
        emit(Notice("warning", f"joint-offset-only figure not computed: {exc}"))
    runner.guard.table = None
    controller = runner.controller
    if controller.status().table_active:  # a table would act on top of the compensated targets
        controller.deactivate_table()

    emit(PhaseChanged("verify", "before correction"))
    summary = summary.replace(before=measure(StepKind.VERIFY_BEFORE, articulated_targets(cfg, steps, None, R_id)))
    if not options.upload:
        return _articulated_done(db, run_id, summary.replace(upload_skipped=True, outcome=Outcome.NOT_UPLOADED),
                                 extra, orient, emit)
    emit(PhaseChanged("verify", "after correction (compensated targets)"))
    summary = summary.replace(after=measure(StepKind.VERIFY_AFTER, after_targets))
    if with_oracle and p_true is not None:
        emit(PhaseChanged("verify", "oracle (true parameters)"))
        summary = summary.replace(oracle=measure(StepKind.ORACLE, articulated_targets(cfg, steps, p_true, p_true[:6])))
    gain = summary.gain
    outcome = Outcome.SUCCESS if gain is not None and gain >= options.min_gain else Outcome.TARGET_MISSED
    db.set_status(run_id, "verified")
    return _articulated_done(db, run_id, summary.replace(outcome=outcome), extra, orient, emit)


def _articulated_done(db: RunDB, run_id: int, summary: RunSummary, extra: dict[str, Any],
                      orient: dict[str, dict[str, float]], emit: Callable[[Event], None]) -> RunSummary:
    """Store the articulated arm's figures (result ``articulated``) and state them as notes."""
    extra["orientation"] = orient
    db.save_result(run_id, "articulated", extra)
    notes = ["correction: compensated targets (an articulated arm takes no correction table)"]
    if orient:
        notes.append("orientation error RMS: " + ", ".join(
            f"{k.replace('verification_', '')} {v['rms_arcsec']:.1f}″" for k, v in orient.items()))
    jo = extra.get("joint_offsets_only")
    if jo:
        a = jo["accuracy"]
        ref = "against the simulator's truth" if a["reference"] == "reference parameters" else a["reference"]
        notes.append(f"joint-zero offsets only ({ref}, {a['targets']} targets): RMS "
                     f"{a['joint_offsets']['rms_position_um']:.1f} µm, {a['joint_offsets']['rms_orientation_arcsec']:.1f}″; "
                     f"full model {a['full_model']['rms_position_um']:.1f} µm, "
                     f"{a['full_model']['rms_orientation_arcsec']:.1f}″; uncorrected "
                     f"{a['uncorrected']['rms_position_um']:.1f} µm")
    for n in notes:
        emit(Notice("info", n))
    return summary.replace(notes=(*summary.notes, *notes), compensation=_compensation_summary(extra, orient))


def _compensation_summary(extra: dict[str, Any], orient: dict[str, dict[str, float]]) -> CompensationSummary:
    def rms(kind: StepKind) -> float | None:
        v = orient.get(kind.value)
        return None if v is None else v["rms_arcsec"]

    acc = (extra.get("joint_offsets_only") or {}).get("accuracy")
    fig = {}
    if acc:
        fig = dict(joint_offsets_rms_um=acc["joint_offsets"]["rms_position_um"],
                   joint_offsets_rms_arcsec=acc["joint_offsets"]["rms_orientation_arcsec"],
                   full_model_rms_um=acc["full_model"]["rms_position_um"],
                   full_model_rms_arcsec=acc["full_model"]["rms_orientation_arcsec"],
                   uncorrected_rms_um=acc["uncorrected"]["rms_position_um"],
                   offsets_reference=str(acc["reference"]))
    return CompensationSummary(str(extra.get("method", "")), int(extra.get("n_targets", 0)),
                               rms(StepKind.VERIFY_BEFORE), rms(StepKind.VERIFY_AFTER), rms(StepKind.ORACLE), **fig)
