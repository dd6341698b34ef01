"""Uncertainty of identified parameters and of the poses they predict (brief §6, chapter 7.4).

* :func:`linear_uncertainty` — linear propagation by SVD of the σ-normalised Jacobian
  (eq. 7.9–7.13): C' = U S Vᵀ, Σ_p = V S⁻² Vᵀ. Covers measurement noise only. Exact for
  independent residual rows (pose and position data).
* :func:`distance_sandwich` — the same for distances, which are *not* independent: d_ij and
  d_ik share the noise of point i (brief §10). Their covariance is C = D Σ_points Dᵀ, with D the
  derivative of the distances by the measured points (rows u_ijᵀ, −u_ijᵀ). The fit is the
  plain (unweighted) least squares of eq. 7.6, so its covariance is the sandwich
  (JᵀJ)⁻¹ Jᵀ C J (JᵀJ)⁻¹; Jᵀ C J = (DᵀJ)ᵀ Σ_points (DᵀJ) is formed point by point, never as a
  (k, k) matrix, so it costs O(k·p) for k pairs.
* :func:`body_sandwich` — the same when rows share the error of a calibration-body point
  (every measurement at that point: repeats, both elbows, all cycles): the fit weights rows with
  σ_meas² + σ_body², and the covariance is the sandwich (JᵀWJ)⁻¹ Jᵀ W (Σ_meas + B Σ_body Bᵀ) W J
  (JᵀWJ)⁻¹, B the derivative of the measured values by the points' errors.
* :func:`monte_carlo` — many synthetic data sets drawn from the input distributions of what is
  actually measured (the measured points or poses, the joints through the robot's
  repeatability, the calibration-body geometry per measuring point; distances are then computed
  from the perturbed points, never perturbed themselves), each identified by Gauss–Newton; all
  data sets are solved together as one batched computation.
* :func:`pose_accuracy` — Σ_pose = J_pose Σ_p J_poseᵀ at any joint configurations.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from station.core.blas_threads import single_blas_thread
from station.core.kinematics.forward import forward, forward_with_jacobian
from station.core.kinematics.model import RobotModel
from station.core.kinematics.transforms import rotation_exp
from station.core.measurement.measurements import (
    MeasurementSet,
    add_body_error,
    add_noise,
    model_outputs,
    residuals_and_jacobian,
)


def _ro(a):
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class LinearUncertainty:
    """``covariance``: ``(p, p)`` in [mm, rad]²; ``sigma``: ``(p,)``; ``correlation``: ``(p, p)``."""

    names: tuple[str, ...]
    sigma: np.ndarray
    covariance: np.ndarray
    correlation: np.ndarray
    singular_values: np.ndarray
    rank: int

    def max_abs_correlation(self) -> float:
        c = np.abs(self.correlation - np.eye(len(self.names)))
        return float(c.max()) if c.size else 0.0


def linear_uncertainty(Jw: np.ndarray, names: tuple[str, ...], rtol: float = 1e-12) -> LinearUncertainty:
    """Parameter covariance from the σ-normalised Jacobian ``Jw`` ``(n_rows, p)``."""
    if Jw.shape[0] > 2 * Jw.shape[1]:
        # Same singular values and V from the (p, p) triangular factor; U is never needed.
        Jw = np.linalg.qr(Jw, mode="r")  # type: ignore[assignment]  # mode="r" returns R alone
    _, s, Vt = np.linalg.svd(Jw, full_matrices=False)
    rank = int(np.sum(s > rtol * s[0])) if s.size and s[0] > 0 else 0
    with np.errstate(divide="ignore"):
        inv_s2 = np.where(s > rtol * (s[0] if s.size else 1.0), 1.0 / s**2, np.inf)
    cov = (Vt.T * inv_s2) @ Vt if rank == len(s) else np.full((len(s), len(s)), np.inf)
    sig = np.sqrt(np.diag(cov))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(sig, sig)
    return LinearUncertainty(tuple(names), _ro(sig), _ro(cov), _ro(corr), _ro(s), rank)


def distance_sandwich(Jw: np.ndarray, names: tuple[str, ...], pairs: np.ndarray, unit: np.ndarray,
                      row_sigma: np.ndarray, point_sigma: np.ndarray, n_points: int) -> LinearUncertainty:
    """Parameter covariance of a distance fit whose distances share measured points.

    ``Jw``: ``(k, p)`` Jacobian of the distances divided by ``row_sigma`` ``(k,)`` (the fit's
    weights); ``unit``: ``(k, 3)`` unit vectors p_i − p_j of every pair; ``point_sigma``:
    ``(n, 3)`` σ [mm] of the measured points' coordinates.
    """
    base = linear_uncertainty(Jw, names)
    if base.rank < Jw.shape[1]:
        return base
    return _sandwich(base, _distance_point_meat(Jw / row_sigma[:, None], pairs, unit, point_sigma, n_points))


def _distance_point_meat(JW: np.ndarray, pairs: np.ndarray, unit: np.ndarray, point_sigma: np.ndarray,
                         n_points: int) -> np.ndarray:
    """Jᵀ W C W J of distances from measured points: ``JW`` ``(k, p)`` is W J (rows of J divided
    by σ²); C = D Σ_points Dᵀ is never formed."""
    pr = np.asarray(pairs, dtype=int)
    # G = Dᵀ W J: for every point and coordinate, the sum over its pairs of ±u·(weighted row).
    contrib = unit[:, :, None] * JW[:, None, :]  # (k, 3, p)
    G = np.zeros((n_points, 3, JW.shape[1]))
    np.add.at(G, pr[:, 0], contrib)
    np.add.at(G, pr[:, 1], -contrib)
    Gs = (G * np.asarray(point_sigma)[:, :, None]).reshape(-1, JW.shape[1])
    return Gs.T @ Gs


def _sandwich(base: LinearUncertainty, meat: np.ndarray) -> LinearUncertainty:
    """bread · meat · bread with the bread (JᵀWJ)⁻¹ of ``base``."""
    bread = base.covariance
    cov = bread @ meat @ bread
    cov = 0.5 * (cov + cov.T)
    sig = np.sqrt(np.diag(cov))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(sig, sig)
    return LinearUncertainty(base.names, _ro(sig), _ro(cov), _ro(corr), base.singular_values, base.rank)


def _add_by_group(G: np.ndarray, groups: np.ndarray, values: np.ndarray) -> None:
    """``G[g] += Σ values[i]`` over the ``i`` with ``groups[i] == g`` (sorted sums: far faster
    than ``np.add.at`` for many rows)."""
    order = np.argsort(groups, kind="stable")
    g = groups[order]
    starts = np.flatnonzero(np.r_[True, g[1:] != g[:-1]])
    G[g[starts]] += np.add.reduceat(values[order], starts, axis=0)


def body_sandwich(Jw: np.ndarray, names: tuple[str, ...], data: MeasurementSet, fit_sigma: np.ndarray,
                  unit: np.ndarray | None = None) -> LinearUncertainty:
    """Parameter covariance of a fit whose rows share the errors of the calibration body's points.

    ``Jw``: ``(n_rows, p)`` Jacobian of the residuals divided by ``fit_sigma`` ``(n_rows,)``, the
    σ the fit weighted every row with (W = diag(fit_sigma⁻²), σ_meas² + σ_body² per row:
    :meth:`MeasurementSet.fit_sigma`). ``unit``: ``(k, 3)`` pair unit vectors (distance data).

    Cov = (JᵀWJ)⁻¹ Jᵀ W (Σ_meas + B Σ_body Bᵀ) W J (JᵀWJ)⁻¹. Σ_meas is diag(σ_meas²) for pose and
    position rows and the points' covariance for distances (as :func:`distance_sandwich`). B
    (:meth:`MeasurementSet.body_sensitivity`) maps each body point's error (δ, ε) [mm, rad] to the
    rows of every measurement at that point, so rows that share a point are correlated; Jᵀ W B
    is summed point by point, never formed as an (n_rows, n_rows) matrix: O(n_rows · p).
    """
    base = linear_uncertainty(Jw, names)
    p = Jw.shape[1]
    if base.rank < p:
        return base
    JW = Jw / np.asarray(fit_sigma)[:, None]  # W J
    if data.kind == "distance":
        if unit is None:
            raise ValueError("distance data need the pairs' unit vectors")
        meat = _distance_point_meat(JW, data.distance_pairs(), unit, data.points_sigma(), data.joints.shape[0])
    else:
        A = JW * data.sigma[:, None]
        meat = A.T @ A
    if not data.has_body_sigma:
        return _sandwich(base, meat)
    assert data.body_point is not None
    B = data.body_sensitivity()  # (n, r, 6)
    sig6 = data.body_sigma6()
    G = np.zeros((sig6.shape[0], 6, p))  # Bᵀ W J, per body point
    if data.kind == "distance":
        assert unit is not None
        pr = data.distance_pairs()
        for col, sign in ((0, 1.0), (1, -1.0)):
            a = (unit[:, None, :] @ B[pr[:, col]])[:, 0, :]  # (k, 6): uᵀ B of the pair's point
            _add_by_group(G, data.body_point[pr[:, col]], sign * a[:, :, None] * JW[:, None, :])
    else:
        contrib = np.swapaxes(B, 1, 2) @ JW.reshape(B.shape[0], B.shape[1], p)  # (n, 6, p)
        _add_by_group(G, data.body_point, contrib)
    Gs = (G * sig6[:, :, None]).reshape(-1, p)
    return _sandwich(base, meat + Gs.T @ Gs)


@dataclass(frozen=True)
class PoseAccuracy:
    """Predicted σ of the tool pose: ``sigma`` ``(n, 6)`` [mm, rad] per axis x, y, z, rx, ry, rz,
    ``covariance`` ``(n, 6, 6)`` with the correlations."""

    joints: np.ndarray
    sigma: np.ndarray
    covariance: np.ndarray


def pose_accuracy(model: RobotModel, params, chosen_index, covariance, joints, setup: bool = False) -> PoseAccuracy:
    """Propagate the parameter covariance to the tool pose at ``joints`` ``(n, g)``.

    ``setup=False`` (default) leaves out the set-up transform R: what a later user of the robot
    gets in the robot base frame.
    """
    q = model.check_joints(joints)
    res = forward_with_jacobian(model, q, params, setup=setup)
    Jp = res.J[..., np.asarray(chosen_index)]
    cov = Jp @ np.asarray(covariance) @ np.swapaxes(Jp, -1, -2)
    return PoseAccuracy(_ro(q), _ro(np.sqrt(np.einsum("nii->ni", cov))), _ro(cov))


@dataclass(frozen=True)
class MonteCarloResult:
    """``estimates``: ``(n_sets, p)`` identified values of the chosen parameters;
    ``sigma``: ``(p,)`` their sample standard deviation; ``bias``: mean − the exact value (``true_params``)."""

    names: tuple[str, ...]
    estimates: np.ndarray
    sigma: np.ndarray
    bias: np.ndarray
    correlation: np.ndarray
    iterations: int
    n_failed: int


#: data sets drawn and solved together: bounds the memory (the outputs and residuals of one chunk,
#: a few 10 MB at 25 poses) whatever ``n_sets`` is; the statistics are summed chunk by chunk.
CHUNK_SETS = 2000


def monte_carlo(model: RobotModel, data: MeasurementSet, true_params, chosen_index, n_sets: int,
                rng: np.random.Generator, start=None, sigma_joints=None, point_ids=None,
                sigma_point=None, max_iter: int = 12, tol: float = 1e-11,
                exact_jacobian: bool = False) -> MonteCarloResult:
    """Identify ``n_sets`` synthetic data sets like ``data`` drawn around ``true_params``.

    Inputs drawn per data set: measurement noise of ``data.sigma`` (distance data: of the
    measured points, ``data.point_sigma``, with the distances computed from them); robot repeatability as
    Gaussian joint noise ``sigma_joints`` ``(g,)`` (the robot reports the commanded joints but
    stands slightly elsewhere; a robot file's ISO 9283 RP is already in ``data.sigma`` where the
    data come from :meth:`~station.cell.config.sections.IdentificationConfig.pose_sigma`, drawn as
    position noise: give one or the other for one robot, never both); calibration-body geometry as one pose error of σ
    ``sigma_point`` ``(6,)`` per measuring point ``point_ids`` ``(n,)`` shared by all
    measurements at that point (pose and position data), and, when ``data`` carries the body's
    uncertainty (``body_point``, ``body_sigma``, ``body_lever``), one error per body point and
    data set turning the point about its origin (:func:`station.core.measurement.measurements.add_body_error`),
    with the fit weighted as :func:`station.core.identification.identify` weights it.

    Every set is solved to the Gauss–Newton fixed point Jᵀ(p) W r(p) = 0 with its own residuals
    r(p) (the model's forward kinematics at the set's parameters), the chosen parameters moving
    from ``start`` (default nominal) and the others held there. The sets are drawn and solved
    ``CHUNK_SETS`` at a time. Fast path (default): the noise-free data's solution p̄ is found once;
    about it each set's Jacobian is J(p̄) + H·(p − p̄), exact to O(|p − p̄|²) (H by central
    differences of the analytic Jacobian, (rows, m, m)), and the steps use J(p̄)ᵀJ(p̄), factored
    once: a quasi-Newton iteration with the Gauss–Newton fixed point (each step's error shrinks
    ~1e-3-fold at µm noise), so each set costs one forward kinematics (at the linear solution; the
    later iterates' residuals follow from the expansion, :meth:`_Expansion.solve`) instead of an
    analytic Jacobian and a solve per iteration. A set that does not converge within ``max_iter`` is solved
    again the plain way. ``exact_jacobian=True`` (and
    distance data, always) solves every set by Gauss–Newton with its own analytic Jacobian at every
    iteration (the reference the fast path is tested against; ~10× slower).
    """
    with single_blas_thread():
        return _monte_carlo(model, data, true_params, chosen_index, n_sets, rng, start, sigma_joints, point_ids,
                            sigma_point, max_iter, tol, exact_jacobian)


def _monte_carlo(model, data, true_params, chosen_index, n_sets, rng, start, sigma_joints, point_ids, sigma_point,
                 max_iter, tol, exact_jacobian) -> MonteCarloResult:
    """:func:`monte_carlo` on one BLAS thread: its products are many small ones (sets × rows ×
    parameters), where OpenBLAS's threads on a busy two-core machine cost more CPU in waiting
    than they save (a 10 000-set study: 1.9 s of CPU on two threads, 1.1 s on one, load ~7)."""
    idx = np.asarray(chosen_index, dtype=int)
    p_exact = np.asarray(true_params, dtype=float)
    p0 = np.array(model.nominal if start is None else start, dtype=float)
    w = 1.0 / data.fit_sigma(pair_units(model, data, p_exact) if data.has_body_sigma else None)
    est = np.empty((n_sets, idx.size))
    it = 0
    # distances are far from linear at the chapter's noise (condition ≈ 1600; some sets land ~10 σ
    # away, where the expansion's O(|p − p̄|²) no longer vanishes): they keep the plain path
    fast = not exact_jacobian and data.kind != "distance"
    lin = _Expansion.about(model, data, p_exact, p0, idx, w, max_iter, tol) if fast else None
    for lo in range(0, n_sets, CHUNK_SETS):
        n = min(CHUNK_SETS, n_sets - lo)
        measured = _draw(model, data, p_exact, n, rng, sigma_joints, point_ids, sigma_point)
        if lin is None:
            e, k, _ = _gauss_newton(model, data, measured, p0, idx, w, max_iter, tol)
        else:
            e, k, bad = lin.solve(model, data, measured, max_iter, tol)
            if bad.any():
                e[bad], k2, _ = _gauss_newton(model, data, measured[bad], p0, idx, w, max_iter, tol)
                k = max(k, k2)
        est[lo:lo + n] = e
        it = max(it, k)
    ok = np.all(np.isfinite(est), axis=1)
    est_ok = est[ok]
    sig = est_ok.std(axis=0, ddof=1)
    corr = np.corrcoef(est_ok, rowvar=False) if est_ok.shape[0] > 2 else np.eye(len(idx))
    return MonteCarloResult(
        names=tuple(model.param_names[i] for i in idx), estimates=_ro(est), sigma=_ro(sig),
        bias=_ro(est_ok.mean(axis=0) - p_exact[idx]), correlation=_ro(np.atleast_2d(corr)),
        iterations=it, n_failed=int((~ok).sum()),
    )


def _draw(model, data, p_exact, n_sets, rng, sigma_joints, point_ids, sigma_point) -> np.ndarray:
    """``n_sets`` measured values like ``data.measured`` (leading axis: the set) drawn from the
    input distributions of :func:`monte_carlo`."""
    q_act = (np.broadcast_to(data.joints, (n_sets,) + data.joints.shape) if sigma_joints is None else
             data.joints + rng.standard_normal((n_sets,) + data.joints.shape) * np.asarray(sigma_joints))
    if data.kind == "distance":
        # What is measured are points: perturb them (instrument, body geometry), then form the distances.
        pts = add_body_error(data, forward(model, q_act, p_exact, setup=False)[..., :3, 3], rng)
        pts = pts + rng.standard_normal(pts.shape) * data.points_sigma()
        if point_ids is not None and sigma_point is not None:
            pts = _perturb_points("position", pts, np.asarray(point_ids), np.asarray(sigma_point), rng)
        pr = data.distance_pairs()
        return np.linalg.norm(pts[..., pr[:, 0], :] - pts[..., pr[:, 1], :], axis=-1)
    exact = (np.broadcast_to(model_outputs(model, data, p_exact), (n_sets,) + data.measured.shape)
             if sigma_joints is None else _outputs_at(model, data, p_exact, q_act))
    measured = add_noise(data, add_body_error(data, exact, rng), rng)
    if point_ids is not None and sigma_point is not None:
        measured = _perturb_points(data.kind, measured, np.asarray(point_ids), np.asarray(sigma_point), rng)
    return measured


def _gauss_newton(model, data, measured, p0, idx, w, max_iter, tol):
    """Gauss–Newton of every set of ``measured`` from ``p0``, each with its own analytic Jacobian:
    the chosen parameters' estimates ``(n_sets, m)``, the iterations, the final parameters."""
    P = np.broadcast_to(p0, (measured.shape[0], p0.size)).copy()
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007 - the count is reported after the loop
        r, J = residuals_and_jacobian(model, data, P, joints=data.joints, measured=measured)
        J = J[..., idx] * w[:, None]
        r = r * w
        scale = np.linalg.norm(J, axis=-2, keepdims=True)
        Js = J / scale
        JT = np.swapaxes(Js, -1, -2)
        dx = -np.linalg.solve(JT @ Js, (JT @ r[..., None]))[..., 0] / scale[..., 0, :]
        P[:, idx] += dx
        if np.max(np.abs(dx)) < tol:
            break
    return P[:, idx], it, P


@dataclass(frozen=True)
class _Expansion:
    """The weighted Jacobian of the chosen parameters about the noise-free solution ``p_ref``:
    ``J0`` ``(rows, m)``, its derivative ``H`` ``(rows, m, m)`` (H[i, j, k] = ∂J0[i, j]/∂p_k),
    and the column-scaled normal matrix's inverse the steps use. ``Hf`` ``(rows, len(pairs))``
    keeps the columns j·m + k of H flattened that are not all zero, ``pairs`` their indices."""

    p_ref: np.ndarray
    idx: np.ndarray
    w: np.ndarray
    J0: np.ndarray
    Hf: np.ndarray
    pairs: np.ndarray
    scale: np.ndarray
    normal_inv: np.ndarray
    step_tol: np.ndarray

    @classmethod
    def about(cls, model, data, p_exact, p0, idx, w, max_iter, tol) -> "_Expansion":
        exact = model_outputs(model, data, p_exact)[None]
        _, _, P = _gauss_newton(model, data, exact, p0, idx, w, max_iter, tol)
        p_ref = P[0]
        J0 = residuals_and_jacobian(model, data, p_ref)[1][:, idx]
        # steps that move the model's outputs by ~1 µm: central differences far above round-off
        # (ε·|J|/h ~ 1e-10 of H) and far below the third derivative's reach (h² ~ 1e-12 relative)
        h = 1e-3 / np.maximum(np.max(np.abs(J0), axis=0), 1e-12)
        Pd = np.broadcast_to(p_ref, (2, idx.size, p_ref.size)).copy()
        ar = np.arange(idx.size)
        Pd[0, ar, idx] += h
        Pd[1, ar, idx] -= h
        Jd = residuals_and_jacobian(model, data, Pd)[1][..., idx]  # (2, m, rows, m)
        H = np.moveaxis((Jd[0] - Jd[1]) / (2 * h[:, None, None]), 0, -1)  # (rows, m, m)
        J0w = J0 * w[:, None]
        scale = np.linalg.norm(J0w, axis=0)
        Js = J0w / scale
        normal_inv = np.linalg.inv(Js.T @ Js)
        # converged when every step is below 1e-5 of the parameter's noise σ (or ``tol``): what is
        # left, shrinking ~1e-3 per step (the pose residual's rotation vs. J), is then ~1e-8 σ
        step_tol = np.maximum(tol, 1e-5 * np.sqrt(np.diag(normal_inv)) / scale)
        Hw = (H * w[:, None, None]).reshape(H.shape[0], -1)  # (rows, m·m)
        # only the (j, k) pairs where the Jacobian changes at all: a length's column does not turn
        # with another length (about half of the SR 800's 400 pairs are exactly zero), and the
        # products with H are the solve's largest after the forward kinematics
        pairs = np.flatnonzero(np.any(Hw != 0.0, axis=0))
        return cls(p_ref, idx, w, J0w, np.ascontiguousarray(Hw[:, pairs]), pairs, scale, normal_inv, step_tol)

    def solve(self, model, data, measured, max_iter, tol):
        """Estimates ``(n_sets, m)``, the iterations, and the sets that did not converge.

        Two forward kinematics per set at most: the residuals at p̄ (one parameter set for all)
        give the linear step d₁; the residuals r₁ at d₁ (every set's own) are then carried to the
        later iterates d by the expansion itself, r(d) = r₁ + J((d₁ + d)/2)·(d − d₁) (the
        midpoint rule, exact where J is linear in d, as J0 + H·d is): the steps after the first
        are ~1e-4 of the noise (|d − d₁| ≤ 1e-3 σ), so what that leaves out, the change of H over
        d − d₁, is ~1e-10 of σ, far below the step tolerance of 1e-5 σ. A third forward per set
        and iteration (what every iteration cost before) moved no figure of ``station study``.
        """
        n = measured.shape[0]
        P = np.broadcast_to(self.p_ref, (n, self.p_ref.size)).copy()
        # the residuals at p̄ are those of one parameter set: one forward for all sets
        r0 = residuals_and_jacobian(model, data, P[0], joints=data.joints, measured=measured,
                                    with_jacobian=False)[0] * self.w
        d1 = self._step(r0 @ self.J0)  # d = 0 at p̄: J = J0
        P[:, self.idx] += d1
        step = np.max(np.abs(d1) / self.step_tol, axis=1)
        it = 1
        if max_iter > 1:
            r1 = residuals_and_jacobian(model, data, P, joints=data.joints, measured=measured,
                                        with_jacobian=False)[0] * self.w
            d = d1.copy()
            for it in range(2, max_iter + 1):  # noqa: B007 - the count is reported after the loop
                r = r1 if it == 2 else r1 + self._along(d - d1, 0.5 * (d + d1))
                dx = self._step(r @ self.J0 + self._along_t(r, d))
                d += dx
                step = np.max(np.abs(dx) / self.step_tol, axis=1)
                if np.max(step) < 1.0:
                    break
            P[:, self.idx] = self.p_ref[self.idx] + d
        bad = ~(step < 1.0) | ~np.all(np.isfinite(P[:, self.idx]), axis=1)
        return P[:, self.idx], it, bad

    def _step(self, g: np.ndarray) -> np.ndarray:
        """The quasi-Newton step −(J0ᵀJ0)⁻¹ g of every set, column-scaled."""
        return -((g / self.scale) @ self.normal_inv) / self.scale

    def _along(self, delta: np.ndarray, at: np.ndarray) -> np.ndarray:
        """(J0 + H·at)·delta ``(n, rows)``: the residuals' change over ``delta`` ``(n, m)``."""
        j, k = np.divmod(self.pairs, delta.shape[1])
        return delta @ self.J0.T + (delta[:, j] * at[:, k]) @ self.Hf.T

    def _along_t(self, r: np.ndarray, d: np.ndarray) -> np.ndarray:
        """(H·d)ᵀ r ``(n, m)``: the Jacobian's change at ``d`` applied to the residuals ``r``
        (Σ_ik H[i, j, k] d_k r_i)."""
        m = d.shape[1]
        j, k = np.divmod(self.pairs, m)
        # Σ_k (rᵀH)[j, k] d_k: the pairs' products summed into their j by a (pairs, m) one-hot product
        return ((r @ self.Hf) * d[:, k]) @ (j[:, None] == np.arange(m)).astype(float)


def pair_units(model: RobotModel, data: MeasurementSet, params) -> np.ndarray | None:
    """``(k, 3)`` unit vectors p_i − p_j of a distance set's pairs at ``params`` (None for
    other kinds): what the body variance of a distance needs."""
    if data.kind != "distance":
        return None
    pts = forward(model, data.joints, params, setup=False)[:, :3, 3]
    pr = data.distance_pairs()
    diff = pts[pr[:, 0]] - pts[pr[:, 1]]
    return diff / np.linalg.norm(diff, axis=1)[:, None]


def _outputs_at(model: RobotModel, data: MeasurementSet, p_exact: np.ndarray, q_act: np.ndarray) -> np.ndarray:
    """Exact outputs of the robot ``p_exact`` ``(P,)`` at the actual joints ``(n_sets, n, g)``:
    poses ``(n_sets, n, 4, 4)``, positions ``(n_sets, n, 3)`` or distances ``(n_sets, k)``."""
    T = forward(model, q_act, p_exact, setup=data.uses_setup)
    if data.kind == "pose":
        return T
    p = T[..., :3, 3]
    if data.kind == "position":
        return p
    pairs = data.distance_pairs()
    return np.linalg.norm(p[..., pairs[:, 0], :] - p[..., pairs[:, 1], :], axis=-1)


def _perturb_points(kind, measured, point_ids, sigma_point, rng):
    n_sets = measured.shape[0]
    ids, inv = np.unique(point_ids, return_inverse=True)
    e = rng.standard_normal((n_sets, len(ids), 6)) * sigma_point
    e = e[:, inv]
    out = np.array(measured)
    if kind == "pose":
        out[..., :3, 3] += e[..., :3]
        out[..., :3, :3] = rotation_exp(e[..., 3:]) @ out[..., :3, :3]
    else:
        out += e[..., :3]
    return out
