"""Parameter identification: exact recovery, completeness of the minimal model, convergence,
objectives, outliers, and the errors it must raise."""

from __future__ import annotations

import numpy as np
import pytest

from station.core.identification.identifiability import analyze
from station.core.identification.identify import identify
from station.core.kinematics.poses import spread_joints
from station.core.kinematics.transforms import pose_error, pose_to_matrix
from station.core.measurement.measurements import MeasurementSet, random_pairs, residuals_and_jacobian, synthetic_set
from station.errors import ConfigError, IdentificationError
from station.io.robot.files import load_robot

SR800 = load_robot("sr800")
DEG = np.pi / 180


def perturbed_all(rng, length=0.1, angle=1e-3):
    p = SR800.nominal + rng.standard_normal(36) * np.where(SR800.is_angle(), angle, length)
    p[:6] += [200.0, -100.0, 30.0, 0.01, -0.02, 0.5]  # a real set-up transform
    return p


@pytest.fixture(scope="module")
def q25():
    return spread_joints(SR800, 25, np.random.default_rng(11))


def test_recovers_chosen_parameters_exactly(q25):
    exact_nom = synthetic_set(SR800, "pose", q25, SR800.nominal)
    chosen = analyze(SR800, exact_nom, prefer=SR800.prefer).chosen_indices()
    rng = np.random.default_rng(1)
    true = np.array(SR800.nominal)
    true[chosen] += rng.standard_normal(len(chosen)) * np.where(SR800.is_angle()[chosen], 2e-3, 0.3)
    res = identify(SR800, synthetic_set(SR800, "pose", q25, true))
    assert res.converged
    np.testing.assert_array_equal(res.chosen_index, chosen)
    np.testing.assert_allclose(res.params, true, rtol=0, atol=1e-9)
    assert res.rms_normalized < 1e-6
    assert res.outliers == ()


def test_all_36_perturbed_reproduces_measurements(q25):
    true = perturbed_all(np.random.default_rng(2))
    data = synthetic_set(SR800, "pose", q25, true)
    res = identify(SR800, data)
    assert len(res.chosen) == 20
    assert np.abs(res.residuals).max() < 1e-9  # mm and rad
    # and the identified model predicts *other* poses like the true robot (complete model)
    q_new = spread_joints(SR800, 50, np.random.default_rng(3))
    from station.core.kinematics.forward import forward

    err = pose_error(forward(SR800, q_new, res.params), forward(SR800, q_new, true))
    assert np.abs(err).max() < 1e-8
    # the identified model object carries the parameters
    np.testing.assert_array_equal(res.identified_model.nominal, res.params)


def _gross_start(rng, chosen, tilt_deg):
    """Data sheet with gross errors in the identified parameters: 5 mm in lengths, 3° in yaws
    (joint offsets), ``tilt_deg`` in roll/pitch."""
    yaw = np.array([n.endswith(".yaw") for n in SR800.param_names])
    e = rng.choice([-1, 1], 36) * np.where(SR800.is_angle(), np.where(yaw, 3.0, tilt_deg) * DEG, 5.0)
    start = np.array(SR800.nominal)
    start[chosen] += e[chosen]
    return start


@pytest.mark.parametrize("seed", [0, 1])
def test_converges_from_large_start_errors(q25, seed):
    rng = np.random.default_rng(seed)
    true = perturbed_all(rng)
    data = synthetic_set(SR800, "pose", q25, true)
    # from the data sheet: the set-up is 200 mm and 29° away from R = 0
    res0 = identify(SR800, data)
    assert res0.converged and np.abs(res0.residuals).max() < 1e-9
    chosen = res0.chosen_index
    start = _gross_start(rng, chosen, tilt_deg=0.0)
    res = identify(SR800, data, start=start)
    assert res.converged
    assert np.abs(res.residuals).max() < 1e-9
    np.testing.assert_array_equal(res.chosen_index, chosen)
    np.testing.assert_allclose(res.params, res0.params, atol=1e-8)
    np.testing.assert_array_equal(res.start, start)
    # degrees of tilt as well, with the minimal set named explicitly
    start = _gross_start(rng, chosen, tilt_deg=3.0)
    res = identify(SR800, data, start=start, chosen=res0.chosen)
    assert res.converged and np.abs(res.residuals).max() < 1e-9


@pytest.mark.parametrize("tilt_deg", [1e-3, 3.0])
def test_converges_from_tilted_start_automatic_choice(q25, tilt_deg):
    rng = np.random.default_rng(0)
    data = synthetic_set(SR800, "pose", q25, perturbed_all(rng))
    chosen = identify(SR800, data).chosen_index
    res = identify(SR800, data, start=_gross_start(rng, chosen, tilt_deg))
    assert np.abs(res.residuals).max() < 1e-9


def _tilted_start(rng, length, angle):
    return SR800.nominal + rng.standard_normal(36) * np.where(SR800.is_angle(), angle, length)


def test_start_errors_in_held_parameters_are_absorbed(q25):
    """Held (non-chosen) parameters stay at their start values; lengths there are absorbed."""
    true = perturbed_all(np.random.default_rng(4))
    data = synthetic_set(SR800, "pose", q25, true)
    start = np.array(SR800.nominal)
    start[~SR800.is_angle()] += np.random.default_rng(5).uniform(-3, 3, 18)  # mm only
    res = identify(SR800, data, start=start)
    held = np.setdiff1d(np.arange(36), res.chosen_index)
    np.testing.assert_array_equal(res.params[held], start[held])
    assert np.abs(res.residuals).max() < 1e-9


def test_recalibration_from_identified_model_is_well_conditioned(q25):
    true = perturbed_all(np.random.default_rng(0))
    data = synthetic_set(SR800, "pose", q25, true)
    nominal_start = identify(SR800, data)
    prev = _tilted_start(np.random.default_rng(5), 0.1, 1e-3)  # 0.06° tilts, as identified
    res = identify(SR800, data, start=prev)
    assert np.abs(res.residuals).max() < 1e-9
    assert res.identifiability.chosen_condition < 100
    assert res.uncertainty.sigma.max() < 10 * nominal_start.uncertainty.sigma.max()


def test_converges_from_start_off_in_all_parameters(q25):
    rng = np.random.default_rng(0)
    true = perturbed_all(rng)
    data = synthetic_set(SR800, "pose", q25, true)
    start = true + np.random.default_rng(1).choice([-1, 1], 36) * np.where(SR800.is_angle(), 0.1 * DEG, 0.5)
    res = identify(SR800, data, start=start)
    assert np.abs(res.residuals).max() < 1e-9


def test_position_objective(q25):
    true = perturbed_all(np.random.default_rng(5))
    data = synthetic_set(SR800, "position", q25, true)
    res = identify(SR800, data)
    assert res.kind == "position" and len(res.chosen) == 17
    assert res.residuals.shape == (25, 3)
    assert np.abs(res.residuals).max() < 1e-9


def test_distance_objective():
    q = spread_joints(SR800, 25, np.random.default_rng(6))
    pairs = random_pairs(25, 120, np.random.default_rng(7))
    true = perturbed_all(np.random.default_rng(8), length=0.05, angle=5e-4)
    data = synthetic_set(SR800, "distance", q, true, pairs=pairs)
    res = identify(SR800, data)
    assert len(res.chosen) == 11
    assert res.residuals.shape == (120, 1)
    assert np.abs(res.residuals).max() < 1e-9
    # distances only: R is not touched
    np.testing.assert_array_equal(res.params[:6], SR800.nominal[:6])


def test_distance_objective_nine_parameters():
    q = spread_joints(SR800, 25, np.random.default_rng(6))
    pairs = random_pairs(25, 120, np.random.default_rng(7))
    true = np.array(SR800.nominal)
    true[SR800.param_indices(["A2.x", "A3.x", "K.x", "A3.roll"])] += [0.2, -0.1, 0.05, 1e-3]
    data = synthetic_set(SR800, "distance", q, true, pairs=pairs)
    res = identify(SR800, data, exclude=("A4.roll", "A4.pitch"))
    assert len(res.chosen) == 9 and "A4.roll" not in res.chosen
    np.testing.assert_allclose(res.params, true, atol=1e-9)


def test_outlier_flagged(q25):
    rng = np.random.default_rng(9)
    true = perturbed_all(rng)
    data = synthetic_set(SR800, "pose", q25, true, rng=rng)
    meas = np.array(data.measured)
    meas[13, 0, 3] += 1.0  # one pose shifted 1 mm in x
    res = identify(SR800, data.with_measured(meas))
    assert 13 in res.outliers
    assert len(res.outliers) <= 2
    clean = identify(SR800, data)
    assert clean.outliers == ()
    assert 0.5 < clean.rms_normalized < 1.5  # noise of the stated σ


def test_rank_deficient_chosen_raises(q25):
    data = synthetic_set(SR800, "pose", q25, SR800.nominal)
    with pytest.raises(IdentificationError, match=r"not all identifiable.*rank 1 of 2.*station analyze"):
        identify(SR800, data, chosen=["R.x", "A1.x"])
    # an explicit identifiable set works
    res = identify(SR800, data, chosen=["A2.x", "A3.x", "K.x"])
    assert res.chosen == ("A2.x", "A3.x", "K.x")


def test_too_few_rows_raise():
    q = spread_joints(SR800, 1, np.random.default_rng(1))
    data = synthetic_set(SR800, "pose", q, SR800.nominal)
    # refused before fitting, saying what to measure
    with pytest.raises(ConfigError, match="only 1 distinct joint configuration.*spread over the workspace"):
        identify(SR800, data, chosen=["R.x", "R.y", "R.z", "R.roll", "R.pitch", "R.yaw", "K.x"])
    with pytest.raises(ConfigError, match="only 1 distinct"):
        identify(SR800, data)
    q4 = spread_joints(SR800, 4, np.random.default_rng(1))
    data4 = synthetic_set(SR800, "position", q4, SR800.nominal)
    with pytest.raises((IdentificationError, ConfigError), match="only 4 distinct.*needs at least 7"):
        identify(SR800, data4)


def test_garbage_measurements_refused_before_fitting(q25):
    rng = np.random.default_rng(10)
    garbage = pose_to_matrix(np.column_stack([rng.uniform(-3000, 3000, (25, 3)),
                                              rng.uniform(-3, 3, (25, 3))]))
    data = MeasurementSet("pose", q25, garbage, np.array([0.015] * 3 + [1e-4] * 3))
    with pytest.raises(IdentificationError, match="joint order and joint units"):
        identify(SR800, data)


def test_bad_start_raises(q25):
    data = synthetic_set(SR800, "pose", q25, SR800.nominal)
    bad = np.array(SR800.nominal)
    bad[3] = np.nan
    with pytest.raises(IdentificationError, match="finite"):
        identify(SR800, data, start=bad)


def test_result_residuals_are_those_at_the_returned_params(q25):
    rng = np.random.default_rng(12)
    true = perturbed_all(rng)
    data = synthetic_set(SR800, "pose", q25, true, rng=rng)
    res = identify(SR800, data)
    r, J = residuals_and_jacobian(SR800, data, res.params)
    np.testing.assert_array_equal(res.residuals, r.reshape(25, 6))
    rn = (r / data.sigma).reshape(25, 6)
    assert res.rms_normalized == pytest.approx(np.sqrt(np.mean(rn**2)), rel=1e-14)
    np.testing.assert_allclose(res.normalized, np.sqrt(np.mean(rn**2, axis=1)), rtol=1e-14)
    # uncertainty from the Jacobian at the result
    Jw = J[:, res.chosen_index] / data.sigma[:, None]
    n = np.linalg.norm(Jw, axis=0)  # column-scaled inverse: JᵀJ itself has condition ~1e16
    cov = np.linalg.inv((Jw / n).T @ (Jw / n)) / np.outer(n, n)
    np.testing.assert_allclose(res.uncertainty.covariance, cov, rtol=1e-6, atol=0)
    # first-order optimality at the returned parameters
    g = Jw.T @ (r / data.sigma)
    assert np.linalg.norm(g) < 1e-6 * np.linalg.norm(Jw, 2) * np.linalg.norm(r / data.sigma)
