"""The error terms beyond geometry in a cell session (issue 30, docs/error-terms.md).

``[identification] model`` other than ``"geometric"``: after the geometric identification, the
run's measurements are extended by the terms the same way as ``station identify --model``
(:func:`station.core.terms.selection.select_model`: ``auto`` chooses by cross-validation, a list
of families forces them), with the robot file's ``[gravity]`` and ``[gears]``. An articulated arm's
verification targets are then compensated with the full model
(:func:`station.core.terms.compensation.compensated_targets_with_terms`); a SCARA's correction table
carries the terms (:func:`station.core.table.build.build_correction_table` with ``delta``).

The reference (a simulated cell's judge, :mod:`station.cell.records.judge`) must know what the
simulator knows: a simulated arm whose joints bend and err once per turn (``[simulation]
joint_errors``) has them in its judge (``RunJudge.reference_delta``), and the reference targets
are compensated with them too; otherwise after/oracle compares the station's model with a
geometric reference that cannot reach the targets. Pure functions of the configuration, the
records and the judge; nothing moves or writes.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from station.cell.config.cell_config import CellConfig
from station.cell.correction.robot_tools import judge_delta  # the reference's joint errors (one definition)
from station.cell.records.reading.stored_error_model import StoredErrorModel, stored_error_model  # read back (records)
from station.cell.records.run_records import MeasurementRecord
from station.cell.records.summary import ErrorModelSummary, ErrorTermEstimate
from station.core.identification.identify import IdentificationResult
from station.core.measurement.repeatability import variance_factor
from station.core.terms.selection import Selection
from station.core.units import UM

__all__ = ["JointDelta", "select_terms", "terms_delta", "judge_delta", "error_model_summary", "error_model_record",
           "terms_note", "StoredErrorModel", "stored_error_model"]

#: ``q ↦ Δq(q)``: ``(n, g)`` joints [rad | mm] → ``(n, g)`` where they really stand, minus ``q``
JointDelta = Callable[[np.ndarray], np.ndarray]


def select_terms(cfg: CellConfig, records: Sequence[MeasurementRecord], res: IdentificationResult,
                 reversal: Sequence[MeasurementRecord] = ()) -> Selection | None:
    """The error model ``[identification] model`` asks for, on the run's identification records, with
    ``res`` (their geometric fit) as the start; None for ``"geometric"`` (nothing is computed).

    The rows carry the measurement time (drift runs over the seconds since the first record, not
    the row order) and the side every joint arrived from
    (:func:`~station.cell.pipeline.results.run_term_rows`). ``reversal``: the run's reversal
    records (``[plan] both_directions``: the same poses approached from the other side); where the
    model can take backlash (``auto``, or ``backlash`` named) they join the data, with a geometric
    fit of both sides as the start, so that backlash is a candidate for every joint that arrived
    from both sides; otherwise the identification records alone. Kept backlash is folded into the
    geometry for the side the station's moves arrive from (:func:`_fold_backlash`)."""
    ident = cfg.identification
    if ident.terms == ("geometric",):
        return None
    from station.cell.pipeline.results import identify_run, run_measurements, run_term_rows
    from station.core.terms.error_model import GravityModel, TermSpec
    from station.core.terms.selection import select_model

    if reversal and ("auto" in ident.terms or "backlash" in ident.terms):
        records = [*records, *reversal]
        res = identify_run(cfg, records)  # the geometric fit of the data the terms extend
    data = run_measurements(cfg, records)
    rows = run_term_rows(cfg, records)
    spec = TermSpec(gravity=ident.gravity or GravityModel(), ratios=ident.gear_ratios)
    force = None if ident.terms == ("auto",) else ident.terms
    return _fold_backlash(cfg, select_model(cfg.model, data, rows=rows, spec=spec, geometric=res, force=force),
                          data.joints[0])


def _fold_backlash(cfg: CellConfig, sel: Selection, q: np.ndarray) -> Selection:
    """``sel`` with its kept backlash folded into the joint zeros of the fitted geometry for the side
    the station's own moves arrive from (direction +1: the verification, a recheck, the table's
    use; :func:`~station.cell.pipeline.results.arrival_sides`), as
    :func:`~station.cell.pipeline.results.reference_params` folds the simulated robot's: the fit
    puts each joint's zero in the middle of its lost motion, and every reader of the model leaves
    backlash at zero (:func:`~station.core.terms.error_model.prediction_basis`), which would put every
    corrected pose half the lost motion off. The geometry so moved stands, at the station's
    approach, exactly where the fit's geometry and backlash stand (``apply_joint_offsets``); the
    terms keep their values (the width of each joint's lost motion); the fit's residuals are the
    fit's. ``q``: joints of a measured pose (the sides do not depend on where). Unchanged without
    backlash."""
    from station.cell.pipeline.results import arrival_sides
    from station.core.kinematics.joint_offsets import apply_joint_offsets

    fit = sel.fit
    cols = [(k, int(n.split(".q")[1]) - 1) for k, n in enumerate(fit.basis.names) if n.startswith("backlash.q")]
    if not cols:
        return sel
    half = np.zeros(cfg.model.n_joints)
    for k, j in cols:
        half[j] = 0.5 * float(fit.values[k])
    params = apply_joint_offsets(cfg.model, fit.params, half * arrival_sides(cfg, q, 1))
    return dataclasses.replace(sel, fit=dataclasses.replace(fit, params=params))


def terms_delta(cfg: CellConfig, sel: Selection | None) -> JointDelta | None:
    """``Δq(q)`` of the kept terms (drift left out: it describes the measurement run; kept backlash is
    folded into the joint zeros, ``_fold_backlash``), or None when nothing that moves a joint was
    kept (nothing beyond geometry, or only drift and backlash)."""
    if sel is None or not sel.fit.basis.size or all(f in ("drift", "backlash") for f in sel.chosen):
        return None
    from station.core.terms.error_model import prediction_basis

    fit, ident = sel.fit, cfg.identification
    values = np.asarray(fit.values, dtype=float)

    def delta(q: np.ndarray) -> np.ndarray:
        basis, _ = prediction_basis(cfg.model, q, sel.chosen, fit.basis.names, ident.gravity, ident.gear_ratios)
        return basis.joint_delta(values)

    return delta


def error_model_summary(cfg: CellConfig, sel: Selection) -> ErrorModelSummary:
    """The summary's ``error_model``: what was chosen, the CV figures [µm], the kept terms in their units."""
    fit = sel.fit
    kept = [r for r in sel.table if r.families == sel.chosen and r.kept]
    cv_chosen = kept[-1].cv_rms_mm if kept else sel.table[0].cv_rms_mm
    # the reported σ pass the same a-posteriori check as the geometric fit's (issue 38); the
    # selection itself weighs held-out error and the a-priori σ, untouched
    var = variance_factor(fit.residuals_w, len(fit.uncertainty.sigma)) if fit.kind != "distance" else None
    factor = 1.0 if var is None else var.factor
    terms = tuple(ErrorTermEstimate(str(t["name"]), float(t["value"]), float(t["sigma"]) * factor, str(t["unit"]))
                  for t in fit.terms_dict())
    return ErrorModelSummary(model=cfg.identification.model, chosen=tuple(sel.chosen), summary=sel.summary,
                             cv=sel.cv, cv_geometric_um=sel.table[0].cv_rms_mm / UM, cv_chosen_um=cv_chosen / UM,
                             rms_residual_um=float(fit.rms_position_mm() / UM), terms=terms, sigma_scaled_by=factor)


def error_model_record(cfg: CellConfig, sel: Selection) -> dict[str, Any]:
    """The run database's ``error_model`` result: the selection's table, terms, σ and
    identifiability (:meth:`Selection.to_dict`, units stated), the configured model, and the
    geometry fitted together with the terms ``params`` [mm, rad] (the one the terms belong to)."""
    out = sel.to_dict()
    ident = cfg.identification
    out.update(model=ident.model, params=np.asarray(sel.fit.params, dtype=float).tolist(),
               rms_residual_um=float(sel.fit.rms_position_mm() / UM),
               # what the terms' basis was computed from, so that a later reader (a recheck) rebuilds Δq(q)
               # exactly, whatever the robot file says by then
               gravity=None if ident.gravity is None else dataclasses.asdict(ident.gravity),
               gear_ratios=None if ident.gear_ratios is None else list(ident.gear_ratios))
    out["units"] = {**out.get("units", {}), "params": "mm and rad (the model's parameter order)",
                    "rms_residual_um": "µm", "gravity": "m/s², kg and mm (station.core.terms.error_model.GravityModel)"}
    return out


def terms_note(es: ErrorModelSummary) -> str:
    """One line for the run's notes: the model and the kept terms with their σ."""
    arcsec = np.pi / 180.0 / 3600.0

    def fmt(t: ErrorTermEstimate) -> str:
        if t.unit == "rad":
            return f"{t.name} {t.value / arcsec:.1f}″ ({t.sigma / arcsec:.1f}″)"
        return f"{t.name} {t.value:.3g} ({t.sigma:.2g}) {t.unit}"

    head = f"error model ([identification] model = {es.model!r}): {es.summary}"
    if not es.terms:
        return head
    return (f"{head}; identification residual RMS with the terms {es.rms_residual_um:.1f} µm; terms (σ): "
            + ", ".join(fmt(t) for t in es.terms))
