"""Build a run's report (:mod:`station.ui.report.writer`) from what the run database holds.

The identification is recomputed from the stored measurements (it is deterministic and cheap),
so the report shows exactly what the run identified, with the full covariance; the correction
table is rebuilt the same way (its CRC-32 is compared with the uploaded one).
"""

from __future__ import annotations

import math
import re
import tomllib
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from station.cell.config.cell_config import CellConfig
from station.cell.correction.design import grid_from_json
from station.cell.pipeline.calibration import Options
from station.cell.pipeline.results import build_table_for, identify_run, verification_errors
from station.cell.plan.assembly import head_targets_world
from station.cell.plan.measurement_plan import build_plan
from station.cell.plan.path_record import PATH_RESULT
from station.cell.plan.steps import PlannedStep, StepKind
from station.cell.records.reading.run_list import RunInfo, list_runs
from station.cell.records.reading.stored_config import stored_config, stored_plan
from station.cell.records.reading.stored_error_model import stored_error_model
from station.cell.records.run_records import MeasurementRecord
from station.cell.records.rundb import RunDB
from station.cell.records.summary import RunSummary
from station.cell.run.locate import located_config
from station.cell.run.recentring import stored_recentring
from station.core.accuracy.iso9283 import iso9283_pose
from station.core.accuracy.iso9283_uncertainty import iso9283_uncertainty
from station.core.identification.base_frame import BASE_FRAME_NOTE_PREFIX
from station.core.identification.identify import IdentificationResult
from station.core.kinematics.forward import forward, scara_ik
from station.core.kinematics.transforms import pose_to_matrix
from station.core.measurement.uncertainty import pose_accuracy
from station.core.units import ARCSEC, UM
from station.errors import ConfigError, IdentificationError, StationError
from station.ui.report.contents import Acceptance, IsoPose, ReportData, TestConditions, Traceability, TrendRun
from station.ui.report.progress import document_id, partial_report_data, run_progress
from station.ui.report.provenance import software_rows
from station.ui.report.render.cell_picture import run_picture, stored_check
from station.ui.report.stored_fit import with_stored_figures
from station.ui.report.writer import write_report

__all__ = ["report_data_for_run", "report_for_run", "correlation_from_covariance", "check_operator"]

#: the run database result that keeps the operator a report named (for the rebuilt reports)
OPERATOR_RESULT = "operator"
_CONTROL = re.compile(r"[\x00-\x1f\x7f]")


def _errors_um(cfg: CellConfig, steps: Sequence[PlannedStep], db: RunDB, run_id: int,
               kind: StepKind) -> tuple[np.ndarray, list[str]]:
    """Per verification pose and cycle: the position error [µm] and its label
    (``"<point> elbow <±1> #<cycle>"``)."""
    errs = verification_errors(cfg, steps, db.measurements(run_id, kind=kind.value), stored_recentring(db, run_id))
    labels: list[str] = []
    vals: list[float] = []
    for (pid, elbow), e in errs.items():
        for k, v in enumerate(e):
            labels.append(f"{pid} elbow {elbow:+d} #{k + 1}")
            vals.append(float(np.linalg.norm(v) * 1e3))
    return np.array(vals), labels


def _aligned(base: tuple[np.ndarray, list[str]], *others: tuple[np.ndarray, list[str]]) -> tuple[list[str], list[np.ndarray]]:
    """The union of the labels (``base``'s order first) and each series on it, NaN where a
    series has no value (a cycle that gave no valid measurement)."""
    labels = list(base[1])
    seen = set(labels)
    for _, lab in others:
        for x in lab:
            if x not in seen:
                labels.append(x)
                seen.add(x)
    index = {lab: i for i, lab in enumerate(labels)}
    out = []
    for vals, lab in (base, *others):
        a = np.full(len(labels), np.nan)
        for v, x in zip(vals, lab):
            a[index[x]] = v
        out.append(a)
    return labels, out


def _pose_labels(records: Sequence[MeasurementRecord]) -> list[str]:
    """Labels of the identification rows, as :func:`identify_run` takes the records (valid ones
    with a pose and joints), repeats numbered."""
    count: dict[str, int] = {}
    out = []
    for r in records:
        if not r.ok or r.pose is None or r.joints_read is None:
            continue
        count[r.label] = count.get(r.label, 0) + 1
        out.append(f"{r.label} #{count[r.label]}")
    return out


def correlation_from_covariance(cov: Any) -> np.ndarray:
    """(p, p) correlation coefficients; NaN in the rows of a parameter with σ = 0."""
    c = np.asarray(cov, dtype=float)
    s = np.sqrt(np.clip(np.diag(c), 0.0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        r = c / np.outer(s, s)
    r = np.where(np.outer(s, s) > 0, np.clip(r, -1.0, 1.0), np.nan)
    np.fill_diagonal(r, 1.0)
    return r


def _grid_text(table: Any) -> str:
    names = ("x", "y", "z")
    parts = []
    for name, ax in zip(names, table.data.axes[:3]):
        nodes = ax.nodes
        parts.append(f"{name} {nodes[0]:g} … {nodes[-1]:g} mm step {ax.step:g}" if ax.count > 1
                     else f"{name} {nodes[0]:g} mm")
    yaw = table.data.axes[3]
    parts.append(f"yaw every {math.degrees(yaw.step):g}°")
    return ", ".join(parts)


def _table_info(cfg: CellConfig, table: Any) -> dict[str, Any]:
    corr = []
    for k, (v, kind) in enumerate(zip(table.max_correction, cfg.model.joint_types)):
        corr.append(f"J{k + 1} {v / ARCSEC:.1f} ″" if kind == "revolute" else f"J{k + 1} {v / UM:.1f} µm")
    return {"grid": _grid_text(table), "grid_shape": list(table.data.grid_shape),
            "elbows": ", ".join(f"{e:+d}" for e in table.elbows),
            "unreachable_nodes": int(table.unreachable_nodes),
            "interpolation_bound_arcsec": float(table.interpolation_bound_arcsec),
            "max_correction": ", ".join(corr), "crc32": f"{table.data.crc32():08x}"}


def _rebuilt_table(cfg: CellConfig, db: RunDB, run_id: int, res: IdentificationResult, notes: list[str]) -> Any:
    """The SCARA table the run built, rebuilt: on the grid it was built on (result
    ``correction_grid``) from the identified parameters — or, where its nodes carried error terms
    (that result's ``error_terms``, issue 30), from the stored error model: the geometry fitted
    with the terms and their joint error δ(q) (docs/error-terms.md)."""
    stored = db.load_result(run_id, "correction_grid", default=None)  # the grid the run's table was built on
    grid = None if stored is None else grid_from_json(stored)
    if not (isinstance(stored, Mapping) and stored.get("error_terms")):
        return build_table_for(cfg, res.params, grid)
    em = stored_error_model(cfg, db.load_result(run_id, "error_model", default=None))
    if em is None:
        notes.append("the run's correction table carried error terms but the run stored no error model; the "
                     "table is rebuilt from the geometric identification and its CRC-32 differs from the uploaded")
        return build_table_for(cfg, res.params, grid)
    return build_table_for(cfg, em.params, grid, em.joint_delta(cfg))


def _accuracy_on_grid(cfg: CellConfig, res: IdentificationResult, table: Any) -> tuple[np.ndarray, np.ndarray, list[int], str]:
    """Predicted σ at the table's grid nodes that both models reach within the joint limits,
    per elbow, in the robot base frame (no set-up)."""
    axes = table.data.axes
    grids = np.meshgrid(*[a.nodes for a in axes], indexing="ij")
    pts = np.stack([g.ravel() for g in grids], axis=-1)
    xy, sig, elbows = [], [], []
    per = []
    for c, elbow in enumerate(table.elbows):
        p = pts[np.asarray(table.reachable[c]).ravel()]
        pose = np.zeros((p.shape[0], 6))
        pose[:, :3], pose[:, 5] = p[:, :3], p[:, 3]
        q = scara_ik(cfg.model, pose_to_matrix(pose), elbow=int(elbow), params=res.params, setup=False,
                     check_limits=False)
        ok = np.all(np.isfinite(q), axis=1)
        ok[ok] = cfg.model.within_limits(q[ok])
        q = q[ok]
        acc = pose_accuracy(cfg.model, res.params, res.chosen_index, res.uncertainty.covariance, q, setup=False)
        xy.append(p[ok, :2])
        sig.append(np.linalg.norm(acc.sigma[:, :3], axis=1))
        elbows += [int(elbow)] * q.shape[0]
        per.append(f"{q.shape[0]} with elbow {int(elbow):+d}")
    where = (f"the correction table's grid ({_grid_text(table)}), the nodes both models reach within the "
             f"joint limits: {', '.join(per)}; robot base frame, without the set-up R (this cell's mounting)")
    return np.concatenate(xy), np.concatenate(sig), elbows, where


def _accuracy_on_plan(cfg: CellConfig, res: IdentificationResult) -> tuple[np.ndarray, np.ndarray, list[int], str]:
    """Fallback without a table: the plan's identification and verification poses."""
    plan = build_plan(cfg)
    q = np.array([s.q for s in plan.identification] + [t.joints for t in plan.verification])
    elbows = [int(s.elbow) for s in plan.identification] + [int(t.elbow) for t in plan.verification]
    acc = pose_accuracy(cfg.model, res.params, res.chosen_index, res.uncertainty.covariance, q, setup=False)
    xy = forward(cfg.model, q, res.params, setup=False)[:, :2, 3]
    where = (f"the plan's {len(q)} identification and verification poses (several per body point: repeats, "
             f"elbows, orientations); robot base frame, without the set-up R")
    return xy, np.linalg.norm(acc.sigma[:, :3], axis=1), elbows, where


def _stored_summary(db: RunDB, run_id: int) -> RunSummary | None:
    stored = db.load_result(run_id, "summary", default=None)
    if not stored:
        return None
    try:
        return RunSummary.from_json(stored)
    except (KeyError, TypeError, ValueError):
        return None


def _identify(cfg: CellConfig, db: RunDB, run_id: int, status: str, summary: RunSummary | None) -> IdentificationResult:
    records = db.measurements(run_id, kind=StepKind.IDENTIFICATION.value)
    try:
        return identify_run(cfg, records)
    except IdentificationError as exc:
        n_valid = sum(1 for r in records if r.ok and r.pose is not None and r.joints_read is not None)
        ended = summary.outcome.name if summary is not None else f"status '{status}'"
        if summary is not None and summary.failure is not None:
            ended += f": {summary.failure.message}"
        if n_valid < 5:  # identify_run's own minimum
            raise IdentificationError(
                f"run {run_id} stopped before the identification ({ended}) with {n_valid} valid identification "
                f"measurements on disk, too few to identify from; finish it with 'station calibrate CONFIG "
                f"--resume {run_id}', then 'station report {run_id}'") from None
        raise IdentificationError(f"run {run_id} ({ended}): the identification from its stored measurements "
                                  f"fails: {exc}") from None


def _reached(db: RunDB, run_id: int, summary: RunSummary | None, step: str) -> bool:
    """Whether the run reached ``step`` ("identification" or "correction"), as the report's progress
    line says (:func:`~station.ui.report.progress.run_progress`): by the stored summary, or without
    one (a run still going, or killed) by the step's stored result or a later step's."""
    if summary is not None:
        return (summary.identification if step == "identification" else summary.correction) is not None
    # a later step's stored result says the identification ran too (a table is built from it)
    keys = ("identification", "error_model", "correction_grid") if step == "identification" else ("correction_grid",)
    return any(db.load_result(run_id, k, default=None) is not None for k in keys)


def _not_reached_reason(run_id: int, summary: RunSummary | None, status: str) -> str:
    ended = (f"ended {summary.outcome.name} (exit code {summary.exit_code})" if summary is not None
             else f"has no stored outcome (status '{status}')")
    if summary is not None and summary.failure is not None:
        ended += f": {summary.failure.message}"
    return (f"the run {ended} before its identification; no parameters, residuals, predicted accuracy or "
            f"correction table are shown, and none are recomputed from the measurements it took. Finish it with "
            f"'station calibrate CONFIG --resume {run_id}', then 'station report {run_id}'")


def _trend_run(r: RunInfo) -> TrendRun:
    return TrendRun(run_id=r.id, created=r.created_utc, kind=r.kind, outcome=r.outcome or "", status=r.status,
                    rms_after_um=r.rms_after_um, drift_rms_um=r.drift_rms_um,
                    drift_tolerance_um=r.drift_tolerance_um, moved=r.moved, baseline=r.baseline)


def _trend(db: RunDB, run_id: int, notes: list[str]) -> list[TrendRun]:
    """The runs of this run's cell and robot up to and including it, oldest first (the report's
    trend); empty when the run database cannot list them (the report goes on without)."""
    try:
        runs = list_runs(db)
    except (StationError, KeyError, TypeError, ValueError) as exc:
        notes.append(f"the run history could not be read for the trend ({exc})")
        return []
    this = next((r for r in runs if r.id == run_id), None)
    if this is None:
        return []
    same = [r for r in runs if r.id <= run_id and r.cell == this.cell and r.robot == this.robot]
    return [_trend_run(r) for r in sorted(same, key=lambda r: r.id)]


# ----------------------------------------------------------------------------- sign-off
def _iso_figures(e: np.ndarray | None) -> tuple[int, float | None, float | None]:
    """(cycles, AP, RP) [µm] of one pose's ``(n, 3)`` position errors [mm]; RP needs 2 cycles."""
    if e is None or not len(e):
        return 0, None, None
    if len(e) == 1:
        return 1, float(np.linalg.norm(e[0])) * 1e3, None
    st = iso9283_pose(np.zeros(3), e)
    return len(e), st.AP * 1e3, st.RP * 1e3


def _iso_uncertainty(e: np.ndarray | None, u_reading: float, u_target: float) -> tuple[float | None, float | None]:
    """Standard uncertainties of :func:`_iso_figures`' AP and RP [µm] (None where the figure is)."""
    if e is None or not len(e):
        return None, None
    u = iso9283_uncertainty(e, u_reading, u_target)
    return u.u_ap * 1e3, None if u.u_rp is None else u.u_rp * 1e3


def _iso_poses(cfg: CellConfig, steps: Sequence[PlannedStep], db: RunDB, run_id: int) -> list[IsoPose]:
    """ISO 9283 AP and RP per held-out pose, before and after correction, in plan order."""
    heads = head_targets_world(cfg)
    before = verification_errors(cfg, steps, db.measurements(run_id, kind=StepKind.VERIFY_BEFORE.value))
    after = verification_errors(cfg, steps, db.measurements(run_id, kind=StepKind.VERIFY_AFTER.value))
    poses: dict[tuple[str, int], int] = {}
    for st in steps:
        if st.kind is StepKind.VERIFY_BEFORE:
            poses.setdefault((st.point_id, st.elbow), st.point)
    out = []
    for (pid, elbow), point in poses.items():
        nb, apb, rpb = _iso_figures(before.get((pid, elbow)))
        na, apa, rpa = _iso_figures(after.get((pid, elbow)))
        x, y, z = (float(v) for v in heads[point][:3, 3])
        # the body point's CMM σ per axis (0: taken as exact) and one reading's σ, both [mm]
        u_t = float(cfg.body_sigma[point, 0]) if cfg.body_sigma is not None else 0.0
        u_r = cfg.identification.sigma_position_um * 1e-3
        ub, ua = _iso_uncertainty(before.get((pid, elbow)), u_r, u_t), _iso_uncertainty(after.get((pid, elbow)), u_r, u_t)
        out.append(IsoPose(pid, elbow, (x, y, z), nb, apb, rpb, na, apa, rpa, *ub, *ua))
    return out


def _warmup_text(cfg: CellConfig, db: RunDB, run_id: int) -> str:
    w = cfg.warmup
    if w is None:
        return ""
    what = "until the reference pose stops moving" if w.until == "converged" else f"for {w.minutes:g} min"
    done = db.load_result(run_id, "warmup", default=None)
    if not isinstance(done, Mapping):
        return f"configured ({what}, {w.program_poses} poses per cycle); the run holds no record of it"
    remaining = done.get("remaining_um")
    rest = f", remaining drift ≈ {remaining:.1f} µm" if isinstance(remaining, (int, float)) else ""
    ended = "criterion met" if done.get("converged") else "criterion NOT met"
    return (f"{done.get('cycles', '?')} cycles {what} ({w.program_poses} poses per cycle), reference "
            f"{done.get('reference', '?')}{rest} against {w.converged_um:g} µm: {ended}")


def _conditions(cfg: CellConfig, steps: Sequence[PlannedStep], db: RunDB, run_id: int) -> TestConditions:
    ident = [st for st in steps if st.kind in (StepKind.IDENTIFICATION, StepKind.REVERSAL)]
    held = {(st.point_id, st.elbow) for st in steps if st.kind is StepKind.VERIFY_BEFORE}
    p = cfg.plan
    head = cfg.head
    name = getattr(head, "name", "") or "probe head"
    k = np.asarray(cfg.head_in_flange)[:3, 3] if cfg.head_in_flange is not None else None
    load = f"the probe head '{name}'" + (f", its frame at x, y, z = {k[0]:.1f}, {k[1]:.1f}, {k[2]:.1f} mm in the "
                                        f"flange frame" if k is not None else "")
    return TestConditions(
        identification_poses=len({(st.point_id, st.elbow) for st in ident}), identification_measurements=len(ident),
        repeats=p.repeats, verification_poses=len(held), verification_cycles=p.verification_cycles, speed=p.speed,
        settle_s=p.settle_s, samples=p.samples, elbows=p.elbows, both_directions=p.both_directions, load=load,
        load_kg=cfg.verification.load_kg, warmup=_warmup_text(cfg, db, run_id),
        temperature_c=cfg.verification.temperature_c)


def check_operator(name: str) -> str:
    """The operator's name as given (``--operator``); :class:`ConfigError` for an empty, long or
    control-character name."""
    text = name.strip()
    if not text or len(text) > 256 or _CONTROL.search(text):
        raise ConfigError(f"--operator {name!r}: give the operator's name, 1 … 256 printable characters")
    return text


def _operator(cfg: CellConfig, db: RunDB, run_id: int, given: str | None) -> tuple[str, str]:
    """(name, where it came from): ``--operator``, else the one an earlier report of the run
    recorded, else ``[cell] operator``; ("", "") when none names one."""
    if given:
        return given, "--operator"
    stored = db.load_result(run_id, OPERATOR_RESULT, default=None)
    if isinstance(stored, str) and stored.strip():
        return stored.strip(), "recorded with the run's report"
    if cfg.identity.operator:
        return cfg.identity.operator, "[cell] operator"
    return "", ""


def _files(config_toml: str) -> tuple[str, str]:
    """The [head] and [body] files the configuration names ("" for none)."""
    try:
        data = tomllib.loads(config_toml)
    except tomllib.TOMLDecodeError:
        return "", ""
    head, body = data.get("head"), data.get("body")
    return (str(head.get("file", "")) if isinstance(head, dict) else "",
            str(body.get("file", "")) if isinstance(body, dict) else "")


def _traceability(cfg: CellConfig, db: RunDB, run_id: int, station_version: str, config_toml: str,
                  operator: str | None) -> Traceability:
    name, source = _operator(cfg, db, run_id, operator)
    head_file, body_file = _files(config_toml)
    hc, bc = cfg.head_certificate, cfg.body_certificate
    return Traceability(
        robot_serial=cfg.identity.robot_serial, controller=cfg.identity.controller, operator=name, operator_from=source,
        head=getattr(cfg.head, "name", "") or "probe head", head_file=head_file, head_certificate_id=hc.id,
        head_certificate_date=hc.date, body=f"{len(cfg.point_ids)} measuring points", body_file=body_file,
        body_certificate_id=bc.id, body_certificate_date=bc.date, software=software_rows(station_version))


def report_data_for_run(db: RunDB, run_id: int, *, operator: str | None = None) -> ReportData:
    """The report of run ``run_id``; ``operator`` (``--operator``) names the operator, else the
    one recorded with the run, else ``[cell] operator``."""
    run = db.run(run_id)
    summary = _stored_summary(db, run_id)
    try:
        cfg = stored_config(db, run_id)
    except ConfigError as exc:
        raise ConfigError(f"no report for run {run_id}: its stored configuration does not read with this "
                          f"station version ({exc})") from None
    steps = stored_plan(db, run_id)
    if not _reached(db, run_id, summary, "identification"):
        # a run stopped before its identification shows none of its figures (issue 36): recomputed
        # from the measurements it had, they would read as the run's own under "Not reached"
        return _partial_report(db, run_id, cfg, steps, summary, _not_reached_reason(run_id, summary, run.status), operator)
    try:  # from the set-up the run identified from (the located one, issue 37), as the run did
        res = _identify(located_config(cfg, db, run_id), db, run_id, run.status, summary)
    except IdentificationError as exc:  # a report all the same: how far the run got (issue 29)
        return _partial_report(db, run_id, cfg, steps, summary, str(exc), operator)
    # which directions are the set-up's and what the base frame is tied to (issue 36)
    notes: list[str] = [n for n in res.notes if n.startswith(BASE_FRAME_NOTE_PREFIX)]
    # the figures the run identified, streamed and stored, not computed again (issue 42)
    res = with_stored_figures(res, db.load_result(run_id, "identification", default=None), notes)
    table = None
    if cfg.model.is_scara and not _reached(db, run_id, summary, "correction"):
        notes.append("the run did not reach its correction table: none is shown (none is rebuilt from its "
                     "identification)")
    elif cfg.model.is_scara:  # an articulated arm gets compensated targets, no table
        try:
            table = _rebuilt_table(cfg, db, run_id, res, notes)
        except StationError as exc:
            notes.append(f"the correction table could not be rebuilt for the report ({exc})")
    try:
        if table is None:
            raise ConfigError("no table")
        xy, sig, acc_elbows, where = _accuracy_on_grid(cfg, res, table)
    except (StationError, ValueError, np.linalg.LinAlgError):
        xy, sig, acc_elbows, where = _accuracy_on_plan(cfg, res)
    before = _errors_um(cfg, steps, db, run_id, StepKind.VERIFY_BEFORE)
    after = _errors_um(cfg, steps, db, run_id, StepKind.VERIFY_AFTER)
    oracle = _errors_um(cfg, steps, db, run_id, StepKind.REFERENCE)
    labels, (b, a, o) = _aligned(before, after, oracle)
    pose_labels = _pose_labels(db.measurements(run_id, kind=StepKind.IDENTIFICATION.value))
    devices = db.load_result(run_id, "devices", default=None)
    idx = res.chosen_index
    return ReportData(
        robot_name=cfg.model.name, run_id=run_id,
        param_names=list(res.chosen), param_nominal=np.asarray(cfg.model.nominal)[idx],
        param_identified=res.estimates, param_sigma=res.uncertainty.sigma,
        param_is_angle=cfg.model.is_angle()[idx], residuals=res.residuals,
        param_correlation=correlation_from_covariance(res.uncertainty.covariance),
        outliers=tuple(res.outliers),
        accuracy_xy_mm=xy, accuracy_sigma_mm=sig, accuracy_elbows=acc_elbows, accuracy_where=where,
        errors_before_um=b, errors_after_um=a if after[0].size else np.zeros(0),
        oracle_after_um=o if oracle[0].size and after[0].size else None, summary=summary,
        pose_labels=pose_labels if len(pose_labels) == res.residuals.shape[0] else None,
        verify_labels=labels, created=run.created_utc,
        config_toml=run.config_toml, station_version=run.station_version,
        devices=devices if isinstance(devices, Mapping) else None, run_status=run.status,
        table_info=_table_info(cfg, table) if table is not None else None, notes=notes,
        trend=_trend(db, run_id, notes),
        simulated=run.seed is not None or bool(oracle[0].size),  # a simulated run stores its seed
        conditions=_conditions(cfg, steps, db, run_id), iso_poses=_iso_poses(cfg, steps, db, run_id),
        acceptance=Acceptance(Options().min_gain, cfg.verification.max_ap_um, cfg.verification.max_rp_um),
        traceability=_traceability(cfg, db, run_id, run.station_version, run.config_toml, operator),
        document_id=_document_id(cfg, run), progress=run_progress(db, run_id, steps, summary, run.status),
        cell_svg=_cell_svg(cfg, steps, notes, db.load_result(run_id, PATH_RESULT, default=None)))


def _cell_svg(cfg: CellConfig, steps: Sequence[PlannedStep], notes: list[str], stored: Any = None) -> str | None:
    """The picture of the cell with the run's planned poses (issue 40), from the pre-motion check's
    record where the run stored one (``stored``); None, and a note why, where it
    cannot be drawn (a collision check the station cannot make: the shapes or python-fcl)."""
    try:
        with stored_check(stored):
            return run_picture(cfg, steps).svg
    except Exception as exc:  # noqa: BLE001 - the rest of the report stands; the gap is stated in the notes
        notes.append(f"no picture of the cell ({type(exc).__name__}: {exc})")
        return None


def _document_id(cfg: CellConfig, run: Any) -> str:
    return document_id(cell=cfg.name, serial=cfg.identity.robot_serial,
                       robot=cfg.model.name, run_id=run.id, created=run.created_utc, config_toml=run.config_toml)


def _partial_report(db: RunDB, run_id: int, cfg: CellConfig, steps: Sequence[PlannedStep], summary: RunSummary | None,
                    reason: str, operator: str | None) -> ReportData:
    """The report of a run with nothing identified: its record, conditions, the measurements it
    took and how far it got (:mod:`~station.ui.report.progress`)."""
    run = db.run(run_id)
    before = _errors_um(cfg, steps, db, run_id, StepKind.VERIFY_BEFORE)
    after = _errors_um(cfg, steps, db, run_id, StepKind.VERIFY_AFTER)
    labels, (b, a) = _aligned(before, after)
    notes: list[str] = []
    devices = db.load_result(run_id, "devices", default=None)
    fields = partial_report_data(
        robot_name=cfg.model.name, run_id=run_id, reason=reason, errors_before_um=b,
        errors_after_um=a if after[0].size else np.zeros(0), verify_labels=labels, summary=summary,
        created=run.created_utc, config_toml=run.config_toml, station_version=run.station_version,
        devices=devices if isinstance(devices, Mapping) else None, run_status=run.status,
        trend=_trend(db, run_id, notes), notes=notes, simulated=run.seed is not None,
        conditions=_conditions(cfg, steps, db, run_id), iso_poses=_iso_poses(cfg, steps, db, run_id),
        acceptance=Acceptance(Options().min_gain, cfg.verification.max_ap_um, cfg.verification.max_rp_um),
        traceability=_traceability(cfg, db, run_id, run.station_version, run.config_toml, operator),
        document_id=_document_id(cfg, run),
        progress=run_progress(db, run_id, steps, summary, run.status) or f"Nothing was identified: {reason}")
    return ReportData(**fields)


def report_for_run(db_path: str | Path, run_id: int, out_dir: Path, *, operator: str | None = None) -> Path:
    """Write the run's report into ``out_dir``: ``report.html`` (returned) and ``report.md``.
    ``operator`` (``--operator``) is recorded with the run, so that a rebuilt report names it."""
    name = check_operator(operator) if operator is not None else None
    with RunDB(db_path) as db:
        data = report_data_for_run(db, run_id, operator=name)
        if name is not None:
            db.save_result(run_id, OPERATOR_RESULT, name)
    return write_report(Path(out_dir), data)


