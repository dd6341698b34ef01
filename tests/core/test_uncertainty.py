"""Uncertainty: linear propagation vs a direct inverse and vs Monte Carlo; pose accuracy."""

from __future__ import annotations

import numpy as np
import pytest

from station.core.accuracy.studies import StudyInputs, perturbed
from station.core.identification.identify import identify
from station.core.kinematics.forward import forward
from station.core.kinematics.poses import spread_joints
from station.core.kinematics.transforms import pose_error
from station.core.measurement.measurements import synthetic_set
from station.core.measurement.uncertainty import linear_uncertainty, monte_carlo, pose_accuracy
from station.io.robot.files import load_robot

SR800 = load_robot("sr800")
INPUTS = StudyInputs()
SIG = np.array([INPUTS.sigma_position_mm] * 3 + [INPUTS.sigma_angle_rad] * 3)


@pytest.fixture(scope="module")
def study():
    """The chapter's 25-pose study, 3-D pose, seeded."""
    rng = np.random.default_rng(0)
    true = perturbed(SR800, rng, INPUTS)
    q = spread_joints(SR800, 25, rng)
    exact = synthetic_set(SR800, "pose", q, true, sigma=SIG)
    res = identify(SR800, exact)
    return true, exact, res


def test_linear_uncertainty_equals_direct_inverse(study):
    from station.core.measurement.measurements import residuals_and_jacobian

    _, exact, res = study
    _, J = residuals_and_jacobian(SR800, exact, res.params)
    Jw = J[:, res.chosen_index] / exact.sigma[:, None]
    lu = linear_uncertainty(Jw, res.chosen)
    n = np.linalg.norm(Jw, axis=0)
    direct = np.linalg.inv((Jw / n).T @ (Jw / n)) / np.outer(n, n)  # (JᵀJ)⁻¹, column-scaled
    np.testing.assert_allclose(lu.covariance, direct, rtol=1e-7, atol=0)
    np.testing.assert_allclose(lu.sigma, np.sqrt(np.diag(direct)), rtol=1e-8)
    np.testing.assert_allclose(lu.correlation, direct / np.outer(lu.sigma, lu.sigma), atol=1e-8)
    np.testing.assert_allclose(np.diag(lu.correlation), 1.0, atol=1e-12)
    assert lu.rank == 20
    assert 0 < lu.max_abs_correlation() < 1
    # σ² = Σ_i (v_ji / s_i)² (eq. 7.13)
    _, s, Vt = np.linalg.svd(Jw, full_matrices=False)
    np.testing.assert_allclose(lu.sigma**2, np.sum((Vt.T / s) ** 2, axis=1), rtol=1e-8)


def test_linear_uncertainty_small_exact_case():
    # two independent parameters, three unit-σ rows: cov = (JᵀJ)⁻¹ by hand
    J = np.array([[1.0, 0.0], [1.0, 1.0], [0.0, 2.0]])
    lu = linear_uncertainty(J, ("a", "b"))
    expected = np.linalg.inv(np.array([[2.0, 1.0], [1.0, 5.0]]))
    np.testing.assert_allclose(lu.covariance, expected, rtol=1e-13)
    assert lu.correlation[0, 1] == pytest.approx(-1 / np.sqrt(10), rel=1e-12)


def test_linear_uncertainty_rank_deficient_is_infinite():
    J = np.array([[1.0, 2.0], [2.0, 4.0], [3.0, 6.0]])
    lu = linear_uncertainty(J, ("a", "b"))
    assert lu.rank == 1
    assert np.all(np.isinf(lu.sigma))


def test_monte_carlo_agrees_with_linear(study):
    true, exact, res = study
    mc = monte_carlo(SR800, exact, true, res.chosen_index, 400, np.random.default_rng(1))
    assert mc.n_failed == 0
    assert mc.names == res.chosen
    ratio = mc.sigma / res.uncertainty.sigma
    assert np.all(np.abs(ratio - 1) < 0.25), dict(zip(res.chosen, np.round(ratio, 3)))
    # and the mean of the estimates is the noise-free solution (no bias beyond sampling)
    mean = mc.estimates.mean(axis=0)
    assert np.all(np.abs(mean - res.estimates) < 4.5 * res.uncertainty.sigma / np.sqrt(400))
    # correlations agree too
    assert np.abs(mc.correlation - res.uncertainty.correlation).max() < 0.25


def test_monte_carlo_scatter_scales_with_noise(study):
    true, exact, res = study
    base = monte_carlo(SR800, exact, true, res.chosen_index, 150, np.random.default_rng(2))
    from station.core.measurement.measurements import MeasurementSet

    double = MeasurementSet("pose", exact.joints, exact.measured, 2 * SIG)
    mc2 = monte_carlo(SR800, double, true, res.chosen_index, 150, np.random.default_rng(2))
    # same random draws, doubled σ -> doubled scatter (linear regime)
    np.testing.assert_allclose(mc2.sigma / base.sigma, 2.0, rtol=0.02)
    # joint noise (repeatability) only adds spread
    sj = [INPUTS.sigma_joint_rad, INPUTS.sigma_joint_rad, INPUTS.sigma_joint_mm, INPUTS.sigma_joint_rad]
    mcj = monte_carlo(SR800, exact, true, res.chosen_index, 150, np.random.default_rng(2), sigma_joints=sj)
    assert np.median(mcj.sigma / base.sigma) > 1.0


def test_pose_accuracy_matches_independent_propagation(study):
    true, exact, res = study
    q = spread_joints(SR800, 4, np.random.default_rng(3))
    cov_p = res.uncertainty.covariance
    acc = pose_accuracy(SR800, res.params, res.chosen_index, cov_p, q, setup=True)
    # J by central finite differences of pose_error with respect to the chosen parameters
    T0 = forward(SR800, q, res.params)
    cols = []
    for i in res.chosen_index:
        h = 1e-7 if SR800.is_angle()[i] else 1e-4
        dp = np.zeros(36)
        dp[i] = h
        cols.append((pose_error(forward(SR800, q, res.params + dp), T0)
                     - pose_error(forward(SR800, q, res.params - dp), T0)) / (2 * h))
    J = np.stack(cols, axis=-1)  # (n, 6, p)
    cov = J @ cov_p @ np.swapaxes(J, -1, -2)
    np.testing.assert_allclose(acc.sigma, np.sqrt(np.einsum("nii->ni", cov)), rtol=1e-5)
    np.testing.assert_allclose(acc.covariance, cov, rtol=1e-4, atol=1e-6 * np.abs(cov).max())
    # chapter order of magnitude: a few µm and some arc seconds
    assert np.all(acc.sigma[:, :3] < 0.05) and np.all(acc.sigma[:, :3] > 1e-4)
    # base frame: R left out
    base = pose_accuracy(SR800, res.params, res.chosen_index, cov_p, q, setup=False)
    assert base.sigma.shape == (4, 6)
    assert not np.allclose(base.sigma, acc.sigma)
