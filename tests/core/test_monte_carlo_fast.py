"""The Monte Carlo's fast path (issue 38) solves every set to the same fixed point as Gauss–Newton
with each set's own analytic Jacobian, chunk by chunk, whatever the data kind and inputs drawn."""

from __future__ import annotations

import numpy as np
import pytest

from station.core.accuracy.studies import StudyInputs, perturbed
from station.core.identification.identify import identify
from station.core.kinematics.poses import spread_joints
from station.core.measurement import uncertainty as unc
from station.core.measurement.measurements import random_pairs, synthetic_set
from station.core.measurement.uncertainty import monte_carlo
from station.io.robot.files import load_robot

SR800 = load_robot("sr800")
INPUTS = StudyInputs()
SIG = np.array([INPUTS.sigma_position_mm] * 3 + [INPUTS.sigma_angle_rad] * 3)
SJ = [INPUTS.sigma_joint_rad, INPUTS.sigma_joint_rad, INPUTS.sigma_joint_mm, INPUTS.sigma_joint_rad]


def _case(kind: str, seed: int = 4):
    rng = np.random.default_rng(seed)
    true = perturbed(SR800, rng, INPUTS)
    q = spread_joints(SR800, 25, rng)
    if kind == "distance":
        exact = synthetic_set(SR800, "distance", q, true, sigma=np.sqrt(2) * 0.015, pairs=random_pairs(25, 40, rng))
    else:
        exact = synthetic_set(SR800, kind, q, true, sigma=SIG if kind == "pose" else SIG[:3])
    return true, exact, identify(SR800, exact)


@pytest.mark.parametrize("kind, extra", [
    ("pose", {}),
    # repeatability and the body's points drawn too: the fit still runs at the commanded joints
    ("pose", {"sigma_joints": SJ, "point_ids": np.arange(25) // 2, "sigma_point": [0.002] * 3 + [1e-5] * 3}),
    ("position", {"sigma_joints": SJ}),
])
def test_fast_path_reaches_the_gauss_newton_solution_of_every_set(kind, extra):
    true, exact, res = _case(kind)
    fast = monte_carlo(SR800, exact, true, res.chosen_index, 40, np.random.default_rng(7), **extra)
    slow = monte_carlo(SR800, exact, true, res.chosen_index, 40, np.random.default_rng(7), exact_jacobian=True,
                       **extra)
    assert fast.n_failed == slow.n_failed == 0
    # same draws, same fixed point: the sets agree to 1e-4 of their scatter, parameter by parameter
    dev = np.abs(fast.estimates - slow.estimates) / slow.sigma
    assert dev.max() < 1e-4, (kind, dev.max())
    assert fast.iterations <= slow.iterations


def test_chunks_draw_and_solve_the_same_sets_as_one_batch(monkeypatch):
    """Chunked, the statistics come from every set: 25 sets in chunks of 7 (the last one short)."""
    true, exact, res = _case("pose")
    monkeypatch.setattr(unc, "CHUNK_SETS", 7)
    fast = monte_carlo(SR800, exact, true, res.chosen_index, 25, np.random.default_rng(3))
    slow = monte_carlo(SR800, exact, true, res.chosen_index, 25, np.random.default_rng(3), exact_jacobian=True)
    assert fast.estimates.shape == (25, len(res.chosen))
    assert (np.abs(fast.estimates - slow.estimates) / slow.sigma).max() < 1e-4
    np.testing.assert_allclose(fast.sigma, fast.estimates.std(axis=0, ddof=1), rtol=1e-12)
    # a chunk is its own draw: the sets differ from one another
    assert np.unique(np.round(fast.estimates[:, 0], 12)).size == 25


def test_a_set_the_fast_path_cannot_settle_is_solved_the_plain_way():
    """One iteration settles no set: every one is re-solved by Gauss–Newton with its own Jacobian
    (and, with one iteration there too, is as far as that gets: the same estimates)."""
    true, exact, res = _case("pose")
    fast = monte_carlo(SR800, exact, true, res.chosen_index, 10, np.random.default_rng(5), max_iter=1)
    slow = monte_carlo(SR800, exact, true, res.chosen_index, 10, np.random.default_rng(5), max_iter=1,
                       exact_jacobian=True)
    np.testing.assert_array_equal(fast.estimates, slow.estimates)


def test_distance_data_keep_gauss_newton_with_each_sets_jacobian():
    """Distances are far from linear at the chapter's noise: no expansion, the plain solution."""
    true, exact, res = _case("distance")
    fast = monte_carlo(SR800, exact, true, res.chosen_index, 12, np.random.default_rng(7))
    slow = monte_carlo(SR800, exact, true, res.chosen_index, 12, np.random.default_rng(7), exact_jacobian=True)
    np.testing.assert_array_equal(fast.estimates, slow.estimates)


def test_pose_spread_chunk_by_chunk_is_the_spread_of_all_models():
    """The study's Monte Carlo pose σ, combined over chunks of 100 models (the last one short),
    equals the standard deviation over all 1 203 at once."""
    from station.core.accuracy.studies import _mc_pose_sigma
    from station.core.kinematics.forward import forward
    from station.core.kinematics.transforms import pose_error

    rng = np.random.default_rng(0)
    true = perturbed(SR800, rng, INPUTS)
    idx = np.arange(20)
    est = true[idx] + rng.standard_normal((1203, 20)) * 1e-3
    q = spread_joints(SR800, 30, rng)
    P = np.broadcast_to(SR800.nominal, (1203, SR800.n_params)).copy()
    P[:, idx] = est
    whole = pose_error(forward(SR800, np.broadcast_to(q, (1203,) + q.shape), P), forward(SR800, q, true))
    np.testing.assert_allclose(_mc_pose_sigma(SR800, SR800.nominal, true, idx, est, q, chunk=100),
                               whole.std(axis=0, ddof=1), rtol=1e-12)
