"""The standard uncertainty of ISO 9283 AP and RP (issue 41) against the spread it claims to
describe: many poses simulated with a known offset, scatter and target error (seeded), AP and RP
computed as the station computes them, and the spread of those figures compared with the
uncertainty each pose's own cycles gave."""

from __future__ import annotations

import numpy as np
import pytest

from station.core.accuracy.iso9283 import iso9283_pose
from station.core.accuracy.iso9283_uncertainty import iso9283_uncertainty
from station.errors import ConfigError

OFFSET = np.array([0.05, 0.02, -0.03])  # [mm]: AP ≈ 62 µm, well above its uncertainty


def _simulate(n: int, scale: tuple[float, float, float], u_target: float, poses: int, seed: int):
    """(AP, RP, u_AP, u_RP) of ``poses`` simulated poses of ``n`` cycles each."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(poses):
        e = OFFSET + rng.normal(0.0, u_target, 3) + rng.normal(0.0, 0.01, (n, 3)) * np.asarray(scale)
        st, u = iso9283_pose(np.zeros(3), e), iso9283_uncertainty(e, 0.01, u_target)
        out.append((st.AP, st.RP, u.u_ap, u.u_rp))
    return np.array(out, dtype=float)


@pytest.mark.parametrize("n", [3, 5, 30])
def test_ap_uncertainty_is_the_spread_of_ap(n):
    r = _simulate(n, (1.0, 0.5, 2.0), 0.004, 1200, seed=n)
    spread, claimed = np.std(r[:, 0], ddof=1), np.sqrt(np.mean(r[:, 2] ** 2))
    assert claimed == pytest.approx(spread, rel=0.06), (claimed, spread)


def test_the_target_error_counts_in_ap_and_not_in_rp():
    e = OFFSET + np.random.default_rng(3).normal(0.0, 0.01, (5, 3))
    exact, uncertain = iso9283_uncertainty(e, 0.01, 0.0), iso9283_uncertainty(e, 0.01, 0.02)
    assert uncertain.u_ap > 2 * exact.u_ap and uncertain.u_ap >= 0.02 * 0.99
    assert uncertain.u_rp == exact.u_rp


@pytest.mark.parametrize("n, scale, low, high", [(3, (1.0, 1.0, 1.0), 1.0, 1.7), (3, (1.0, 0.5, 2.0), 1.0, 1.5),
                                                 (10, (1.0, 0.5, 2.0), 0.95, 1.2), (30, (1.0, 0.5, 2.0), 0.9, 1.1)])
def test_rp_uncertainty_covers_the_spread_of_rp(n, scale, low, high):
    """Never understated by more than a few per cent; overstated with few cycles (the sample
    covariance of three cycles is uncertain itself), as the module says."""
    r = _simulate(n, scale, 0.0, 500, seed=100 + n)
    ratio = np.sqrt(np.mean(r[:, 3] ** 2)) / np.std(r[:, 1], ddof=1)
    assert low <= ratio <= high, ratio


def test_one_cycle_has_ap_from_the_reading_sigma_and_no_rp():
    u = iso9283_uncertainty(np.array([[0.03, 0.0, 0.04]]), 0.002, 0.0)
    assert u.u_rp is None and u.u_ap == pytest.approx(0.002)  # along the error: the one reading's σ
    assert iso9283_uncertainty(np.zeros((1, 3)), 0.002, 0.0).u_ap == pytest.approx(0.002)  # AP = 0: no NaN


def test_same_cycles_same_uncertainty():
    e = OFFSET + np.random.default_rng(5).normal(0.0, 0.01, (4, 3))
    assert iso9283_uncertainty(e, 0.01, 0.0) == iso9283_uncertainty(e.copy(), 0.01, 0.0)


@pytest.mark.parametrize("e, u_r, u_t", [(np.zeros((0, 3)), 0.0, 0.0), (np.zeros((3, 2)), 0.0, 0.0),
                                         (np.full((3, 3), np.nan), 0.0, 0.0), (np.zeros((3, 3)), -1.0, 0.0),
                                         (np.zeros((3, 3)), 0.0, np.inf)])
def test_bad_input_is_a_typed_error(e, u_r, u_t):
    with pytest.raises(ConfigError):
        iso9283_uncertainty(e, u_r, u_t)
