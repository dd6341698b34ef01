"""The six-axis arm with joint errors beyond geometry (issue 30): what the geometric model leaves and
what ``--model auto`` recovers, per seed. ``bench_six_axis.py --terms`` prints it.

A model-level rehearsal, not a cell session: the simulated cell's true robot
(:func:`simulators.six_axis_cell.six_axis_truth`: geometric errors in every parameter, the set-up)
carries the joint errors of :func:`simulators.joint_errors.six_axis_joint_errors` (compliance of
every joint under the arm's weight and the head's, first harmonics of every joint) and repeats
to 10 µm at each joint's lever. It is measured at ``n_ident`` poses spread over the workspace as
the cell's head measures (pose, σ 15 µm and 15″), identified by the station geometric and with
``--model auto``, and both models predict ``n_held`` other poses. after: RMS position error of a
model's prediction against where the robot really stands there; oracle: the same for the truth's
own model (geometry and joint errors known; what is left is the repeatability); structure: the
truth's own model *structure* (the simulator's masses, compliance and every first harmonic) fitted
to the same measurements, the floor that estimating any model from them stands on. The joint errors
are computed by the simulator's own physics, never by the station's error terms.
"""

from __future__ import annotations

import numpy as np

from simulators.joint_errors import six_axis_joint_errors
from simulators.six_axis_cell import LEVERS_MM, six_axis_truth
from simulators.truth_kinematics import true_forward
from station.core.identification.identify import identify
from station.core.kinematics.poses import spread_joints
from station.core.measurement.measurements import MeasurementSet, add_noise
from station.core.terms.error_model import GravityModel, TermSpec, apply_terms, term_basis
from station.core.terms.fit import fit_terms
from station.core.terms.selection import select_model

SIGMA = np.array([0.015] * 3 + [15 * np.pi / 180 / 3600] * 3)


def _structure_prediction(model, data: MeasurementSet, geo, errs, q_h: np.ndarray) -> np.ndarray:
    """The truth's own structure fitted to the same data (the simulator's masses as the gravity
    model, compliance of the joints they load and every first harmonic): what estimating the right
    model from these measurements costs, the floor any selection stands on."""
    g = model.n_joints
    masses = np.zeros(g)
    for j, m in errs.masses:
        masses[j] = m
    spec = TermSpec(("compliance",) + tuple(f"cyclic.q{j + 1}" for j in range(g)),
                    GravityModel(masses=tuple(masses), payload_kg=errs.payload_kg))
    fit = fit_terms(model, data, geo, term_basis(model, data.joints, spec, params=geo.params))
    loaded = tuple(int(n.split(".q")[1]) - 1 for n in fit.basis.names if n.startswith("compliance."))
    basis = term_basis(model, q_h, spec, params=fit.params, loaded=loaded)
    cols = np.array([basis.names.index(n) for n in fit.basis.names], dtype=int)
    return apply_terms(model, q_h, fit.params, basis.select(cols), fit.values)[:, :3, 3]


def rehearse(seed: int, n_ident: int = 120, n_held: int = 200, scale: float = 1.0) -> dict:
    """One seed: geometric and auto after, oracle, the terms auto kept (see the module)."""
    truth = six_axis_truth(seed)
    model, p_true = truth.model, truth.params
    errs = six_axis_joint_errors(seed, scale)
    rng = np.random.default_rng(np.random.SeedSequence([seed, 3030]))
    kinds = [t.joint for t in model.transforms]
    rep = 0.01 / LEVERS_MM  # 10 µm at each joint's lever [rad]

    def physical(q: np.ndarray) -> np.ndarray:
        return q + errs.delta(model, p_true, q) + rng.standard_normal(q.shape) * rep

    q_id = spread_joints(model, n_ident, rng)
    T_meas = true_forward(kinds, p_true, physical(q_id))
    data = MeasurementSet("pose", q_id, T_meas, SIGMA)
    data = data.with_measured(add_noise(data, T_meas, rng))
    geo = identify(model, data)
    sel = select_model(model, data, geometric=geo)
    q_h = spread_joints(model, n_held, rng)
    real = true_forward(kinds, p_true, physical(q_h))[:, :3, 3]
    oracle = true_forward(kinds, p_true, q_h + errs.delta(model, p_true, q_h))[:, :3, 3]
    geo_pred = true_forward(kinds, geo.params, q_h)[:, :3, 3]
    fit = sel.fit
    basis = term_basis(model, q_h, TermSpec(sel.chosen))
    cols = np.array([basis.names.index(n) for n in fit.basis.names], dtype=int)
    auto_pred = apply_terms(model, q_h, fit.params, basis.select(cols), fit.values)[:, :3, 3]

    def rms(p: np.ndarray) -> float:
        return float(np.sqrt(np.mean(np.sum((p - real) ** 2, axis=1)))) * 1e3

    o = rms(oracle)
    floor = rms(_structure_prediction(model, data, geo, errs, q_h)) if errs.active else rms(geo_pred)
    return {"seed": seed, "geometric_um": rms(geo_pred), "auto_um": rms(auto_pred), "oracle_um": o,
            "structure_um": floor, "structure_vs_oracle": floor / o,
            "geometric_vs_oracle": rms(geo_pred) / o, "auto_vs_oracle": rms(auto_pred) / o, "chosen": sel.chosen,
            "cv_geometric_um": sel.table[0].cv_rms_mm * 1e3}
