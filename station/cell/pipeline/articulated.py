"""Correction and verification of an articulated arm (issue 9): compensated targets instead of a
table. The held-out targets are commanded as Cartesian targets, before correction as they are,
after it compensated with the identified model (and, in simulation, with the judge's: the
oracle); beside the full model stand the joint-zero-offset-only figures and the orientation
errors. :func:`station.cell.pipeline.calibration.run_calibration` hands over here after the identification.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from station.cell.config.cell_config import CellConfig
from station.cell.correction.robot_tools import run_tools
from station.cell.pipeline.results import (
    missed_limits,
    reference_params,
    verification_errors,
    verification_orientation_errors,
    verified_outcome,
)
from station.cell.pipeline.shifted import checked_compensated, checked_plain, reference_skipped
from station.cell.pipeline.terms import (
    JointDelta,
    error_model_record,
    error_model_summary,
    judge_delta,
    terms_delta,
    terms_note,
)
from station.cell.plan.measurement_plan import head_targets_world
from station.cell.plan.moved_path.shifted_check import ShiftedPathCollides
from station.cell.plan.steps import PlannedStep, StepKind
from station.cell.records.judge import RunJudge
from station.cell.records.run_records import MeasurementRecord
from station.cell.records.rundb import RunDB
from station.cell.records.summary import CompensationSummary, ErrorStats, RunSummary
from station.cell.run.facts.events import Event, Notice, PhaseChanged, StatusChanged, Verified
from station.cell.run.recentring import stored_recentring
from station.cell.run.runner import Procedure, Runner, approach_and_read
from station.core.identification.identify import IdentificationResult
from station.core.kinematics.transforms import invert, matrix_to_pose, pose_to_matrix
from station.core.terms.selection import Selection
from station.errors import Outcome

__all__ = ["articulated_targets", "joint_offset_figures", "articulated_correction"]


def articulated_targets(cfg: CellConfig, steps: Sequence[PlannedStep], params: np.ndarray | None,
                        R_world_base: np.ndarray, delta: JointDelta | None = None
                        ) -> dict[tuple[int, int], tuple[np.ndarray, np.ndarray]]:
    """Per verification target (point, configuration code): the joints the controller will
    command and the Cartesian command (base frame, (6,)). ``params`` None: the plain target
    through the nominal IK (before correction); else the target compensated with ``params``
    (:func:`station.core.kinematics.compensation.compensated_targets`, in the configuration of the planned
    joints) and, where given, the joint errors ``delta`` beyond geometry
    (:func:`station.core.terms.compensation.compensated_targets_with_terms`). Raises
    :class:`UnreachableError` naming a target that cannot be compensated."""
    from station.core.kinematics.compensation import compensated_targets
    from station.core.kinematics.ik import configuration as arm_configuration
    from station.core.kinematics.ik import solve_ik
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
        if delta is None:
            comp = compensated_targets(cfg.model, p, T_world, q0=q0, setup=True, allow_singular=True)
        else:
            from station.core.terms.compensation import compensated_targets_with_terms

            comp = compensated_targets_with_terms(cfg.model, p, delta, T_world, q0=q0, setup=True,
                                                  allow_singular=True)
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
    (:mod:`station.core.kinematics.joint_offsets`): offsets fitted to the identified model over the
    identification joints; errors against ``reference`` (a simulated cell's judge's robot) or, without one,
    predicted by the identified model."""
    from station.core.kinematics.joint_offsets import fit_joint_offsets, offset_accuracy

    q = np.array([r.joints_read for r in records if r.ok and r.joints_read is not None])
    offsets = fit_joint_offsets(cfg.model, params, q)
    heads = head_targets_world(cfg)
    keys = sorted({(st.point, st.elbow) for st in steps if st.kind.is_verification})
    T_base = invert(pose_to_matrix(params[:6]))[None] @ heads[[k[0] for k in keys]]
    from station.core.kinematics.ik import configuration as arm_configuration

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


def articulated_correction(cfg: CellConfig, runner: Runner, db: RunDB, run_id: int, steps: tuple[PlannedStep, ...],
                           emit: Callable[[Event], None], with_oracle: bool, summary: RunSummary,
                           res: IdentificationResult, *, upload: bool, min_gain: float,
                           judge: RunJudge | None, terms: Selection | None = None,
                           configured: np.ndarray | None = None) -> RunSummary:
    """Correct and verify an articulated arm: no table; the held-out targets are commanded as
    Cartesian targets, before correction as they are, after it compensated with the identified
    model (and, in simulation, with the true one: the oracle). Beside the full model: what
    joint-zero offsets alone would reach on the same targets, and the orientation errors.
    ``terms``: the error model of ``[identification] model`` (:mod:`station.cell.pipeline.terms`);
    with terms kept, the targets are compensated with the geometry fitted with them and the terms,
    and the reference (a simulated cell's judge) with its joint errors as well as its geometry.
    ``configured``: the ``[robot] setup`` the plan was made at (where the last identification pose stood
    on the located set-up follows from it); given, the path before correction is checked before it moves."""
    total = len(steps)
    params, delta = res.params, None
    if terms is not None:
        es = error_model_summary(cfg, terms)
        db.save_result(run_id, "error_model", error_model_record(cfg, terms))
        note = terms_note(es)
        emit(Notice("info", note))
        summary = summary.replace(error_model=es, notes=(*summary.notes, note))
        delta = terms_delta(cfg, terms)
        if terms.chosen:  # the geometry fitted with what was kept (drift alone included), as the recheck reads it
            params = np.asarray(terms.fit.params, dtype=float)
    R_id = params[:6]
    ARCSEC_RAD = np.pi / 180.0 / 3600.0

    def measure(kind: StepKind, targets: dict) -> ErrorStats | None:
        runner.measure_steps(db, run_id, steps, {kind}, total, _articulated_proc(cfg, targets))
        recs = db.measurements(run_id, kind=kind.value)
        moved = stored_recentring(db, run_id)  # a re-centring's move is part of the error (issue 18)
        ang = verification_orientation_errors(cfg, steps, recs, moved) / ARCSEC_RAD
        if ang.size:
            orient[kind.value] = {"rms_arcsec": float(np.sqrt(np.mean(ang**2))), "max_arcsec": float(ang.max())}
        return ErrorStats.from_errors(verification_errors(cfg, steps, recs, moved))

    orient: dict[str, dict[str, float]] = {}
    emit(PhaseChanged("correct"))
    after_targets = articulated_targets(cfg, steps, params, R_id, delta)  # every target compensable, before moving
    extra: dict[str, Any] = {"method": "compensated targets" + (" with error terms" if delta else ""),
                             "n_targets": len(after_targets)}
    p_ref = reference_params(cfg, judge) if judge is not None else None
    ref_delta = judge_delta(judge)  # the simulated robot's joint errors: the reference knows them too
    if cfg.tools:  # [[tool]]: each tool's own compensated targets, stored as tool:<name>
        summary = summary.replace(tools=run_tools(cfg, db, run_id, steps, params, None, p_ref,  # the terms too
                                                  judge, emit, delta=delta))
    try:
        extra["joint_offsets_only"] = joint_offset_figures(
            cfg, steps, db.measurements(run_id, kind=StepKind.IDENTIFICATION.value), res.params,
            p_ref if ref_delta is None else None)  # a geometric reference misses a bending arm: predicted then
    except Exception as exc:  # noqa: BLE001 - a figure beside the result must not stop the run
        emit(Notice("warning", f"joint-offset-only figure not computed: {exc}"))
    # before: the plain targets in the frame the uncorrected robot located the body in (cfg's set-up: the
    # located one, else the configured), the joints its identification poses were commanded at. Not the
    # identified set-up: an arm's shares its turn about axis 1 with A1's zero (a minimal set), and the
    # nominal robot took that share alone, up to 0.43° of joint 1 from the plan's joints (irb2600 seed 5:
    # probe 6's housing 0.5 mm into cube 1 in the controller's model, the run ended UNREACHABLE)
    before_targets = articulated_targets(cfg, steps, None, cfg.model.nominal[:6])
    if configured is not None:  # and their path checked as the runner moves it, before any verification motion (40)
        summary = checked_plain(cfg, steps, set(db.completed_steps(run_id, ok_only=True)), before_targets,
                                configured, summary, emit, runner)
    # the path the compensated targets move, before any verification motion (issue 40), the body where the
    # configured set-up puts it (the identified one is no place alone: R and A1 merge); the oracle's at
    # the simulated robot's true set-up, the one its targets are compensated in
    if upload:
        summary = checked_compensated(cfg, steps, set(db.completed_steps(run_id, ok_only=True)), after_targets,
                                      StepKind.VERIFY_AFTER, summary, emit, runner, before_targets, None)
    runner.guard.table = None
    controller = runner.controller
    if controller.status().table_active:  # a table would act on top of the compensated targets
        controller.deactivate_table()

    emit(PhaseChanged("verify", "before correction"))
    summary = summary.replace(before=measure(StepKind.VERIFY_BEFORE, before_targets))
    if not upload:
        return _articulated_done(db, run_id, summary.replace(upload_skipped=True, outcome=Outcome.NOT_UPLOADED),
                                 extra, orient, emit)
    emit(PhaseChanged("verify", "after correction (compensated targets)"))
    summary = summary.replace(after=measure(StepKind.VERIFY_AFTER, after_targets))
    if summary.after is not None:  # the same fact as a SCARA's table run reports (one stream, issue 42)
        emit(Verified(summary.before, summary.after, summary.gain))
    if with_oracle and p_ref is not None:
        emit(PhaseChanged("verify", "oracle (reference parameters)"))
        ref_targets = articulated_targets(cfg, steps, p_ref, p_ref[:6], ref_delta)
        try:  # before it moves (40)
            summary = checked_compensated(cfg, steps, set(db.completed_steps(run_id, ok_only=True)), ref_targets,
                                          StepKind.REFERENCE, summary, emit, runner, after_targets, p_ref[:6])
        except ShiftedPathCollides as exc:
            emit(Notice("warning", reference_skipped(exc)))
        else:
            summary = summary.replace(oracle=measure(StepKind.REFERENCE, ref_targets))
    outcome, missed = verified_outcome(cfg, summary, min_gain)
    summary = summary.replace(notes=(*summary.notes, *missed), missed=missed_limits(cfg, summary, min_gain))
    emit(StatusChanged("verified"))  # stored by the run database's writer (station/cell/run/facts/writer.py)
    return _articulated_done(db, run_id, summary.replace(outcome=outcome), extra, orient, emit)


def _articulated_done(db: RunDB, run_id: int, summary: RunSummary, extra: dict[str, Any],
                      orient: dict[str, dict[str, float]], emit: Callable[[Event], None]) -> RunSummary:
    """Store the articulated arm's figures (result ``articulated``) and state them as notes."""
    extra["orientation"] = orient
    db.save_result(run_id, "articulated", extra)
    notes = [f"correction: {extra.get('method', 'compensated targets')} (an articulated arm takes no correction table)"]
    if orient:
        notes.append("orientation error RMS: " + ", ".join(
            f"{k.replace('verification_', '')} {v['rms_arcsec']:.1f}″" for k, v in orient.items()))
    jo = extra.get("joint_offsets_only")
    if jo:
        a = jo["accuracy"]
        ref = "against the simulated robot" if a["reference"] == "reference parameters" else a["reference"]
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
                               rms(StepKind.VERIFY_BEFORE), rms(StepKind.VERIFY_AFTER), rms(StepKind.REFERENCE), **fig)
