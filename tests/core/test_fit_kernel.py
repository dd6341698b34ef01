"""The fit's fast path gives the figures of the plain one, bit for bit: the fixed-joints residuals
and Jacobian, MINPACK called directly, the analysis's choice of parameters, the duplicate-row
check and the one-thread BLAS block. (Speed is measured by benchmarks/bench_core.py; no test here
times anything.)"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares

from station.core import blas_threads
from station.core.fit_kernel import DataEvaluator, FitProblem, minpack_lm
from station.core.identifiability import GS_RTOL, _greedy, analyze, structural_params, weighted_jacobian
from station.core.identification import identify
from station.core.measurements import Kind, random_pairs, residuals_and_jacobian, synthetic_set
from station.core.poses import spread_joints
from station.core.registration import _first_equal_row
from station.core.study import StudyInputs, perturbed
from station.io.robot_files import load_robot

ROBOTS = {"sr800": load_robot("sr800"), "irb2600": load_robot("irb2600")}
KINDS: tuple[Kind, ...] = ("pose", "position", "distance")


def _data(robot: str, kind: Kind, n: int, seed: int = 0):
    model = ROBOTS[robot]
    rng = np.random.default_rng(seed)
    true = perturbed(model, rng, StudyInputs())
    q = spread_joints(model, n, rng)
    pairs = random_pairs(n, 3 * n, rng) if kind == "distance" else None
    return model, true, synthetic_set(model, kind, q, true, rng=rng, pairs=pairs)


@pytest.mark.parametrize("robot", sorted(ROBOTS))
@pytest.mark.parametrize("kind", KINDS)
def test_evaluator_is_residuals_and_jacobian_bit_for_bit(robot, kind):
    model, true, data = _data(robot, kind, 30)
    ev = DataEvaluator(model, data)
    points = [model.nominal, true, true + 1e-3, true]  # the last: back to a point left behind
    for p in points:
        r0, J0 = residuals_and_jacobian(model, data, p)
        assert np.array_equal(ev.residuals(p), r0)
        r1, J1 = ev.residuals_and_jacobian(p)
        assert np.array_equal(r1, r0) and np.array_equal(J1, J0)
        assert np.array_equal(ev.residuals(p), r0)


@pytest.mark.parametrize("robot", sorted(ROBOTS))
@pytest.mark.parametrize("kind", KINDS)
def test_minpack_lm_is_least_squares_lm_bit_for_bit(robot, kind):
    model, true, data = _data(robot, kind, 40, seed=3)
    idx = analyze(model, data, structural_params(model, model.nominal), prefer=model.prefer).chosen_indices()
    w = 1.0 / data.sigma
    p0 = np.array(model.nominal)

    def full(x):
        p = p0.copy()
        p[idx] = x
        return p

    ref = least_squares(lambda x: residuals_and_jacobian(model, data, full(x), with_jacobian=False)[0] * w,
                        p0[idx], jac=lambda x: residuals_and_jacobian(model, data, full(x))[1][:, idx] * w[:, None],
                        method="lm", x_scale="jac", max_nfev=200, xtol=1e-15, ftol=1e-15, gtol=1e-15)
    sol = minpack_lm(FitProblem(DataEvaluator(model, data), p0, idx, w), p0[idx], 200)
    assert np.array_equal(sol.x, ref.x)
    assert (sol.nfev, sol.status, sol.message) == (ref.nfev, ref.status, ref.message)


def test_identify_returns_the_reference_fit_and_its_uncertainty():
    model, true, data = _data("sr800", "pose", 25, seed=5)
    res = identify(model, data)
    idx = res.chosen_index
    w = 1.0 / data.sigma

    def full(x):
        p = res.start.copy()
        p[idx] = x
        return p

    ref = least_squares(lambda x: residuals_and_jacobian(model, data, full(x), with_jacobian=False)[0] * w,
                        res.start[idx], jac=lambda x: residuals_and_jacobian(model, data, full(x))[1][:, idx] * w[:, None],
                        method="lm", x_scale="jac", max_nfev=200, xtol=1e-15, ftol=1e-15, gtol=1e-15)
    assert np.array_equal(res.params, full(ref.x)) and res.iterations == ref.nfev and res.converged
    r, J = residuals_and_jacobian(model, data, res.params)
    assert np.array_equal(res.residuals.reshape(-1), r)
    _, s, Vt = np.linalg.svd(np.linalg.qr(J[:, idx] * w[:, None], mode="r"), full_matrices=False)
    np.testing.assert_allclose(res.uncertainty.sigma, np.sqrt(np.diag((Vt.T / s**2) @ Vt)), rtol=1e-9)


def _gram_schmidt(J, norms, order, rank):
    chosen: list[int] = []
    basis = np.zeros((J.shape[0], 0))
    for i in order:
        v = J[:, i] / norms[i]
        for _ in range(2):
            v = v - basis @ (basis.T @ v)
        nv = np.linalg.norm(v)
        if nv > GS_RTOL:
            chosen.append(i)
            basis = np.column_stack([basis, v / nv])
        if len(chosen) == rank:
            break
    return chosen


@pytest.mark.parametrize("robot", sorted(ROBOTS))
@pytest.mark.parametrize("kind", KINDS)
def test_greedy_choice_is_gram_schmidts(robot, kind):
    model, true, data = _data(robot, kind, 20, seed=7)
    rng = np.random.default_rng(1)
    for params in (model.nominal, structural_params(model, true), true):
        J = np.asarray(np.linalg.qr(weighted_jacobian(model, data, params), mode="r"))
        norms = np.linalg.norm(J, axis=0)
        live = [i for i in range(J.shape[1]) if norms[i] > 1e-10 * norms.max()]
        for _ in range(4):  # preference orders as a robot file or a user gives them
            order = list(rng.permutation(live))
            rank = int(np.linalg.matrix_rank(J[:, live] / norms[live], tol=None))
            assert _greedy(J, norms, order, rank) == _gram_schmidt(J, norms, order, rank)


def test_greedy_falls_back_where_a_left_out_column_is_nearly_a_combination():
    rng = np.random.default_rng(2)
    A = rng.standard_normal((8, 4))
    J = np.column_stack([A, A[:, 0] + A[:, 1] + 3e-8 * rng.standard_normal(8)])  # just under GS_RTOL
    norms = np.linalg.norm(J, axis=0)
    for order in ([0, 1, 4, 2, 3], [4, 0, 1, 2, 3], [0, 1, 2, 3, 4]):
        assert _greedy(J, norms, order, 5) == _gram_schmidt(J, norms, order, 5)


def test_first_equal_row_is_uniques():
    rng = np.random.default_rng(0)
    for _ in range(300):
        n, k = int(rng.integers(1, 30)), int(rng.integers(1, 5))
        a = rng.integers(0, 3, size=(n, k)).astype(float)
        a[rng.random(a.shape) < 0.1] = -0.0
        _, first, inv = np.unique(a, axis=0, return_index=True, return_inverse=True)
        assert np.array_equal(_first_equal_row(a), first[np.asarray(inv).reshape(-1)])


def test_single_blas_thread_restores_the_count_and_changes_no_result():
    fns = blas_threads._functions()
    A = np.random.default_rng(0).standard_normal((3000, 30))
    outside = np.linalg.qr(A, mode="r")
    before = fns[0]() if fns is not None else None
    with blas_threads.single_blas_thread():
        with blas_threads.single_blas_thread():
            inside = np.linalg.qr(A, mode="r")
            if fns is not None:
                assert fns[0]() == 1
        if fns is not None:
            assert fns[0]() == 1  # the outer block still runs on one thread
    if fns is not None:
        assert fns[0]() == before
    assert np.array_equal(inside, outside)


def test_pose_residuals_at_zero_and_half_turn_rotation_errors():
    model, true, _ = _data("sr800", "pose", 12, seed=4)
    q = spread_joints(model, 12, np.random.default_rng(4))
    exact = synthetic_set(model, "pose", q, true)  # rotation errors of round-off size
    flipped = np.array(exact.measured)
    flipped[3, :3, :3] = np.diag([1.0, -1.0, -1.0]) @ flipped[3, :3, :3]  # one a half turn off
    for data in (exact, exact.with_measured(flipped)):
        ev = DataEvaluator(model, data)
        for p in (true, model.nominal):
            assert np.array_equal(ev.residuals(p), residuals_and_jacobian(model, data, p, with_jacobian=False)[0])


def test_median_is_numpys():
    from station.core.identification import _median

    rng = np.random.default_rng(3)
    for _ in range(500):
        n = int(rng.integers(1, 40))
        x = np.round(rng.standard_normal(n) * 10.0 ** rng.uniform(-4, 4), int(rng.integers(0, 6)))
        assert _median(x) == float(np.median(x))
        assert _median(x.reshape(1, -1)) == float(np.median(x.reshape(1, -1)))
    assert np.isnan(_median(np.array([1.0, np.nan, 2.0])))
