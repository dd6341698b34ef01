"""The error terms beyond geometry in a cell session (issue 30, docs/error-terms.md).

``[identification] model`` other than ``"geometric"``: after the geometric identification, the
run's measurements are extended by the terms the same way as ``station identify --model``
(:func:`station.core.model_selection.select_model`: ``auto`` chooses by cross-validation, a list
of families forces them), with the robot file's ``[gravity]`` and ``[gears]``. An articulated arm's
verification targets are then compensated with the full model
(:func:`station.core.term_compensation.compensated_targets_with_terms`); a SCARA's correction table
carries the terms (:func:`station.core.correction_table.build_correction_table` with ``delta``).

The oracle must know what the simulator knows: a simulated arm whose joints bend and err once per
turn (``[simulation] joint_errors``) has them in its truth (``truth.joint_delta``), and the
oracle's targets are compensated with them too; otherwise after/oracle compares the station's
model with a geometric oracle that cannot reach the targets. Pure functions of the configuration,
the records and the truth; nothing moves or writes.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from station.cell.config.cell_config import CellConfig
from station.cell.records.run_records import MeasurementRecord
from station.cell.records.summary import ErrorModelSummary, ErrorTermEstimate
from station.core.identification import IdentificationResult
from station.core.model_selection import Selection
from station.core.units import UM

__all__ = ["JointDelta", "select_terms", "terms_delta", "truth_delta", "error_model_summary", "error_model_record",
           "terms_note", "StoredErrorModel", "stored_error_model"]

#: ``q ↦ Δq(q)``: ``(n, g)`` joints [rad | mm] → ``(n, g)`` where they really stand, minus ``q``
JointDelta = Callable[[np.ndarray], np.ndarray]


class _TruthWithJointErrors(Protocol):
    """What the oracle needs of a simulator's truth with joint errors (simulators.cell.CellTruth)."""

    joint_errors: Any

    def joint_delta(self, q_commanded: np.ndarray) -> np.ndarray: ...


def select_terms(cfg: CellConfig, records: Sequence[MeasurementRecord], res: IdentificationResult) -> Selection | None:
    """The error model ``[identification] model`` asks for, on the run's identification records, with
    ``res`` (their geometric fit) as the start; None for ``"geometric"`` (nothing is computed)."""
    ident = cfg.identification
    if ident.terms == ("geometric",):
        return None
    from station.cell.results.pipeline_results import run_measurements
    from station.core.error_terms import GravityModel, TermSpec
    from station.core.model_selection import select_model

    data = run_measurements(cfg, records)
    spec = TermSpec(gravity=ident.gravity or GravityModel(), ratios=ident.gear_ratios)
    force = None if ident.terms == ("auto",) else ident.terms
    return select_model(cfg.model, data, spec=spec, geometric=res, force=force)


def terms_delta(cfg: CellConfig, sel: Selection | None) -> JointDelta | None:
    """``Δq(q)`` of the kept terms (drift left out: it describes the measurement run), or None when
    nothing beyond geometry was kept."""
    if sel is None or not sel.fit.basis.size:
        return None
    from station.core.error_terms import prediction_basis

    fit, ident = sel.fit, cfg.identification
    values = np.asarray(fit.values, dtype=float)

    def delta(q: np.ndarray) -> np.ndarray:
        basis, _ = prediction_basis(cfg.model, q, sel.chosen, fit.basis.names, ident.gravity, ident.gear_ratios)
        return basis.joint_delta(values)

    return delta


def truth_delta(truth: Any) -> JointDelta | None:
    """The simulator's joint errors as ``Δq(q)`` at the commanded joints, or None without them (a
    real cell, or a simulated arm with ``joint_errors = "none"``)."""
    if truth is None or getattr(truth, "joint_errors", None) is None:
        return None
    t: _TruthWithJointErrors = truth
    return t.joint_delta


def error_model_summary(cfg: CellConfig, sel: Selection) -> ErrorModelSummary:
    """The summary's ``error_model``: what was chosen, the CV figures [µm], the kept terms in their units."""
    fit = sel.fit
    kept = [r for r in sel.table if r.families == sel.chosen and r.kept]
    cv_chosen = kept[-1].cv_rms_mm if kept else sel.table[0].cv_rms_mm
    terms = tuple(ErrorTermEstimate(str(t["name"]), float(t["value"]), float(t["sigma"]), str(t["unit"]))
                  for t in fit.terms_dict())
    return ErrorModelSummary(model=cfg.identification.model, chosen=tuple(sel.chosen), summary=sel.summary,
                             cv=sel.cv, cv_geometric_um=sel.table[0].cv_rms_mm / UM, cv_chosen_um=cv_chosen / UM,
                             rms_residual_um=float(fit.rms_position_mm() / UM), terms=terms)


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
                    "rms_residual_um": "µm", "gravity": "m/s², kg and mm (station.core.error_terms.GravityModel)"}
    return out


@dataclass(frozen=True)
class StoredErrorModel:
    """A run's stored error model with terms kept (result ``error_model``): the geometry fitted with
    the terms ``params`` [mm, rad], the kept ``families``, the terms' ``names`` and ``values`` (in
    their units), and what their basis is computed from."""

    params: np.ndarray
    families: tuple[str, ...]
    names: tuple[str, ...]
    values: np.ndarray
    gravity: Any  # station.core.error_terms.GravityModel | None
    gear_ratios: tuple[float, ...] | None
    rms_residual_um: float | None

    def joint_delta(self, cfg: CellConfig) -> JointDelta:
        """``Δq(q)`` of the kept terms (drift and backlash left at zero, as for any new joints)."""
        from station.core.error_terms import prediction_basis

        def delta(q: np.ndarray) -> np.ndarray:
            basis, _ = prediction_basis(cfg.model, q, self.families, self.names, self.gravity, self.gear_ratios)
            return basis.joint_delta(self.values)

        return delta


def stored_error_model(cfg: CellConfig, record: Mapping[str, Any] | None) -> StoredErrorModel | None:
    """The stored ``error_model`` result (its fields checked where records are read,
    ``record_fields.check_result_fields``) as a :class:`StoredErrorModel`; None when the run kept no
    term (or stored no error model): its geometric identification is its model. A record of older
    stations without ``gravity`` / ``gear_ratios`` takes the cell's."""
    if not record or not record.get("chosen") or not record.get("terms"):
        return None
    from station.core.error_terms import GravityModel

    g = record.get("gravity")
    if g is None:
        gravity = cfg.identification.gravity
    else:
        gravity = GravityModel(gravity=tuple(g["gravity"]), masses=None if g.get("masses") is None else tuple(g["masses"]),
                               com=None if g.get("com") is None else tuple(tuple(c) for c in g["com"]),
                               payload_kg=float(g.get("payload_kg", 0.0)),
                               payload_com=tuple(g.get("payload_com", (0.0, 0.0, 0.0))))
    ratios = record.get("gear_ratios")
    ratios = cfg.identification.gear_ratios if ratios is None else tuple(float(r) for r in ratios)
    rms = record.get("rms_residual_um")
    return StoredErrorModel(params=np.asarray(record["params"], dtype=float), families=tuple(record["chosen"]),
                            names=tuple(str(t["name"]) for t in record["terms"]),
                            values=np.array([float(t["value"]) for t in record["terms"]]),
                            gravity=gravity, gear_ratios=ratios,
                            rms_residual_um=None if rms is None else float(rms))


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
