"""Honest σ (issue 38): the robot file's ISO 9283 pose repeatability in the noise model, and the
a-posteriori variance factor that scales the reported σ where the residuals say the noise is larger."""

from __future__ import annotations

import math

import numpy as np
import pytest

from simulators.cell import CellTruth
from simulators.truth_kinematics import true_forward
from station.core.accuracy.iso9283 import iso9283_pose
from station.core.identification.identify import identify
from station.core.kinematics.model import robot_from_dict, robot_to_toml
from station.core.kinematics.poses import spread_joints
from station.core.measurement.measurements import MeasurementSet, add_noise, synthetic_set
from station.core.measurement.repeatability import (
    RP_PER_SIGMA,
    sigma_from_rp,
    variance_factor,
    with_repeatability,
)
from station.core.measurement.uncertainty import monte_carlo, pose_accuracy
from station.core.units import ARCSEC
from station.errors import ConfigError, Outcome
from station.io.robot.files import load_robot

SIG = np.array([0.006] * 3 + [6 * ARCSEC] * 3)


def _robot_dict(**robot) -> dict:
    return {"robot": {"name": "r3", **robot},
            "transform": [{"name": "R"}, {"name": "A1", "joint": "revolute", "z": 400.0, "limits": [-170, 170]},
                          {"name": "A2", "joint": "revolute", "x": 300.0, "limits": [-150, 150]},
                          {"name": "K", "x": 200.0}]}


def test_the_robot_files_repeatability_is_read_and_written_back(tmp_path):
    model = robot_from_dict(_robot_dict(repeatability_mm=0.02))
    assert model.repeatability_mm == 0.02
    assert robot_from_dict(_robot_dict()).repeatability_mm is None
    assert model.with_params(model.nominal).repeatability_mm == 0.02  # an identified model keeps it
    path = tmp_path / "r3.toml"
    path.write_text(robot_to_toml(model))
    assert load_robot(str(path)).repeatability_mm == 0.02  # through the schema too


@pytest.mark.parametrize("value", [-0.01, 0.0, math.inf, math.nan, 50.0, "0.02", True])
def test_a_repeatability_that_is_no_data_sheet_figure_is_refused_with_its_fix(value):
    with pytest.raises(ConfigError) as exc:
        robot_from_dict(_robot_dict(repeatability_mm=value), "r3.toml")
    msg = str(exc.value)
    assert msg.startswith("r3.toml: [robot].repeatability_mm") and "ISO 9283" in msg and "leave the key out" in msg
    assert exc.value.exit_code == int(Outcome.CONFIG_ERROR) == 2


def test_a_negative_repeatability_in_a_robot_file_is_refused_by_name(tmp_path):
    path = tmp_path / "r.toml"
    model = robot_from_dict(_robot_dict(repeatability_mm=0.02))
    path.write_text(robot_to_toml(model).replace("repeatability_mm = 0.02", "repeatability_mm = -0.02"))
    with pytest.raises(ConfigError, match="repeatability_mm = -0.02 is outside"):
        load_robot(str(path))


def test_rp_is_l_mean_plus_three_s_l_of_an_isotropic_gaussian_scatter():
    """ISO 9283 §7.2.2 on a simulated isotropic scatter of σ per axis gives RP ≈ 3.617 σ, and the
    conversion inverts it (the assumption the robot file's key is read under)."""
    rng = np.random.default_rng(4)
    sigma = 0.004
    rp = [iso9283_pose(np.zeros(3), rng.standard_normal((30, 3)) * sigma).RP for _ in range(400)]
    assert np.mean(rp) / sigma == pytest.approx(RP_PER_SIGMA, rel=0.03)
    assert sigma_from_rp(float(np.mean(rp))) == pytest.approx(sigma, rel=0.03)
    assert sigma_from_rp(None) == 0.0


def test_the_repeatability_adds_to_the_positions_only():
    s = with_repeatability(SIG, 0.02)
    sr = 0.02 / RP_PER_SIGMA
    assert s[:3] == pytest.approx(np.hypot(0.006, sr))
    assert np.array_equal(s[3:], SIG[3:])
    assert np.array_equal(with_repeatability(SIG, None), SIG)


def _scara_set(rng, n=60, scale=1.0):
    model = load_robot("sr800")
    true = model.nominal + rng.standard_normal(model.n_params) * np.where(model.is_angle(), 3e-4, 0.05)
    q = spread_joints(model, n, np.random.default_rng(7))
    exact = synthetic_set(model, "pose", q, true, sigma=SIG * scale)
    return model, true, exact


def _draws(model, exact, rng, n):
    assumed = MeasurementSet("pose", exact.joints, exact.measured, SIG)
    for _ in range(n):
        yield identify(model, assumed.with_measured(add_noise(exact, exact.measured, rng)))


def test_noise_twice_the_assumed_scales_the_reported_sigma_to_the_scatter():
    """The weights assume σ; the data carry 2σ. The a-priori σ is half the estimates' scatter; the
    a-posteriori factor (s0 ≈ 2, far beyond the χ² limit) brings the reported σ to it."""
    rng = np.random.default_rng(11)
    model, _, exact = _scara_set(rng, scale=2.0)
    results = list(_draws(model, exact, rng, 60))
    assert all(r.variance is not None and r.variance.scaled for r in results)
    s0 = np.array([r.variance.s0 for r in results])
    assert np.median(s0) == pytest.approx(2.0, rel=0.1)
    scatter = np.std([r.estimates for r in results], axis=0, ddof=1)
    reported = np.mean([r.uncertainty.sigma for r in results], axis=0)
    apriori = np.mean([r.uncertainty.sigma / r.variance.factor for r in results], axis=0)
    assert np.median(scatter / apriori) > 1.6  # the check can fail: without the factor σ is half
    ratio = scatter / reported
    assert np.all((ratio > 0.8) & (ratio < 1.2)), f"scatter/σ {ratio.min():.2f}–{ratio.max():.2f}"
    assert any("a-posteriori variance factor" in n and "scaled" in n for n in results[0].notes)


def test_noise_as_assumed_leaves_the_reported_sigma_as_propagated():
    rng = np.random.default_rng(12)
    model, _, exact = _scara_set(rng)
    results = list(_draws(model, exact, rng, 120))
    scaled = [r for r in results if r.variance.scaled]
    assert len(scaled) <= 15  # a 5 % test: 6 of 120 expected
    for r in results:
        if not r.variance.scaled:
            assert r.variance.factor == 1.0 and r.variance.s0 <= r.variance.limit
    scatter = np.std([r.estimates for r in results], axis=0, ddof=1)
    ratio = scatter / np.mean([r.uncertainty.sigma for r in results], axis=0)
    # the linear propagation's own agreement (tests/core/test_uncertainty_calibration.py holds it finer)
    assert np.all((ratio > 0.7) & (ratio < 1.3)), f"scatter/σ {ratio.min():.2f}–{ratio.max():.2f}"


def test_variance_factor_never_scales_down_and_needs_redundancy():
    small = variance_factor(np.full(100, 0.5), 10)
    assert small is not None and small.s0 == pytest.approx(0.5 * math.sqrt(100 / 90)) and small.factor == 1.0
    assert variance_factor(np.ones(5), 5) is None


def test_the_repeatability_in_the_linear_model_matches_the_monte_carlo_through_the_joints():
    """The simulated SR 800 repeats to 5 µm per joint at 450 mm; its ISO 9283 RP, as a robot file
    would state it, put into the linear model, predicts the pose σ the Monte Carlo draws through the
    joints (measurement σ alone underestimates it by ~1.3×, benchmarks/bench_sigma_honesty.py)."""
    truth = CellTruth.generate(seed=2)
    model, p = truth.model, truth.params
    kinds = [t.joint for t in model.transforms]
    rng = np.random.default_rng(5)
    q_rp = spread_joints(model, 5, rng)
    rp = max(iso9283_pose(np.zeros(3), true_forward(kinds, p, qi + rng.standard_normal((30, 4)) * truth.repeatability)
                          [:, :3, 3]).RP for qi in q_rp)
    q = spread_joints(model, 60, rng)
    exact = MeasurementSet("pose", q, true_forward(kinds, p, q), SIG)
    res = identify(model, exact.with_measured(add_noise(exact, exact.measured, rng)))
    # the a-priori σ with the key: noise-free data, so no a-posteriori factor either
    keyed = identify(model, MeasurementSet("pose", q, exact.measured, with_repeatability(SIG, rp)))
    mc = monte_carlo(model, exact, p, res.chosen_index, 400, rng, sigma_joints=truth.repeatability)
    q_h = spread_joints(model, 100, rng)

    def rms(cov) -> float:
        s = pose_accuracy(model, p, res.chosen_index, cov, q_h, setup=True).sigma[:, :3]
        return float(np.sqrt(np.mean(np.sum(s**2, axis=1))))

    mc_sigma = rms(np.cov(mc.estimates, rowvar=False))
    plain = rms(np.asarray(res.uncertainty.covariance) / res.variance.factor**2)
    assert not keyed.variance.scaled
    with_rp = rms(keyed.uncertainty.covariance)
    assert mc_sigma / plain > 1.15  # what leaving the repeatability out costs
    assert 0.8 < mc_sigma / with_rp < 1.1


def test_the_runs_summary_says_the_sigma_were_scaled_and_by_how_much():
    from station.cell.pipeline.calibration import _identification_summary
    from station.cell.records.summary import RunSummary

    rng = np.random.default_rng(13)
    model, _, exact = _scara_set(rng, scale=2.0)
    res = next(_draws(model, exact, rng, 1))
    ident = _identification_summary(res)
    assert ident.sigma_scaled_by == pytest.approx(res.variance.s0) and ident.sigma_scaled_by > 1.5
    assert ident.variance_factor_s0 == pytest.approx(res.variance.s0)
    assert ident.variance_limit_s0 == pytest.approx(res.variance.limit)
    assert [p.sigma for p in ident.parameters] == pytest.approx(list(res.uncertainty.sigma))
    out = RunSummary(Outcome.SUCCESS, identification=ident).to_json()
    assert out["identification"]["sigma_scaled_by"] == pytest.approx(res.variance.s0)
    assert RunSummary.from_json(out).identification == ident
