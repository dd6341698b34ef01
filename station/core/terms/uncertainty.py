"""Monte Carlo study of the geometry and the error terms beyond geometry together (issue 30): the
scatter of their estimates over synthetic data sets, for the σ-versus-scatter honesty check of
:class:`station.core.terms.fit.TermFit`'s linear σ.

Like :func:`station.core.measurement.uncertainty.monte_carlo`: ``n_sets`` data sets of the robot ``true_params``
with the terms ``x_true`` of ``basis`` (built at the data's joints), each with fresh measurement
noise of the data's σ, all solved at once by Gauss–Newton from the exact values. Pose and position data.
mm and rad inside.
"""

from __future__ import annotations

import numpy as np

from station.core.kinematics.forward import forward, forward_with_jacobian, joint_jacobian
from station.core.kinematics.model import RobotModel
from station.core.kinematics.transforms import pose_error
from station.core.measurement.measurements import MeasurementSet, add_noise
from station.core.measurement.uncertainty import MonteCarloResult
from station.core.terms.error_model import TermBasis
from station.errors import ConfigError

__all__ = ["monte_carlo_terms"]


def _outputs(model: RobotModel, data: MeasurementSet, q: np.ndarray, p: np.ndarray, basis: TermBasis,
             x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World←tool ``(..., n, 4, 4)`` (point moved by D·x), geometric Jacobian ``(..., n, 6, P)`` and
    the terms' ``(..., n, 6, k)`` at joints ``q`` ``(..., n, g)`` (already moved by B·x)."""
    fk = forward_with_jacobian(model, q, p, setup=True)
    Jq = joint_jacobian(model, q, p, setup=True).J
    Jx = np.einsum("...nrg,ngk->...nrk", Jq, basis.B)
    Jx[..., :3, :] += basis.D
    T = np.array(fk.T)
    T[..., :3, 3] += np.einsum("nck,...k->...nc", basis.D, x)
    return T, fk.J, Jx


def monte_carlo_terms(model: RobotModel, data: MeasurementSet, true_params, chosen_index, basis: TermBasis,
                      x_true, n_sets: int, rng: np.random.Generator, max_iter: int = 12,
                      tol: float = 1e-12) -> MonteCarloResult:
    """Estimates of the geometric parameters ``chosen_index`` and the terms of ``basis`` over
    ``n_sets`` noisy copies of ``data`` (see the module). ``names``: the geometric parameters'
    then the terms'."""
    if data.kind == "distance":
        raise ConfigError("the error terms' Monte Carlo study needs pose or position data")
    idx = np.asarray(chosen_index, dtype=int)
    p_exact = np.asarray(true_params, dtype=float)
    x_true = np.asarray(x_true, dtype=float)
    m, k = len(idx), basis.size
    q_true = data.joints + basis.joint_delta(x_true)
    T_true = np.array(forward(model, q_true, p_exact))
    T_true[:, :3, 3] += basis.point_delta(x_true)
    exact = T_true if data.kind == "pose" else T_true[:, :3, 3]
    measured = add_noise(data, np.broadcast_to(exact, (n_sets,) + exact.shape), rng)
    w = 1.0 / data.fit_sigma()
    P = np.broadcast_to(p_exact, (n_sets, p_exact.size)).copy()
    X = np.broadcast_to(x_true, (n_sets, k)).copy()
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007 - the count is reported after the loop
        q = data.joints + np.einsum("ngk,sk->sng", basis.B, X)
        T, Jg, Jx = _outputs(model, data, q, P, basis, X)
        J = np.concatenate([Jg[..., idx], Jx], axis=-1)
        if data.kind == "pose":
            r = pose_error(T, measured).reshape(n_sets, -1)
            J = J.reshape(n_sets, -1, m + k)
        else:
            r = (T[..., :3, 3] - measured).reshape(n_sets, -1)
            J = J[..., :3, :].reshape(n_sets, -1, m + k)
        J = J * w[:, None]
        r = r * w
        scale = np.linalg.norm(J, axis=-2, keepdims=True)
        Js = J / scale
        JT = np.swapaxes(Js, -1, -2)
        d = -np.linalg.solve(JT @ Js, JT @ r[..., None])[..., 0] / scale[..., 0, :]
        P[:, idx] += d[:, :m]
        X += d[:, m:]
        if np.max(np.abs(d)) < tol:
            break
    est = np.concatenate([P[:, idx], X], axis=1)
    ok = np.all(np.isfinite(est), axis=1)
    e = est[ok]
    exact_values = np.concatenate([p_exact[idx], x_true])
    corr = np.corrcoef(e, rowvar=False) if e.shape[0] > 2 else np.eye(m + k)
    ro = [np.array(a) for a in (est, e.std(axis=0, ddof=1), e.mean(axis=0) - exact_values, np.atleast_2d(corr))]
    for a in ro:
        a.setflags(write=False)
    return MonteCarloResult(names=tuple(model.param_names[i] for i in idx) + basis.names, estimates=ro[0],
                            sigma=ro[1], bias=ro[2], correlation=ro[3], iterations=it, n_failed=int((~ok).sum()))
