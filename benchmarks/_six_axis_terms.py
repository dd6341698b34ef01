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

The identification poses are the station's own design (issue 38), not a number picked for the
bench: :func:`design_poses` takes them from :data:`N_CANDIDATES` poses spread over the joint ranges
by the greedy I-optimal selection the articulated plan uses
(:func:`station.core.identification.pose_design.select_i_optimal` over the Jacobian of the
geometry and the terms ``auto`` designs for, :func:`station.core.terms.design.design_jacobians`),
under the plan's stopping rule (:data:`station.cell.plan.articulated.NOISE_FRACTION`: the predicted
σ at the working poses down to ¼ of the 15 µm measurement σ). On this arm that is ~450 poses: the
200 random poses the bench took before left a predicted σ of 6.0 µm (0.40 of the measurement σ),
and the estimation error that costs (8.0 µm RMS against the truth, the mean of 20 noise draws on
each of seeds 1-5, which the linear σ with the repeatability counted predicts to within 4 %) put
even the truth's own structure at after/oracle ≈ 1.07 in the mean and 1.06-1.13 on single draws.
``n_ident`` still draws that many random poses instead, to compare.
"""

from __future__ import annotations

import numpy as np

from simulators.joint_errors import six_axis_joint_errors
from simulators.six_axis_cell import LEVERS_MM, six_axis_truth
from simulators.truth_kinematics import true_forward
from station.cell.plan.articulated import NOISE_FRACTION
from station.core.identification.identifiability import analyze
from station.core.identification.identify import identify
from station.core.identification.pose_design import select_i_optimal
from station.core.kinematics.forward import forward_with_jacobian
from station.core.kinematics.model import RobotModel
from station.core.kinematics.poses import spread_joints
from station.core.measurement.measurements import MeasurementSet, add_noise, synthetic_set
from station.core.measurement.repeatability import variance_factor, with_repeatability
from station.core.terms.design import design_jacobians, term_columns
from station.core.terms.error_model import GravityModel, TermBasis, TermSpec, apply_terms, term_basis
from station.core.terms.fit import TermFit, fit_terms
from station.core.terms.selection import expand_families, select_model

SIGMA = np.array([0.015] * 3 + [15 * np.pi / 180 / 3600] * 3)
#: the pool the design picks its identification poses from, and the working poses it weighs
N_CANDIDATES = 2000
N_WORKING = 500


def design_poses(model: RobotModel, rng: np.random.Generator) -> tuple[np.ndarray, dict]:
    """The identification poses the station's design takes for ``--model auto`` on this arm (see
    the module): the joints ``(n, g)`` and the design's account (poses, candidates, predicted σ at
    the working poses and its target, µm). The nominal model, as a plan knows the robot."""
    q_cand = spread_joints(model, N_CANDIDATES, rng)
    q_work = spread_joints(model, N_WORKING, rng)
    idx = analyze(model, synthetic_set(model, "pose", q_cand, model.nominal, sigma=SIGMA), describe=False).chosen_indices()
    # what station.cell.plan.articulated.design_terms designs for under auto: compliance (lumped:
    # the robot file gives no masses) and the first harmonic of every revolute joint
    spec = TermSpec(expand_families(model, ("compliance", "cyclic")), GravityModel())
    J, G, _ = design_jacobians(model, model.nominal, idx, spec, q_cand, q_work, SIGMA)
    target = NOISE_FRACTION * float(SIGMA[0])
    design = select_i_optimal(J, G, N_CANDIDATES, enough=target**2)
    chosen = np.array(sorted(design.chosen), dtype=int)
    return q_cand[chosen], {"poses": len(chosen), "candidates": N_CANDIDATES,
                            "sigma_um": float(np.sqrt(design.mean_variance[-1])) * 1e3, "target_um": target * 1e3}


def _prediction(model: RobotModel, fit: TermFit, basis: TermBasis, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The fit's tool positions ``(n, 3)`` [mm] at joints ``q`` (``basis``: its terms there) and their
    linear σ ``(n,)`` [mm] (3-D, from the fit's covariance: the measurement σ only)."""
    P = apply_terms(model, q, fit.params, basis, fit.values)[:, :3, 3]
    G = forward_with_jacobian(model, q, fit.params).J[:, :3, fit.chosen_index]
    if basis.size:
        G = np.concatenate([G, term_columns(model, q, fit.params, basis)[:, :3]], axis=-1)
    var = np.einsum("nrp,pq,nrq->n", G, np.asarray(fit.uncertainty.covariance), G)
    return P, np.sqrt(np.maximum(var, 0.0))


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


def rehearse(seed: int, n_ident: int | None = None, n_held: int = 200, scale: float = 1.0,
             design: tuple[np.ndarray, dict] | None = None, rp_mm: float | None = None) -> dict:
    """One seed: geometric and auto after, oracle, the terms auto kept (see the module). The
    identification poses: ``n_ident`` random ones, else ``design`` (from :func:`design_poses`),
    else the design made here. ``rp_mm``: the fit weighs with the repeatability a robot file would
    state (σ per axis RP/3.617 on the positions). ``estimation_um``: auto against the truth's own prediction (what the
    fit adds to the repeatability); ``predicted_um``: the fit's linear σ there (RMS)."""
    truth = six_axis_truth(seed)
    model, p_true = truth.model, truth.params
    errs = six_axis_joint_errors(seed, scale)
    rng = np.random.default_rng(np.random.SeedSequence([seed, 3030]))
    kinds = [t.joint for t in model.transforms]
    rep = 0.01 / LEVERS_MM  # 10 µm at each joint's lever [rad]

    def physical(q: np.ndarray) -> np.ndarray:
        return q + errs.delta(model, p_true, q) + rng.standard_normal(q.shape) * rep

    if n_ident is not None:
        q_id, account = spread_joints(model, n_ident, rng), {"poses": n_ident, "candidates": None}
    else:
        q_id, account = design if design is not None else design_poses(
            model, np.random.default_rng(np.random.SeedSequence([seed, 3031])))
    T_meas = true_forward(kinds, p_true, physical(q_id))
    data = MeasurementSet("pose", q_id, T_meas, SIGMA)
    data = data.with_measured(add_noise(data, T_meas, rng))
    if rp_mm is not None:  # the robot file's ISO 9283 RP in the weights (issue 38); the noise as drawn
        data = MeasurementSet("pose", q_id, data.measured, with_repeatability(SIGMA, rp_mm))
    geo = identify(model, data)
    sel = select_model(model, data, geometric=geo)
    q_h = spread_joints(model, n_held, rng)
    real = true_forward(kinds, p_true, physical(q_h))[:, :3, 3]
    oracle = true_forward(kinds, p_true, q_h + errs.delta(model, p_true, q_h))[:, :3, 3]
    geo_pred = true_forward(kinds, geo.params, q_h)[:, :3, 3]
    fit = sel.fit
    basis = term_basis(model, q_h, TermSpec(sel.chosen))
    cols = np.array([basis.names.index(n) for n in fit.basis.names], dtype=int)
    auto_pred, auto_sigma = _prediction(model, fit, basis.select(cols), q_h)

    def rms(p: np.ndarray, ref: np.ndarray = real) -> float:
        return float(np.sqrt(np.mean(np.sum((p - ref) ** 2, axis=1)))) * 1e3

    o = rms(oracle)
    var = variance_factor(fit.residuals_w, len(fit.uncertainty.sigma))
    floor = rms(_structure_prediction(model, data, geo, errs, q_h)) if errs.active else rms(geo_pred)
    return {"seed": seed, "geometric_um": rms(geo_pred), "auto_um": rms(auto_pred), "oracle_um": o,
            "structure_um": floor, "structure_vs_oracle": floor / o,
            "geometric_vs_oracle": rms(geo_pred) / o, "auto_vs_oracle": rms(auto_pred) / o, "chosen": sel.chosen,
            "cv_geometric_um": sel.table[0].cv_rms_mm * 1e3, "design": account, "n_parameters": fit.n_parameters,
            "estimation_um": rms(auto_pred, oracle), "predicted_um": float(np.sqrt(np.mean(auto_sigma**2))) * 1e3,
            # the a-posteriori check of auto's fit (issue 38): s0 and the σ it reports, scaled where the χ² test says so
            "s0": np.nan if var is None else var.s0, "reported_um": float(np.sqrt(np.mean(auto_sigma**2))) * 1e3
            * (1.0 if var is None else var.factor),
            "missed": _missed(errs, sel.chosen)}


def _missed(errs, chosen: tuple[str, ...]) -> tuple[str, ...]:
    """The truth's families that ``chosen`` lacks: compliance where a joint bends (its fitted shape
    counts as compliance), the first harmonic of every joint that has one."""
    true = (("compliance",) if any(errs.compliance) else ()) + tuple(
        f"cyclic.q{j + 1}" for j, (a, b) in enumerate(errs.cyclic) if a or b)
    have = {f.replace("cyclic2.", "cyclic.") for f in chosen}
    return tuple(f for f in true if f not in have)
