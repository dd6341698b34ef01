"""The fit's fast path gives the figures of the plain one, bit for bit: the fixed-joints residuals
and Jacobian, MINPACK called directly, the analysis's choice of parameters, the duplicate-row
check and the one-thread BLAS block. (Speed is measured by benchmarks/bench_core.py; no test here
times anything.)"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares

from station.core import blas_threads
from station.core.accuracy.studies import StudyInputs, perturbed
from station.core.identification.fit_kernel import DataEvaluator, FitProblem, minpack_lm
from station.core.identification.identifiability import GS_RTOL, _greedy, analyze, structural_params, weighted_jacobian
from station.core.identification.identify import identify
from station.core.identification.registration import _first_equal_row
from station.core.kinematics.poses import spread_joints
from station.core.measurement.measurements import Kind, random_pairs, residuals_and_jacobian, synthetic_set
from station.io.robot.files import load_robot

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
    from station.core.identification.identify import _median

    rng = np.random.default_rng(3)
    for _ in range(500):
        n = int(rng.integers(1, 40))
        x = np.round(rng.standard_normal(n) * 10.0 ** rng.uniform(-4, 4), int(rng.integers(0, 6)))
        assert _median(x) == float(np.median(x))
        assert _median(x.reshape(1, -1)) == float(np.median(x.reshape(1, -1)))
    assert np.isnan(_median(np.array([1.0, np.nan, 2.0])))


@pytest.mark.parametrize("robot", sorted(ROBOTS))
def test_chain_tool_is_forward_and_registration_from_it_is_the_same(robot):
    from station.core.identification.fit_kernel import FixedJointsChain
    from station.core.identification.registration import register
    from station.core.kinematics.forward import forward

    model, true, data = _data(robot, "pose", 30, seed=6)
    chain = FixedJointsChain(model, data.joints, setup=True)
    for p in (model.nominal, true):
        for setup in (True, False):
            assert np.array_equal(chain.tool(p, setup=setup), forward(model, data.joints, p, setup=setup))
    pos = data.measured[:, :3, 3]
    ref = register(model, data.joints, pos, 0.01)
    fast = register(model, data.joints, pos, 0.01, base_points=chain.tool(model.nominal, setup=False)[:, :3, 3])
    assert np.array_equal(fast.transform, ref.transform) and np.array_equal(fast.residuals_mm, ref.residuals_mm)
    assert (fast.scale, fast.rms_mm, fast.worst_rows) == (ref.scale, ref.rms_mm, ref.worst_rows)


def test_duplicate_rows_are_found_only_where_joints_repeat():
    from station.core.identification.registration import data_information
    from station.errors import ConfigError

    model, _, data = _data("sr800", "pose", 20, seed=7)
    q = np.array(data.joints)
    q[5] = q[2]  # a repeated pose measured again: other readings, accepted
    meas = np.array(data.measured)
    info = data_information(model, q, meas, rows_per_item=6)
    assert info.n_distinct_joints == 19 and info.duplicate_rows == ()
    meas[5] = meas[2]  # the same reading too: a copied row
    with pytest.raises(ConfigError, match="repeat another row exactly"):
        data_information(model, q, meas, rows_per_item=6)


def test_analysis_reads_its_dependencies_and_chosen_singular_values_when_asked():
    model, _, data = _data("sr800", "pose", 25, seed=8)
    p = structural_params(model, model.nominal)
    a = analyze(model, data, p, prefer=model.prefer)
    assert "dependencies" not in vars(a) and "chosen_singular_values" not in vars(a)
    R = np.linalg.qr(weighted_jacobian(model, data, p), mode="r")
    idx = a.chosen_indices()
    unit = R[:, idx] / np.linalg.norm(R, axis=0)[idx]
    assert np.array_equal(a.chosen_singular_values, np.linalg.svd(unit, compute_uv=False))
    assert a.dependencies and a.dependencies is a.dependencies  # computed once, then kept
    assert analyze(model, data, p, prefer=model.prefer, describe=False).dependencies == ()


def test_registrations_sums_are_numpys():
    from station.core.identification.registration import _centroid, _rms_norm

    rng = np.random.default_rng(5)
    for _ in range(300):
        n, scale = int(rng.integers(1, 200)), 10.0 ** rng.uniform(-3, 4)
        frames = rng.standard_normal((n, 4, 4)) * scale
        for x in (rng.standard_normal((n, 3)) * scale, frames[:, :3, 3]):  # strided: a frame's points
            assert np.array_equal(_centroid(x), x.mean(0))
            assert _rms_norm(x) == float(np.sqrt(np.mean(np.sum(x**2, axis=1))))


def test_the_point_spread_of_pose_data_is_the_spread_of_their_positions():
    # pose data are (n, 4, 4): the spread is that of the translation column (it once read the
    # rotation's first row, about 1 "mm" whatever the robot's reach)
    from station.core.identification.registration import data_information
    from station.core.kinematics.forward import forward
    from station.io.robot.files import load_robot

    model = load_robot("sr800")
    q = np.random.default_rng(3).uniform(model.joint_limits[:, 0], model.joint_limits[:, 1], (30, model.n_joints))
    T = forward(model, q)
    info = data_information(model, q, T, rows_per_item=6)
    p = T[:, :3, 3]
    expected = float(np.sqrt(np.mean(np.sum((p - p.mean(axis=0)) ** 2, axis=1))))
    assert info.point_spread_mm == pytest.approx(expected, rel=1e-12) and info.point_spread_mm > 50.0
    assert data_information(model, q, p).point_spread_mm == pytest.approx(expected, rel=1e-12)
