"""The table's IK keeps recent results by a digest of all its inputs: a repeated call gives the
same values as a fresh solve, a caller that writes into its copy cannot change what the next
caller gets, and any change of parameters, targets or elbow is solved anew."""

from __future__ import annotations

import numpy as np

from station.core.kinematics.forward import forward
from station.core.kinematics.poses import spread_joints
from station.core.table import build
from station.io.robot.files import load_robot

SR800 = load_robot("sr800")


def _targets(n: int = 50, seed: int = 2) -> np.ndarray:
    q = spread_joints(SR800, n, np.random.default_rng(seed))
    q[:, 1] = np.abs(q[:, 1]).clip(0.2)
    return forward(SR800, q, setup=False)


def _errors(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return SR800.nominal + rng.standard_normal(SR800.n_params) * np.where(SR800.is_angle(), 5e-4, 0.2)


def test_a_repeated_solve_gives_the_fresh_solve_s_values_and_its_own_arrays():
    T, p = _targets(), _errors(1)
    fresh_q, fresh_ok = build._solve_masked(SR800, p, T, 1)
    q1, ok1 = build._ik_masked(SR800, p, T, 1)
    q1[:] = 0.0  # the caller's copy: node_joints writes into it
    ok1[:] = False
    q2, ok2 = build._ik_masked(SR800, p, T, 1)
    assert fresh_ok.all() and np.array_equal(ok2, fresh_ok)
    assert np.array_equal(q2, fresh_q)
    assert q2.flags.writeable and not np.shares_memory(q1, q2)


def test_other_parameters_targets_or_elbow_are_solved_anew():
    T, p = _targets(), _errors(1)
    q, _ = build._ik_masked(SR800, p, T, 1)
    q_other, _ = build._ik_masked(SR800, _errors(2), T, 1)
    assert not np.allclose(q_other, q)
    assert np.array_equal(q_other, build._solve_masked(SR800, _errors(2), T, 1)[0])
    T2 = T.copy()
    T2[0, 0, 3] += 1.0  # one target 1 mm further along x
    q_moved, _ = build._ik_masked(SR800, p, T2, 1)
    assert not np.allclose(q_moved[0], q[0]) and np.array_equal(q_moved[1:], q[1:])
    q_elbow, ok_elbow = build._ik_masked(SR800, p, T, -1)
    assert np.all(np.sign(q_elbow[ok_elbow, 1]) != np.sign(q[ok_elbow, 1]))
