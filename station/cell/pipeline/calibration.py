"""Calibrate → correct → upload → verify, end to end, for a nightly script or an operator.

:func:`run_calibration` is the one pipeline; ``station calibrate`` and the terminal UI both reach
it through :func:`station.cell.session.calibrate.run_calibration_session`. It is resumable: the plan and
every measurement live in the run database, so a run that was interrupted (crash, kill, power
cut) continues at the next missing step, and the results (identification, table) are recomputed
from what is on disk.

Verification measures held-out poses with Cartesian moves: before correction (no table active),
after (the station's table active) and — in simulation — with a table computed from the
simulator's true parameters (the oracle), each over several cycles for ISO 9283 AP and RP. An
articulated arm takes compensated targets instead of a table (:mod:`station.cell.pipeline.articulated`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from station.cell.config.cell_config import CellConfig
from station.cell.correction.design import grid_to_json, identified_table, worst_cell
from station.cell.correction.robot_tools import run_tools
from station.cell.correction.table_keeping import finish_tables, restore_after_failure, table_at_start
from station.cell.correction.upload import verified_upload
from station.cell.pipeline.articulated import articulated_correction, articulated_targets
from station.cell.pipeline.invalid_poses import invalid_advice, rejudge
from station.cell.pipeline.judging import judged
from station.cell.pipeline.premotion import Premotion, check_first_motion, premotion_check
from station.cell.pipeline.results import (
    build_table_for,
    grid_for,
    identify_run,
    missed_limits,
    reference_params,
    reversal_error,
    run_measurements,
    verification_errors,
    verified_outcome,
)
from station.cell.pipeline.shifted import checked_shifted, clearance_of, reference_skipped, scara_standing
from station.cell.plan.measurement_plan import head_targets_world, joints_for
from station.cell.plan.moved_path.shifted_check import ShiftedPathCollides
from station.cell.plan.path_record import PATH_RESULT, checked_path_record
from station.cell.plan.steps import PlannedStep, StepKind
from station.cell.records.fingerprint import check_same_cell, current_like, fingerprint, resume_note
from station.cell.records.judge import RunJudge
from station.cell.records.reading.stored_config import config_source, stored_config, stored_plan
from station.cell.records.run_records import MeasurementRecord
from station.cell.records.rundb import RunDB
from station.cell.records.summary import (
    CorrectionSummary,
    ErrorStats,
    IdentificationSummary,
    ParameterEstimate,
    RunSummary,
    UploadSummary,
)
from station.cell.run.devices import CellController, ProbeHead
from station.cell.run.facts.events import (
    CellChanged,
    Event,
    Identified,
    Notice,
    PhaseChanged,
    RunFinished,
    RunPlanned,
    RunStarted,
    StatusChanged,
    TableDesigned,
    Uploaded,
    Verified,
)
from station.cell.run.facts.next_move import next_moves
from station.cell.run.facts.writer import RunWriter
from station.cell.run.locate import locate_body, located_joints
from station.cell.run.questions import Confirm, KeepCorrection, UploadProposal
from station.cell.run.recentring import recentring_stats, stored_recentring
from station.cell.run.runcontrol import RunControl
from station.cell.run.runner import Procedure, Runner, approach_and_read
from station.core.identification.identify import BODY_NOTE_PREFIX, IdentificationResult
from station.core.kinematics.transforms import invert, matrix_to_pose, pose_to_matrix
from station.errors import ConfigError, IdentificationError, Outcome, RunAborted

# The figures of a stored run (pipeline_results), its configuration and plan (stored_config) and
# the articulated arm's step (pipeline_articulated) live apart; their names stay importable here.
__all__ = ["Options", "run_calibration", "MIN_VALID_FRACTION", "MAX_RMS_NORMALIZED", "MAX_OUTLIER_FRACTION",
           "min_valid_identification", "check_identification", "check_plausible", "identify_run", "reversal_error",
           "verification_errors", "reference_params", "grid_for", "build_table_for", "articulated_targets",
           "config_source", "stored_config", "stored_plan"]

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


def check_plausible(cfg: CellConfig, records: Sequence[MeasurementRecord], res: IdentificationResult) -> None:
    """Refuse a converged fit far from the robot file's geometry (issue 36): exit 3 naming the
    parameter, its value, its σ and the likely cause. The limits widen with a rehearsal's
    ``[simulation]`` error sizes (PRIOR_FACTOR times their σ), never below the defaults."""
    from station.core.identification.plausibility import (
        PLAUSIBLE_ANGLE_RAD,
        PLAUSIBLE_LENGTH_MM,
        PRIOR_FACTOR,
        require_plausible,
    )
    from station.core.units import ARCSEC

    sim = cfg.simulation
    length = max(PLAUSIBLE_LENGTH_MM, PRIOR_FACTOR * (getattr(sim, "length_sigma_um", 0.0) or 0.0) / 1000.0)
    angle = max(PLAUSIBLE_ANGLE_RAD, PRIOR_FACTOR * (getattr(sim, "angle_sigma_arcsec", 0.0) or 0.0) * ARCSEC)
    require_plausible(cfg.model, run_measurements(cfg, records), res.params, res.chosen, res.uncertainty.sigma,
                      length, angle)


@dataclass(frozen=True)
class Options:
    upload: bool = True
    judge: RunJudge | None = None  # a simulated cell's judge (station/cell/records/judge.py); None: a real cell
    confirm: Confirm | None = None  # the operator's yes/no before the upload and to keep it
    min_gain: float = 20.0  # required RMS improvement (before / after)


def _proc_for(cfg: CellConfig, R_world_base: np.ndarray | None,
              located: np.ndarray | None = None) -> Callable[[PlannedStep], Procedure]:
    """``located``: the set-up the body was located at (issue 37), where the identification poses
    are commanded on it instead of the plan's joints (None: the plan's joints)."""
    heads = head_targets_world(cfg)

    def make(st: PlannedStep) -> Procedure:
        if not st.kind.is_verification:
            q = st.q if located is None else located_joints(cfg, st, located)
            return approach_and_read(cfg, q, st.direction, cycle=st.cycle)
        # Verification: a Cartesian target in the base frame, as a user of the robot gives it.
        assert R_world_base is not None, "verification needs the identified set-up"
        T_base = invert(pose_to_matrix(R_world_base)) @ heads[st.point]
        q_nom = joints_for(cfg, heads[st.point], st.elbow, R_world_base)[0]
        return approach_and_read(cfg, q_nom, 1, cartesian=(matrix_to_pose(T_base), st.elbow), cycle=st.cycle)

    return make


def run_calibration(cfg: CellConfig, probe: ProbeHead, controller: CellController, db: RunDB,
                    emit: Callable[[Event], None], control: RunControl | None = None,
                    options: Options = Options(), resume_run: int | None = None,
                    seed: int | None = None, devices_info: dict[str, str] | None = None) -> RunSummary:
    """Measure → identify → correct → upload → verify. Returns the run's summary; raises the
    typed error of whatever stopped it (everything measured so far is on disk)."""
    control = control or RunControl()
    pre = premotion_check(cfg)  # tools, plan, correction: what 'station plan' checks, before anything moves
    runner = Runner(cfg, probe, controller, emit, control)
    # the run database's writer, first for the whole run: the pipeline emits its facts, the writer
    # stores each before a view hears of it, and a failed write stops the run (station/cell/run/facts/writer.py)
    writer = RunWriter(db, resume_run)
    runner.stream.subscribe(writer, first=True)
    emit = runner.stream
    with_oracle = options.judge is not None and options.upload
    reused: tuple[str, ...] = ()  # a resume: the post-processing sections changed since
    if resume_run is None:
        emit(PhaseChanged("plan"))
        steps = pre.plan.run_steps(cfg.plan.verification_cycles, with_oracle, options.upload)
        emit(RunPlanned(cfg.source_text, tuple(st.to_record() for st in steps), seed, config_source(cfg),
                        fingerprint(cfg)))
        run_id = writer.run_id  # the run database's number of the run it created
        resumed = 0
    else:
        run_id = resume_run
        stored_fp = db.load_result(run_id, "fingerprint", default=None)
        if stored_fp is None:  # a run from before fingerprints: compare with its snapshot
            stored_fp = fingerprint(stored_config(db, run_id))
        steps = stored_plan(db, run_id)  # the plan first: a damaged plan is named as such (exit 5)
        reused = check_same_cell(stored_fp, current_like(stored_fp, cfg), run_id, db.measurements(run_id))
        moved = config_source(cfg) != db.load_result(run_id, "config_source", default=None)
        if reused or moved:  # the measurements are kept; the table, the figures and the report follow this
            # text, and its files are read where they lie now (a cell folder moved or copied: issue 37)
            emit(CellChanged(run_id, cfg.source_text, config_source(cfg), fingerprint(cfg)))
        db.measurements(run_id)  # what is on disk must belong to that plan (record_checks.py), else exit 5
        planned_upload = any(st.kind is StepKind.VERIFY_AFTER for st in steps)
        if planned_upload != options.upload:
            raise ConfigError(f"run {run_id} was planned {'with' if planned_upload else 'without'} the upload; "
                              f"resume it {'without' if planned_upload else 'with'} --no-upload as it started, "
                              f"or start a new run")
        resumed = len(db.completed_steps(run_id, ok_only=True))
    checked = pre.plan.run_steps(cfg.plan.verification_cycles, False)  # the steps the collision check saw
    if pre.collision is not None:  # its poses and least clearance, for the report's picture (issue 42); None
        # (the picture's path is not the checked one) replaces a resumed run's earlier record
        db.save_result(run_id, PATH_RESULT, checked_path_record(cfg, pre.plan, checked, pre.collision))
    runner.next_moves = next_moves(pre.collision, checked, steps)  # each step's clearance, for the views
    emit(RunStarted(run_id, len(steps), resumed, resume=resume_run is not None,
                    devices=tuple((devices_info or {}).items())))  # the latest attempt's devices, for the report
    runner.progress.start(len(steps), resumed)  # k of n from here on (station/cell/run/facts/progress.py)
    design = None if pre.design is None else f"correction table designed: {pre.design.describe()}"
    for note in (resume_note(reused), design):
        if note:
            emit(Notice("info", note))
    summary = RunSummary(outcome=Outcome.SUCCESS, run_id=run_id, cell=cfg.name, robot=cfg.model.name,
                         clearances=tuple(c for c in [clearance_of("pre-motion", pre.collision)] if c))
    start = table_at_start(controller, db, run_id, emit)  # before anything changes the controller's tables
    try:  # the first move, from where the robot stands, is checked as the plan's moves are (issue 40)
        check_first_motion(cfg, controller.read_joints(), steps, db.completed_steps(run_id, ok_only=True))
        summary = _pipeline(cfg, runner, db, run_id, steps, emit, options, with_oracle, summary, pre)
        if options.judge is not None:  # a simulated cell: its judge's figures (station/cell/pipeline/judging.py)
            summary = judged(cfg, options.judge, db, run_id, summary, emit)
        summary = summary.replace(recentring=recentring_stats(
            steps, {k: db.measurements(run_id, kind=k.value) for k in StepKind if k is not StepKind.RECHECK},
            stored_recentring(db, run_id)))
        summary = summary.replace(notes=(*summary.notes, *runner.stuck.notes()))  # a stuck probe, by name
        rp = summary.rp_text()  # RP after > before is no sign of a bad correction unless beyond its spread
        if rp is not None:
            summary = summary.replace(notes=(*summary.notes, rp))
        summary = finish_tables(controller, start, summary, emit)
    except Exception as exc:  # station and driver errors alike: log, mark the run, re-raise
        note = restore_after_failure(controller, start, emit)
        exc.add_note(note)
        emit(StatusChanged("aborted" if isinstance(exc, RunAborted) else "failed", f"{type(exc).__name__}: {exc}",
                           note))
        raise
    runner.progress.finish()  # the steps a run without its upload does not measure: not left to do
    emit(RunFinished(summary))  # stored by the writer (result 'summary'), then the views
    return summary


def _not_uploaded(cfg: CellConfig, summary: RunSummary, run_id: int, table: Any, used: Any, bound: float,
                  emit: Callable[[Event], None]) -> RunSummary:
    """No table within the capacity meets the bound for the identified robot: nothing is uploaded
    (NOT_UPLOADED, reason ``correction_bound``); the measurements and the identification stay."""
    limit = float(cfg.correction.max_interpolation_um)
    note = (f"no correction table within the controller's {used.capacity} values meets correction.max_interpolation_um "
            f"= {limit:g} for the identified robot: on the grid {'×'.join(map(str, used.counts))} (the design, refined for "
            f"this robot as far as the capacity allows) "
            f"its table interpolates with up to {bound:.1f} µm {worst_cell(table, used.region)}, where "
            f"{used.predicted_bound_um:.1f} µm was predicted before motion. Nothing was uploaded. Every measurement "
            f"and the identified parameters of run {run_id} are stored: set correction.max_interpolation_um = "
            f"{math.ceil(bound * 1.05)} or a smaller correction.region, then 'station calibrate CONFIG --resume "
            f"{run_id}' builds the table again without measuring ('station export --run {run_id} --format identify' "
            f"and 'station identify' give the identified model for compensated targets)")
    emit(Notice("warning", note))
    return summary.replace(outcome=Outcome.NOT_UPLOADED, upload_skipped=True, not_uploaded_reason="correction_bound",
                           notes=(*summary.notes, note))


def _scara_terms(cfg: CellConfig, db: RunDB, run_id: int, terms: Any, summary: RunSummary, res: IdentificationResult,
                 emit: Callable[[Event], None]) -> tuple[RunSummary, np.ndarray, Any]:
    """A SCARA's ``[identification] model`` (issue 30): the selection stored (result ``error_model``),
    its note and the summary's ``error_model``; returns the summary, the parameters the table is
    built from (the geometry fitted with the kept terms, else ``res``'s) and the terms' joint error
    ``δ(q)`` (None: nothing beyond geometry kept, or ``model = "geometric"``)."""
    if terms is None:
        return summary, res.params, None
    from station.cell.pipeline.terms import error_model_record, error_model_summary, terms_delta, terms_note

    es = error_model_summary(cfg, terms)
    db.save_result(run_id, "error_model", error_model_record(cfg, terms))
    note = terms_note(es)
    delta = terms_delta(cfg, terms)
    if delta is not None:
        note += "; the correction table's nodes carry the terms (drift left out)"
    emit(Notice("info", note))
    summary = summary.replace(error_model=es, notes=(*summary.notes, note))
    # the geometry fitted with what was kept (backlash folded into its zeros, drift alone included), as
    # the recheck and the report read it back
    return summary, (np.asarray(terms.fit.params, dtype=float) if terms.chosen else res.params), delta


def _frozen(a: Any) -> Any:
    """An array as nested tuples of floats (an event's figures cannot change under its subscribers);
    None stays None."""
    def tuples(v: Any) -> Any:
        return tuple(tuples(x) for x in v) if isinstance(v, list) else v

    return None if a is None else tuples(np.asarray(a, dtype=float).tolist())


def _identification_summary(res: IdentificationResult) -> IdentificationSummary:
    return IdentificationSummary(
        objective=res.kind, n_measurements=int(res.residuals.shape[0]), n_parameters=len(res.chosen),
        rms_normalized=float(res.rms_normalized), rms_residual_um=float(res.rms_position_mm() * 1e3),
        outliers=tuple(int(i) for i in res.outliers),
        parameters=tuple(ParameterEstimate(n, float(v), float(s))
                         for n, v, s in zip(res.chosen, res.estimates, res.uncertainty.sigma)),
        variance_factor_s0=None if res.variance is None else res.variance.s0,
        variance_limit_s0=None if res.variance is None else res.variance.limit,
        sigma_scaled_by=1.0 if res.variance is None else res.variance.factor)


@dataclass(frozen=True)
class _Run:
    """What every part of one run's pipeline works with: the devices' runner, the run database and
    the run, its planned steps, the event stream and the options."""

    runner: Runner
    db: RunDB
    run_id: int
    steps: tuple[PlannedStep, ...]
    emit: Callable[[Event], None]
    options: Options

    def measure(self, cfg: CellConfig, kinds: set[StepKind], R: np.ndarray | None,
                located: np.ndarray | None = None) -> None:
        """The planned steps of ``kinds``, each on disk before the next motion."""
        self.runner.measure_steps(self.db, self.run_id, self.steps, kinds, len(self.steps), _proc_for(cfg, R, located))

    def stats(self, cfg: CellConfig, kind: StepKind) -> ErrorStats | None:
        """The stored verification steps of ``kind`` as error statistics; re-centred readings said."""
        recs = self.db.measurements(self.run_id, kind=kind.value)
        moved = stored_recentring(self.db, self.run_id)
        (rc,) = recentring_stats(self.steps, {kind: recs}, moved) or (None,)
        if rc is not None and rc.n_recentred:
            self.emit(Notice("info", f"{kind.caption}: {rc.n_recentred} of {rc.n_readings} readings re-centred to "
                                     f"bring the probes into their stroke (up to {rc.max_um:.0f} µm); the "
                                     f"re-centring's move is counted in the measured error"))
        return ErrorStats.from_errors(verification_errors(cfg, self.steps, recs, moved))


def _pipeline(cfg: CellConfig, runner: Runner, db: RunDB, run_id: int, steps: tuple[PlannedStep, ...],
              emit: Callable[[Event], None], options: Options, with_oracle: bool,
              summary: RunSummary, pre: Premotion) -> RunSummary:
    run = _Run(runner, db, run_id, steps, emit, options)
    planned = cfg  # the configuration the run was planned and checked in before motion (its set-up the guess)
    cfg, records, reversal_records, summary = _measure_identification(run, cfg, summary)
    res, summary = _identify_recorded(run, cfg, records, summary)
    from station.cell.pipeline.terms import select_terms  # [identification] model (issue 30)

    terms = select_terms(cfg, records, res, reversal_records)
    if not cfg.model.is_scara:  # an articulated arm: compensated targets, no table (issue 9)
        return articulated_correction(cfg, runner, db, run_id, steps, emit, with_oracle, summary, res,
                                      upload=options.upload, min_gain=options.min_gain,
                                      judge=options.judge, terms=terms,
                                      configured=planned.model.nominal[:6])

    # a SCARA with error terms: the table's nodes carry them, on the geometry fitted with them, and the
    # targets after correction are commanded in that fit's base frame (before: the geometric fit's)
    summary, params, delta = _scara_terms(cfg, db, run_id, terms, summary, res, emit)
    emit(PhaseChanged("correct"))
    table, used, bound, summary = _designed_table(run, cfg, params, delta, pre, summary)
    if not bound <= float(cfg.correction.max_interpolation_um):
        return _not_uploaded(cfg, summary, run_id, table, used, bound, emit)
    if cfg.tools:  # [[tool]]: each tool's own correction, stored as tool:<name>; the head's table is uploaded
        # In the planned configuration, not the located one: a tool's grid is designed, as the head's, over
        # the plan's poses at the configured set-up, the grid premotion checked; 'station export --tool' and
        # the report rebuild it from the run's configuration snapshot and must get the same table (CRC-32).
        # Nothing else of a tool's correction reads the nominal set-up (the tables are in the base frame,
        # the targets in the identified one).
        judge = options.judge
        summary = summary.replace(tools=run_tools(planned, db, run_id, steps, params, table,  # with the terms, as the head's
                                                  None if judge is None else reference_params(planned, judge), judge,
                                                  emit, delta=delta))

    if options.upload:  # the table's verification path as the controller will move it, before any of it, from
        # where the last step before correction leaves the robot (40)
        start = scara_standing(cfg, steps, StepKind.VERIFY_AFTER, res.params[:6], None)
        summary = checked_shifted(cfg, steps, set(db.completed_steps(run_id, ok_only=True)), params[:6],
                                  table.data, StepKind.VERIFY_AFTER, summary, emit, runner, start)
    emit(PhaseChanged("verify", "before correction"))
    if runner.controller.status().table_active:  # the operator's table: kept aside (table_keeping.py)
        runner.controller.deactivate_table()
    runner.guard.table = None
    run.measure(cfg, {StepKind.VERIFY_BEFORE}, res.params[:6])
    summary = summary.replace(before=run.stats(cfg, StepKind.VERIFY_BEFORE))
    if not options.upload:
        return summary.replace(upload_skipped=True, outcome=Outcome.NOT_UPLOADED)
    declined = _upload_declined(run, cfg, table, bound, summary)
    if declined is not None:
        return declined
    summary = _upload_and_verify(run, cfg, table, params[:6], summary)
    if with_oracle:
        summary = _reference_check(run, cfg, table, used, summary, params[:6])
    outcome, missed = verified_outcome(cfg, summary, options.min_gain)
    summary = summary.replace(notes=(*summary.notes, *missed), missed=missed_limits(cfg, summary, options.min_gain))
    emit(StatusChanged("verified"))
    return _kept_or_restored(run, table, summary, outcome)


def _measure_identification(run: _Run, cfg: CellConfig, summary: RunSummary):
    """Warm-up, locating the body and the identification poses, each on disk before the next
    motion; returns the configuration the rest works in (its set-up the located one, where the
    body was located), the identification and reversal records, and the summary with the
    reversal error."""
    db, run_id, emit = run.db, run.run_id, run.emit
    if cfg.warmup is not None and len(db.completed_steps(run_id, ok_only=True)) < len(run.steps):  # [warmup] (13)
        from station.cell.run.warmup import run_warmup

        run_warmup(cfg, run.runner, db, run_id, run.steps[0], emit)
    emit(StatusChanged("measuring"))
    rejudge(cfg, db, run_id, emit)  # a resume after [plan] max_residual_um changed: judged, not measured, again
    located = locate_body(cfg, run.runner, db, run_id, run.steps, emit)  # the body is found, not assumed (issue 37)
    emit(PhaseChanged("measure", "identification poses"))
    run.measure(cfg, {StepKind.IDENTIFICATION, StepKind.REVERSAL}, None, located)
    emit(StatusChanged("measured"))
    if located is not None:  # the identification starts from the located set-up, and the set-up parameters
        # it cannot tell from the arm's (its minimal set) stay there: the verification's base frame is the body's
        cfg = dataclasses.replace(cfg, model=cfg.model.with_setup(located))
    records = db.measurements(run_id, kind=StepKind.IDENTIFICATION.value)
    reversal_records = db.measurements(run_id, kind=StepKind.REVERSAL.value)  # the terms' backlash uses them too
    reversal = reversal_error(cfg, records, reversal_records, stored_recentring(db, run_id))
    if reversal is not None:
        summary = summary.replace(reversal=reversal)
        emit(Notice("info", f"reversal error (both approach directions): RMS {reversal.rms_um:.1f} µm, "
                            f"max {reversal.max_um:.1f} µm over {reversal.n} poses"))
    return cfg, records, reversal_records, summary


def _identify_recorded(run: _Run, cfg: CellConfig, records, summary: RunSummary):
    """The identification of the stored poses, refused where too few are valid, where it did not
    converge or where its robot is implausible; stored and streamed."""
    emit = run.emit
    emit(PhaseChanged("identify"))
    n_planned = sum(1 for st in run.steps if st.kind is StepKind.IDENTIFICATION)
    n_valid = sum(1 for r in records if r.ok and r.pose is not None)
    needed = min_valid_identification(n_planned)
    if n_valid < needed:
        raise IdentificationError(
            f"only {n_valid} of {n_planned} identification poses are valid, {needed} are needed "
            f"({MIN_VALID_FRACTION:.0%}); no correction was identified. Of the invalid: "
            f"{invalid_advice(cfg, records, needed) or 'fix what the warnings name, then resume'}")
    res = identify_run(cfg, records)
    check_identification(res)
    check_plausible(cfg, records, res)
    identified = _identification_summary(res)
    summary = summary.replace(identification=identified)
    emit(Identified(identified, tuple(float(v) for v in res.params), _frozen(res.uncertainty.covariance),
                    _frozen(res.residuals)))  # stored by the writer (result 'identification'), then shown
    for note in (n for n in res.notes if n.startswith(BODY_NOTE_PREFIX)):  # the body's CMM σ is in the fit
        summary = summary.replace(notes=(*summary.notes, note))
        emit(Notice("info", note))
    if res.variance is not None and res.variance.scaled:  # the σ reported are the residuals' (issue 38)
        summary = summary.replace(notes=(*summary.notes, res.variance.note()))
        emit(Notice("info", res.variance.note()))
    if res.outliers:
        emit(Notice("warning", f"suspected outliers among identification measurements: {list(res.outliers)}"))
    return res, summary


def _designed_table(run: _Run, cfg: CellConfig, params: np.ndarray, delta, pre: Premotion, summary: RunSummary):
    """The identified robot's table on the pre-motion design (refined where the identified robot
    needs it), its one bound, stored and streamed."""
    assert pre.design is not None  # a SCARA's pre-motion check designs its table
    table, used, bound = (identified_table(cfg, params, pre.design) if delta is None
                          else identified_table(cfg, params, pre.design, delta))
    summary = summary.replace(correction=(designed := CorrectionSummary(
        n_values=int(table.data.n_values), interpolation_bound_um=bound, crc32=f"{table.data.crc32():08x}",
        predicted_bound_um=pre.design.predicted_bound_um, grid_shape=tuple(int(n) for n in used.counts),
        refined=used.counts != pre.design.counts, limit_um=float(cfg.correction.max_interpolation_um))))
    # the one bound the run judges, stores (result 'correction_grid', by the writer) and shows
    run.emit(TableDesigned(designed, grid_to_json(used.grid), tuple(float(b) for b in pre.design.bounds_um),
                           bool(table.with_terms)))  # its nodes carry the terms
    if used.counts != pre.design.counts:
        run.emit(Notice("info", f"the correction grid was refined for the identified robot: {used.describe()}"))
    return table, used, bound, summary


def _upload_declined(run: _Run, cfg: CellConfig, table, bound: float, summary: RunSummary) -> RunSummary | None:
    """The upload question; the summary of a run the operator declined it in, else None."""
    options = run.options
    proposal = UploadProposal(
        n_values=int(table.data.n_values), grid_shape=tuple(int(n) for n in table.data.grid_shape),
        # the one stored bound (over the working cells, judged against the limit), which the report,
        # the JSON and the fleet read; the whole table's (every reachable cell) read 5.6 µm where they said 4.7
        interpolation_bound_um=float(bound), crc32=f"{table.data.crc32():08x}",
        max_correction=tuple(float(v) for v in table.max_correction), joint_types=tuple(cfg.model.joint_types))
    if options.confirm is None or options.confirm(proposal):
        return None
    if run.runner.control.aborted:  # the abort answered the open question "no": an abort, not a decline,
        # so the run stays resumable at this question (its measurements are all stored)
        raise RunAborted("run aborted by the operator at the upload question; nothing was uploaded")
    run.emit(Notice("info", "upload declined by the operator: the controller's table of the run's start is kept"))
    return summary.replace(upload_skipped=True, outcome=Outcome.NOT_UPLOADED,
                           notes=(*summary.notes, "upload declined by the operator"))


def _upload_and_verify(run: _Run, cfg: CellConfig, table, R_after: np.ndarray, summary: RunSummary) -> RunSummary:
    """The verified upload, then the held-out poses through the active table."""
    emit = run.emit
    upload = verified_upload(run.runner.controller, table.data, emit)
    run.runner.guard.table = table.data  # Cartesian moves are now corrected by this table
    summary = summary.replace(upload=(uploaded := UploadSummary(crc32=f"{upload.crc32:08x}", seconds=upload.total_s)))
    emit(Uploaded(uploaded, *(f"{c:08x}" if c else "none" for c in (upload.active_crc32, upload.previous_crc32))))
    # (the writer stores the status 'uploaded' from it)
    emit(PhaseChanged("verify", "after correction"))
    run.measure(cfg, {StepKind.VERIFY_AFTER}, R_after)
    summary = summary.replace(after=run.stats(cfg, StepKind.VERIFY_AFTER))
    if summary.after is not None:
        emit(Verified(summary.before, summary.after, summary.gain))
    return summary


def _reference_check(run: _Run, cfg: CellConfig, table, used, summary: RunSummary, R_after: np.ndarray) -> RunSummary:
    """A simulated cell's reference: the held-out poses through the table of the judge's robot,
    then the station's own table active again and the roll-back slot emptied (``R_after``: the
    set-up the steps after correction were commanded in)."""
    emit, controller, judge = run.emit, run.runner.controller, run.options.judge
    assert judge is not None  # with_oracle
    from station.cell.pipeline.terms import judge_delta

    emit(PhaseChanged("verify", "oracle (reference parameters)"))
    p_ref = reference_params(cfg, judge)
    # a simulated arm whose joints err (the judge's reference_delta): the oracle's table carries them too
    oracle_table = build_table_for(cfg, p_ref, used.grid, judge_delta(judge)).data
    start = scara_standing(cfg, run.steps, StepKind.REFERENCE, R_after, table.data)  # the last step after correction's
    try:  # before it is active (40)
        summary = checked_shifted(cfg, run.steps, set(run.db.completed_steps(run.run_id, ok_only=True)), p_ref[:6],
                                  oracle_table, StepKind.REFERENCE, summary, emit, run.runner, start)
    except ShiftedPathCollides as exc:  # the station's own table stays active, its result stands
        emit(Notice("warning", reference_skipped(exc)))
        return summary
    verified_upload(controller, oracle_table, emit)
    run.runner.guard.table = oracle_table
    emit(PhaseChanged("verify", "oracle (reference parameters)"))  # back from the upload's phase
    run.measure(cfg, {StepKind.REFERENCE}, p_ref[:6])
    summary = summary.replace(oracle=run.stats(cfg, StepKind.REFERENCE))
    controller.rollback_table()  # the station's own table is the one left active
    # the oracle's table must never be what a later roll back revives: the roll-back slot is
    # emptied (the table of the run's start stays recoverable from the run database)
    controller.discard_previous_table()
    run.runner.guard.table = table.data
    emit(Notice("info", "rolled back to the station's table after the oracle check"))
    return summary


def _kept_or_restored(run: _Run, table, summary: RunSummary, outcome: Outcome) -> RunSummary:
    """The operator's last word on the new table: kept (the run's outcome), or declined (the
    table of the run's start restored by run_calibration)."""
    confirm = run.options.confirm
    if confirm is not None and summary.before is not None and summary.after is not None:
        keep = KeepCorrection(summary.before.rms_um, summary.after.rms_um, float(summary.gain or 0.0),
                              f"{table.data.crc32():08x}")
        if not confirm(keep):  # run_calibration puts the table of the run's start back
            run.runner.guard.table = None
            run.emit(Notice("warning", "declined by the operator: the table of the run's start is restored"))
            return summary.replace(outcome=Outcome.NOT_UPLOADED,
                                   notes=(*summary.notes, "the new table was rolled back by the operator"))
    return summary.replace(outcome=outcome)
