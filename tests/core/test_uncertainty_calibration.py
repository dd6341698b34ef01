"""The reported σ must be the real scatter: for every objective, on the SCARA and on a six-axis
arm, the standard deviation of the identified parameters over 200 independent noise draws
divided by the σ that ``identify`` reports lies within 0.8–1.25 for every parameter.

Noise is put where it arises: on the measured poses, the measured positions, and for distances
on the measured *points* (distances that share a point are then correlated, as in practice).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from station.core.identification.identify import identify
from station.core.kinematics.poses import spread_joints
from station.core.measurement.distance_pairs import make_pairs
from station.core.measurement.measurements import synthetic_set
from station.io.robot.files import load_robot

ARM6 = Path(__file__).parent / "data" / "arm6_fixture.dh.csv"
DRAWS = 200


def _truth(model, rng):
    return model.nominal + rng.standard_normal(model.n_params) * np.where(model.is_angle(), 5e-4, 0.1)


@pytest.mark.parametrize("robot", ["sr800", str(ARM6)], ids=["scara", "six-axis"])
@pytest.mark.parametrize("kind", ["pose", "position", "distance"])
def test_reported_sigma_matches_actual_scatter(robot, kind):
    model = load_robot(robot)
    rng = np.random.default_rng(2026)
    n = 25
    q = spread_joints(model, n, rng)
    true = _truth(model, rng)
    pairs = make_pairs(n, "all") if kind == "distance" else None
    estimates, sigmas, chosen = [], [], None
    for _ in range(DRAWS):
        data = synthetic_set(model, kind, q, true, rng=rng, pairs=pairs)
        res = identify(model, data)
        if chosen is None:
            chosen = res.chosen
        assert res.chosen == chosen
        estimates.append(res.estimates)
        sigmas.append(res.uncertainty.sigma)
    ratio = np.std(estimates, axis=0, ddof=1) / np.mean(sigmas, axis=0)
    worst = int(np.argmax(np.abs(np.log(ratio))))
    assert np.all((ratio > 0.8) & (ratio < 1.25)), (
        f"{kind}: scatter/σ {ratio.min():.2f}–{ratio.max():.2f}, worst {chosen[worst]} {ratio[worst]:.2f}")


def test_independent_pair_treatment_would_be_too_optimistic():
    """The check above can fail: σ computed as if the 300 distances were independent is far
    smaller than the scatter (the defect of the issue: 2.9–3.0×)."""
    from station.core.measurement.uncertainty import linear_uncertainty

    model = load_robot("sr800")
    rng = np.random.default_rng(7)
    q = spread_joints(model, 25, rng)
    true = _truth(model, rng)
    pairs = make_pairs(25, "all")
    res = identify(model, synthetic_set(model, "distance", q, true, rng=rng, pairs=pairs))
    from station.core.measurement.measurements import residuals_and_jacobian

    _, J = residuals_and_jacobian(model, res_data := synthetic_set(model, "distance", q, res.params, pairs=pairs),
                                  res.params)
    naive = linear_uncertainty(J[:, res.chosen_index] / res_data.sigma[:, None], res.chosen)
    assert np.median(res.uncertainty.sigma / naive.sigma) > 1.5
