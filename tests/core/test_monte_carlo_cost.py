"""What the Monte Carlo's fast path evaluates (issue 38): the forward kinematics of every set once,
at its linear solution; the later iterates' residuals come from the expansion, and still reach
the Gauss–Newton solution of every set (tests/core/test_monte_carlo_fast.py)."""

from __future__ import annotations

import numpy as np
import pytest

from station.core.accuracy.studies import StudyInputs, perturbed
from station.core.identification.identify import identify
from station.core.kinematics.poses import spread_joints
from station.core.measurement import uncertainty as unc
from station.core.measurement.measurements import synthetic_set
from station.io.robot.files import load_robot

SR800 = load_robot("sr800")
INPUTS = StudyInputs()
SIG = np.array([INPUTS.sigma_position_mm] * 3 + [INPUTS.sigma_angle_rad] * 3)


def _counted(monkeypatch) -> list[int]:
    """The parameter sets of every residual evaluation without a Jacobian (the solve's), in order."""
    sets: list[int] = []
    real = unc.residuals_and_jacobian

    def counting(model, data, params, *args, with_jacobian=True, **kw):
        if not with_jacobian:
            p = np.asarray(params)
            sets.append(1 if p.ndim == 1 else p.shape[0])
        return real(model, data, params, *args, with_jacobian=with_jacobian, **kw)

    monkeypatch.setattr(unc, "residuals_and_jacobian", counting)
    return sets


@pytest.mark.parametrize("chunk", [2000, 7])
def test_each_set_costs_one_forward_and_the_estimates_stay_gauss_newtons(monkeypatch, chunk):
    rng = np.random.default_rng(2)
    true = perturbed(SR800, rng, INPUTS)
    q = spread_joints(SR800, 25, rng)
    exact = synthetic_set(SR800, "pose", q, true, sigma=SIG)
    res = identify(SR800, exact)
    slow = unc.monte_carlo(SR800, exact, true, res.chosen_index, 30, np.random.default_rng(9), exact_jacobian=True)
    monkeypatch.setattr(unc, "CHUNK_SETS", chunk)
    sets = _counted(monkeypatch)
    fast = unc.monte_carlo(SR800, exact, true, res.chosen_index, 30, np.random.default_rng(9))
    chunks = -(-30 // chunk)
    # per chunk: the residuals at p̄ (one parameter set for all) and at every set's linear solution
    assert sets == [1, min(chunk, 30)] * (chunks - 1) + [1, 30 - (chunks - 1) * chunk]
    assert fast.iterations >= 2 and fast.n_failed == 0
    assert (np.abs(fast.estimates - slow.estimates) / slow.sigma).max() < 1e-4
