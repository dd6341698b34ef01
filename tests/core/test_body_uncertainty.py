"""The calibration body's CMM uncertainty in the identification and the Monte Carlo (issue 8.3).

A body point's error is the same in every measurement of that point, so the rows are correlated.
The reported σ must still be the real scatter: over 200 data sets in which each body point is
off by a fresh error (shared by all of its measurements) plus fresh measurement noise, the
standard deviation of the identified parameters ÷ the reported σ lies within 0.8–1.25.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from station.core.identification.identify import identify
from station.core.kinematics.forward import forward
from station.core.kinematics.poses import spread_joints
from station.core.kinematics.transforms import invert, pose_error, pose_to_matrix, rotation_exp
from station.core.measurement.distance_pairs import make_pairs
from station.core.measurement.measurements import (
    MeasurementSet,
    add_body_error,
    add_noise,
    residuals_and_jacobian,
    synthetic_set,
)
from station.core.measurement.uncertainty import linear_uncertainty, monte_carlo
from station.core.units import ARCSEC, UM
from station.errors import ConfigError
from station.io.robot.files import load_robot

ARM6 = Path(__file__).parent / "data" / "arm6_fixture.dh.csv"
DRAWS = 200
N_POINTS, REPEATS = 10, 4  # 10 body points, each measured 4 times (elbows, repeats)
BODY_SIGMA = (20 * UM, 10 * ARCSEC)


def _truth(model, rng):
    return model.nominal + rng.standard_normal(model.n_params) * np.where(model.is_angle(), 5e-4, 0.1)


def _case(robot, kind, seed=2026, sigma=BODY_SIGMA):
    model = load_robot(robot)
    rng = np.random.default_rng(seed)
    n = N_POINTS * REPEATS
    q = spread_joints(model, n, rng)
    true = _truth(model, rng)
    point = np.repeat(np.arange(N_POINTS), REPEATS)
    lever = rng.standard_normal((n, 3))
    lever *= 40.0 / np.linalg.norm(lever, axis=1)[:, None]  # head frame ~40 mm from the corner
    body_sigma = np.tile(sigma, (N_POINTS, 1))
    pairs = make_pairs(n, "all", groups=point) if kind == "distance" else None
    plain = synthetic_set(model, kind, q, true, pairs=pairs)
    return model, true, plain, plain.with_body(point, body_sigma, lever), rng


def _draw(model, true, data, rng):
    """One data set: every body point off by one error (shared by its measurements), plus noise."""
    if data.kind == "distance":
        pts = forward(model, data.joints, true, setup=False)[:, :3, 3]
        pts = add_body_error(data, pts, rng) + rng.standard_normal(pts.shape) * data.points_sigma()
        pr = data.distance_pairs()
        return data.with_measured(np.linalg.norm(pts[pr[:, 0]] - pts[pr[:, 1]], axis=1))
    return data.with_measured(add_noise(data, add_body_error(data, data.measured, rng), rng))


@pytest.mark.parametrize("robot, kind", [("sr800", "pose"), ("sr800", "position"), ("sr800", "distance"),
                                         (str(ARM6), "pose")], ids=["scara-pose", "scara-position",
                                                                    "scara-distance", "six-axis-pose"])
def test_reported_sigma_matches_scatter_with_body_error(robot, kind):
    model, true, plain, data, rng = _case(robot, kind)
    estimates, sigmas = [], []
    chosen: tuple[str, ...] = ()
    for _ in range(DRAWS):
        res = identify(model, _draw(model, true, data, rng))
        chosen = chosen or res.chosen
        assert res.chosen == chosen
        estimates.append(res.estimates)
        sigmas.append(res.uncertainty.sigma)
    reported = np.mean(sigmas, axis=0)
    ratio = np.std(estimates, axis=0, ddof=1) / reported
    worst = int(np.argmax(np.abs(np.log(ratio))))
    assert np.all((ratio > 0.8) & (ratio < 1.25)), (
        f"{kind}: scatter/σ {ratio.min():.2f}–{ratio.max():.2f}, worst {chosen[worst]} {ratio[worst]:.2f}")
    # the body's σ is in the reported σ: without it every parameter would be reported smaller
    # (and 20 µm against 15 µm of measurement noise is not a small share)
    without = identify(model, plain.with_measured(_draw(model, true, data, rng).measured))
    assert without.chosen == chosen
    # its a-priori σ: the a-posteriori check now sees the body's error in its residuals and scales it up (issue 38)
    factor = without.variance.factor if without.variance else 1.0
    assert np.all(reported > 1.1 * without.uncertainty.sigma / factor)


def test_treating_rows_as_independent_would_be_too_optimistic():
    """The check above can fail: weights with the body's σ but rows taken as independent (no
    sandwich) report far less than the scatter on some parameters, because the 4 measurements of a
    point share its error (on others the shared error is absorbed, e.g. by the set-up R)."""
    model, true, _, data, rng = _case("sr800", "pose")
    res = identify(model, _draw(model, true, data, rng))
    _, J = residuals_and_jacobian(model, data, res.params)
    fs = data.fit_sigma()
    naive = linear_uncertainty(J[:, res.chosen_index] / fs[:, None], res.chosen)
    assert np.max(res.uncertainty.sigma / naive.sigma) > 1.4


def test_monte_carlo_perturbs_each_point_once_per_draw():
    """The Monte Carlo with the body's σ agrees with the sandwich; one that drew the error per
    measurement (independent) would scatter less."""
    model, true, _, data, rng = _case("sr800", "pose")
    res = identify(model, _draw(model, true, data, rng))
    mc = monte_carlo(model, data, true, res.chosen_index, 400, np.random.default_rng(1))
    assert mc.n_failed == 0
    ratio = mc.sigma / res.uncertainty.sigma
    assert np.all((ratio > 0.85) & (ratio < 1.15)), ratio
    independent = data.with_body(np.arange(data.n_items), np.tile(BODY_SIGMA, (data.n_items, 1)), data.body_lever)
    mc_ind = monte_carlo(model, independent, true, res.chosen_index, 400, np.random.default_rng(1))
    assert np.max(mc.sigma / mc_ind.sigma) > 1.3


def test_sensitivity_is_the_derivative_of_the_measured_pose_by_the_body_point():
    """B = [[I, −[l]×], [0, I]]: the measured head pose is body point · M⁻¹; turning the point by
    ε about its origin and shifting it by δ changes the pose residual by −B (δ, ε)."""
    rng = np.random.default_rng(3)
    P = pose_to_matrix(np.array([120.0, -40.0, 30.0, 0.2, -0.1, 1.3]))  # KKS←MPKS (body point)
    M = pose_to_matrix(np.array([-20.0, 15.0, 35.0, 0.05, 0.3, -0.7]))  # MKKS←MPKS (what the probes measure)
    T = P @ invert(M)
    lever = T[:3, 3] - P[:3, 3]
    data = MeasurementSet("pose", np.zeros((1, 4)), T[None], np.ones(6), body_point=np.array([0]),
                          body_sigma=np.array([[1e-3, 1e-5]]), body_lever=lever[None])
    B = data.body_sensitivity()[0]
    model_T = T @ pose_to_matrix(np.array([0.01, 0.0, -0.02, 1e-4, 0.0, 2e-4]))
    for _ in range(3):
        e = rng.standard_normal(6) * np.array([1e-4] * 3 + [1e-6] * 3)
        P_err = P.copy()
        P_err[:3, :3] = rotation_exp(e[3:]) @ P[:3, :3]
        P_err[:3, 3] += e[:3]
        d = pose_error(model_T, P_err @ invert(M)) - pose_error(model_T, T)
        np.testing.assert_allclose(d, -B @ e, rtol=0, atol=1e-9)


def test_add_body_error_shares_the_error_of_a_point_and_turns_about_its_origin():
    model, true, _, data, _ = _case("sr800", "pose", sigma=(5e-3, 2e-4))
    out = add_body_error(data, data.measured, np.random.default_rng(5))
    corners = data.measured[:, :3, 3] - data.body_lever  # the body points' origins
    for g in range(N_POINTS):
        rows = np.nonzero(data.body_point == g)[0]
        dR = out[rows, :3, :3] @ np.swapaxes(data.measured[rows, :3, :3], -1, -2)
        np.testing.assert_allclose(dR, np.broadcast_to(dR[0], dR.shape), atol=1e-12)  # one rotation per point
        shift = out[rows, :3, 3] - corners[rows] - np.einsum("nij,nj->ni", dR, data.body_lever[rows])
        np.testing.assert_allclose(shift, np.broadcast_to(shift[0], shift.shape), atol=1e-9)  # one δ per point
        assert np.linalg.norm(shift[0]) > 0
    assert add_body_error(data.with_body(data.body_point, np.zeros((N_POINTS, 2)), data.body_lever),
                          data.measured, np.random.default_rng(5)) is data.measured


def test_zero_body_sigma_changes_nothing():
    """Body σ 0 (an exact body): the same fit, bit for bit, as without a body."""
    model, true, plain, data, rng = _case("sr800", "pose")
    meas = add_noise(plain, plain.measured, rng)
    exact_body = data.with_body(data.body_point, np.zeros((N_POINTS, 2)), data.body_lever)
    a = identify(model, plain.with_measured(meas))
    b = identify(model, exact_body.with_measured(meas))
    assert np.array_equal(a.params, b.params)
    assert np.array_equal(a.uncertainty.covariance, b.uncertainty.covariance)
    assert a.notes == b.notes
    assert not any("body uncertainty" in n for n in a.notes)


def test_fit_weights_add_the_body_variance_per_row():
    _, _, _, data, _ = _case("sr800", "pose")
    fs = data.fit_sigma().reshape(-1, 6)
    s = data.sigma.reshape(-1, 6)
    sp, sa = BODY_SIGMA
    np.testing.assert_allclose(fs[:, 3:], np.sqrt(s[:, 3:] ** 2 + sa**2))
    lev = data.body_lever
    pos_var = sp**2 + sa**2 * (np.sum(lev**2, axis=1)[:, None] - lev**2)  # |e_c × l|² = |l|² − l_c²
    np.testing.assert_allclose(fs[:, :3], np.sqrt(s[:, :3] ** 2 + pos_var))


def test_body_note_names_points_and_sigma():
    model, true, _, data, rng = _case("sr800", "pose")
    # 2 µm … 20 µm over the points
    sig = np.column_stack([np.linspace(2, 20, N_POINTS) * UM, np.full(N_POINTS, 10 * ARCSEC)])
    res = identify(model, _draw(model, true, data.with_body(data.body_point, sig, data.body_lever), rng))
    assert "body uncertainty included: 10 points, σ 2–20 µm, 10 ″" in " ".join(res.notes)


@pytest.mark.parametrize("kw, msg", [
    ({"body_point": np.zeros(40, dtype=int)}, "both"),
    ({"body_point": np.zeros(39, dtype=int), "body_sigma": np.zeros((1, 2))}, "body_point"),
    ({"body_point": np.full(40, 3), "body_sigma": np.zeros((2, 2))}, "indices"),
    ({"body_point": np.zeros(40, dtype=int), "body_sigma": -np.ones((1, 2))}, "≥ 0"),
])
def test_bad_body_arguments_are_config_errors(kw, msg):
    _, _, plain, _, _ = _case("sr800", "pose")
    with pytest.raises(ConfigError, match=msg):
        MeasurementSet("pose", plain.joints, plain.measured, plain.sigma, **kw)


@pytest.mark.parametrize("kind", ["pose", "position", "distance"])
def test_sandwich_equals_the_dense_formula(kind):
    """body_sandwich (summed point by point) equals (JᵀWJ)⁻¹ Jᵀ W (Σ_meas + B Σ_body Bᵀ) W J (JᵀWJ)⁻¹
    formed with the full (n_rows, n_rows) matrices."""
    from station.core.measurement.uncertainty import body_sandwich, pair_units

    model, true, _, data, _ = _case("sr800", kind)
    unit = pair_units(model, data, true)
    _, J = residuals_and_jacobian(model, data, true)
    res = identify(model, data)
    J = J[:, res.chosen_index]
    fs = data.fit_sigma(unit)
    got = body_sandwich(J / fs[:, None], res.chosen, data, fs, unit)
    # dense B: rows of the residuals by the (m·6) body errors
    B = data.body_sensitivity()
    m = data.body_sigma.shape[0]
    n, r = B.shape[0], B.shape[1]
    Bp = np.zeros((n, r, m * 6))  # the measured values (poses, points) by the body errors
    for i in range(n):
        g = data.body_point[i]
        Bp[i, :, 6 * g:6 * g + 6] = B[i]
    if kind == "distance":
        assert unit is not None
        pr = data.distance_pairs()
        Bd = np.einsum("kc,kce->ke", unit, Bp[pr[:, 0]] - Bp[pr[:, 1]])
        D = np.zeros((len(pr), 3 * n))  # distances by the measured points' coordinates
        for k, (i, j) in enumerate(pr):
            D[k, 3 * i:3 * i + 3], D[k, 3 * j:3 * j + 3] = unit[k], -unit[k]
        S_meas = D @ np.diag(data.points_sigma().reshape(-1) ** 2) @ D.T
    else:
        Bd = Bp.reshape(n * r, m * 6)
        S_meas = np.diag(data.sigma**2)
    S = S_meas + Bd @ np.diag(data.body_sigma6().reshape(-1) ** 2) @ Bd.T
    W = np.diag(1.0 / fs**2)
    bread = np.linalg.inv(J.T @ W @ J)
    dense = bread @ J.T @ W @ S @ W @ J @ bread
    np.testing.assert_allclose(got.covariance, dense, rtol=1e-6, atol=1e-14 * np.abs(dense).max())
    # the fit's weights are the diagonal of the full covariance (distances: σ_meas² = 2 σ_point²)
    np.testing.assert_allclose(np.diag(S), fs**2, rtol=1e-10)
