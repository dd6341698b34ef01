"""The geometric model with error terms beyond geometry, fitted together (issue 30).

:func:`fit_terms` starts from a geometric fit (:func:`station.core.identification.identify`: its
registration, minimal parameter set and solution) and fits the same geometric parameters and the
terms of a :class:`~station.core.terms.error_model.TermBasis` together by Levenberg–Marquardt (MINPACK,
as the geometric fit), weighted by the data's σ. The joints the robot stands at are ``q + B·x``
(compliance, harmonics, backlash), the measured point moves by ``D·x`` (drift). The geometric fit's
own code is not touched: without terms nothing here runs.

A term that the data cannot tell apart from the geometry (a harmonic of a wrist joint whose
motion the measured point does not see, a drift no different from the set-up) is left out before
the fit and listed in ``dropped``; the rest are reported per family with their rank, the condition
number the family brings to the fit and the strongest correlations of its parameters
(:class:`TermIdentifiability`). σ are the linear propagation of the measurement σ (as the
geometric fit's). Pose and position data (distances: not yet). Pure numerics, mm and rad inside.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from station.core.blas_threads import single_blas_thread
from station.core.identification.fit_kernel import FixedJointsChain, minpack_lm
from station.core.identification.identify import IdentificationResult
from station.core.kinematics.forward import _cross
from station.core.kinematics.model import RobotModel
from station.core.kinematics.transforms import pose_error, pose_to_matrix
from station.core.measurement.measurements import MeasurementSet
from station.core.measurement.uncertainty import LinearUncertainty, linear_uncertainty, pair_units
from station.core.terms.error_model import TermBasis, family_of
from station.core.units import ARCSEC, UM
from station.errors import ConfigError, IdentificationError

__all__ = ["TermFit", "TermIdentifiability", "fit_terms", "TermEvaluator"]

#: a term whose σ-scaled Jacobian column keeps less than this of its length once the geometry and
#: the terms before it are projected out cannot be told apart from them: its σ would be 10⁴ times
#: what the column alone gives (a SCARA's constant thrust on its quill is its zero offset, to 10⁻¹³)
DEPENDENT_TOL = 1e-4


@dataclass(frozen=True)
class TermIdentifiability:
    """One family's identifiability at the data: ``rank`` of its ``size`` parameters kept,
    ``condition``: of the σ-scaled Jacobian (unit columns) of the geometry and this family,
    ``condition_geometric``: the geometry's alone, ``correlations``: per kept parameter, the
    parameter it correlates with most strongly and the correlation."""

    family: str
    size: int
    rank: int
    condition: float
    condition_geometric: float
    correlations: tuple[tuple[str, str, float], ...]

    def to_dict(self) -> dict:
        return {"family": self.family, "parameters": self.size, "rank": self.rank,
                "condition": self.condition, "condition_geometric": self.condition_geometric,
                "strongest_correlations": [{"parameter": a, "with": b, "correlation": c}
                                           for a, b, c in self.correlations]}


@dataclass(frozen=True)
class TermFit:
    """Geometry and extra terms fitted together.

    ``params``: ``(n_params,)`` geometry [mm, rad] at the solution; ``chosen_index``: the geometric
    parameters fitted (the geometric fit's minimal set). ``basis``: the kept terms at the data's
    rows; ``values``/``sigma``: ``(k,)`` their values and σ in ``basis.units``. ``dropped``: terms
    left out as not identifiable beside the geometry. ``residuals``: ``(n_items, rows_per_item)``
    model − measured [mm, rad]. ``jacobian_w``/``residuals_w``: the σ-weighted Jacobian
    ``(n_rows, m + k)`` and residuals at the solution (cross-validation uses them); ``weights``:
    ``(n_rows,)`` 1/σ."""

    families: tuple[str, ...]
    model: RobotModel
    kind: str
    params: np.ndarray
    chosen_index: np.ndarray
    basis: TermBasis
    values: np.ndarray
    sigma: np.ndarray
    dropped: tuple[str, ...]
    residuals: np.ndarray
    rms_normalized: float
    uncertainty: LinearUncertainty
    identifiability: tuple[TermIdentifiability, ...]
    jacobian_w: np.ndarray
    residuals_w: np.ndarray
    weights: np.ndarray
    iterations: int
    converged: bool

    @property
    def n_parameters(self) -> int:
        return len(self.chosen_index) + self.basis.size

    def rms_position_mm(self) -> float:
        return float(np.sqrt(np.mean(np.sum(self.residuals[:, :3] ** 2, axis=1))))

    def terms_dict(self) -> list[dict]:
        """Every kept term: name, family, unit, value and σ (JSON), and its physical size where
        people read it (issue 38): a compliance in µrad per N·m, an angle in arc seconds, and the
        largest joint turn [″] or point shift [µm] the term gives over these data, with its σ."""
        out = []
        for k, (n, u, v, s) in enumerate(zip(self.basis.names, self.basis.units, self.values, self.sigma)):
            t = {"name": n, "family": family_of(n), "unit": u, "value": float(v), "sigma": float(s)}
            if u.startswith("rad"):
                scale, shown = (ARCSEC, "″") if u == "rad" else (1e-6, "µ" + u)
                t["readable"] = {"value": float(v) / scale, "sigma": float(s) / scale, "unit": shown}
            reach = np.max(np.abs(self.basis.B[..., k]), initial=0.0)
            if reach > 0 and u.startswith("rad"):
                t["largest_joint_turn"] = {"value": reach * abs(float(v)) / ARCSEC, "sigma": reach * float(s) / ARCSEC,
                                           "unit": "″"}
            shift = np.max(np.abs(self.basis.D[..., k]), initial=0.0)
            if shift > 0:
                t["largest_shift"] = {"value": shift * abs(float(v)) / UM, "sigma": shift * float(s) / UM, "unit": "µm"}
            out.append(t)
        return out


def _joint_columns(model: RobotModel, P: np.ndarray, C: np.ndarray, tool: np.ndarray) -> np.ndarray:
    """``(n, 6, g)`` the geometric Jacobian by the joints from the chain's frames (``P``: the frame
    in front of every transform, ``C``: the transforms), as kinematics.joint_jacobian builds it."""
    cols = []
    for t, spec in enumerate(model.transforms):
        if spec.joint is None:
            continue
        F = P[t] @ C[t]
        axis = F[:, :3, 2]
        if spec.joint == "revolute":
            lever = tool - F[:, :3, 3]
            cols.append(np.concatenate([_cross(axis, lever), axis], axis=-1))
        else:
            cols.append(np.concatenate([axis, np.zeros_like(axis)], axis=-1))
    return np.stack(cols, axis=-1)


class TermEvaluator:
    """Residuals (model − measured) and Jacobian of the geometric parameters ``idx`` and the terms
    of ``basis`` together, at θ = (geometry[idx], x), the rest of the geometry held at ``p0``."""

    def __init__(self, model: RobotModel, data: MeasurementSet, basis: TermBasis, p0: np.ndarray,
                 idx: np.ndarray):
        if data.kind == "distance":
            raise ConfigError("error terms beyond geometry need pose or position data; distances are not "
                              "supported yet (fit --model geometric)")
        self.model, self.data, self.basis = model, data, basis
        self.p0 = np.array(p0, dtype=float)
        self.idx = np.asarray(idx, dtype=int)
        self.m = len(self.idx)
        self._key: bytes | None = None
        self._at: tuple[np.ndarray, np.ndarray] = (np.zeros(0), np.zeros((0, 0)))

    def split(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        p = self.p0.copy()
        p[self.idx] = theta[:self.m]
        return p, np.asarray(theta[self.m:], dtype=float)

    def _frames(self, theta: np.ndarray):
        p, x = self.split(theta)
        q = self.data.joints + self.basis.joint_delta(x) if self.basis.size else self.data.joints
        chain = FixedJointsChain(self.model, q, setup=True)
        T, P = chain.frames(p)
        return p, x, chain, T, P

    def _residuals(self, T: np.ndarray, x: np.ndarray) -> np.ndarray:
        if self.basis.size:
            T = T.copy()
            T[:, :3, 3] += self.basis.point_delta(x)
        if self.data.kind == "pose":
            return pose_error(T, self.data.measured).reshape(-1)
        return (T[:, :3, 3] - self.data.measured).reshape(-1)

    def residuals(self, theta: np.ndarray) -> np.ndarray:
        """Unweighted residuals ``(n_rows,)`` at θ (no Jacobian: what a solver's step asks)."""
        theta = np.asarray(theta, dtype=float)
        if theta.tobytes() == self._key:
            return self._at[0]
        _, x, _, T, _ = self._frames(theta)
        return self._residuals(T, x)

    def __call__(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Unweighted residuals ``(n_rows,)`` and Jacobian ``(n_rows, m + k)`` at θ."""
        theta = np.asarray(theta, dtype=float)
        key = theta.tobytes()
        if key == self._key:
            return self._at
        p, x, chain, T, P = self._frames(theta)
        basis = self.basis
        Jg = chain.jacobian(T, P, p)[:, :, self.idx]
        if basis.size:
            C = pose_to_matrix(p.reshape(-1, 6))
            Jx = np.einsum("nrg,ngk->nrk", _joint_columns(self.model, P, C, T[:, :3, 3]), basis.B)
            Jx[:, :3, :] += basis.D
            J = np.concatenate([Jg, Jx], axis=-1)
        else:
            J = Jg
        r = self._residuals(T, x)
        Jr = J.reshape(-1, J.shape[-1]) if self.data.kind == "pose" else J[:, :3, :].reshape(-1, J.shape[-1])
        self._key, self._at = key, (r, Jr)
        return r, Jr


class _Problem:
    """What MINPACK calls: weighted residuals and Jacobian."""

    def __init__(self, ev: TermEvaluator, w: np.ndarray):
        self.ev, self.w = ev, w

    def fun(self, theta: np.ndarray) -> np.ndarray:
        return self.ev.residuals(theta) * self.w

    def jac(self, theta: np.ndarray) -> np.ndarray:
        return self.ev(theta)[1] * self.w[:, None]


def _independent(Jw: np.ndarray, m: int) -> np.ndarray:
    """Indices (≥ m) of the term columns of ``Jw`` that keep more than DEPENDENT_TOL of their
    σ-scaled length beside the geometry (the first ``m`` columns) and the terms kept before them."""
    norms = np.maximum(np.linalg.norm(Jw, axis=0), 1e-300)
    Js = Jw / norms
    Q, _ = np.linalg.qr(Js[:, :m]) if m else (np.zeros((Js.shape[0], 0)), None)
    keep = []
    for c in range(m, Js.shape[1]):
        v = Js[:, c] - Q @ (Q.T @ Js[:, c])
        nv = float(np.linalg.norm(v))
        if nv > DEPENDENT_TOL and norms[c] > 1e-300:
            keep.append(c)
            Q = np.concatenate([Q, (v / nv)[:, None]], axis=1)
    return np.array(keep, dtype=int)


def _condition(Jw: np.ndarray) -> float:
    if Jw.shape[1] == 0:
        return 1.0
    Js = Jw / np.maximum(np.linalg.norm(Jw, axis=0), 1e-300)
    s = np.linalg.svd(Js, compute_uv=False)
    return float(s[0] / s[-1]) if s[-1] > 0 else float("inf")


def fit_terms(model: RobotModel, data: MeasurementSet, geometric: IdentificationResult, basis: TermBasis,
              max_nfev: int = 200, start: TermFit | None = None) -> TermFit:
    """Fit the geometric parameters of ``geometric`` (its minimal set, from its solution) and the
    terms of ``basis`` (built at ``data``'s rows) together; ``start``: a fit of some of these terms
    to start from (its geometry and its terms' values, the rest at 0). Raises
    :class:`IdentificationError` when the fit does not converge or diverges."""
    with single_blas_thread():
        return _fit_terms(model, data, geometric, basis, max_nfev, start)


def _fit_terms(model: RobotModel, data: MeasurementSet, geometric: IdentificationResult, basis: TermBasis,
               max_nfev: int, start: TermFit | None) -> TermFit:
    idx = np.asarray(geometric.chosen_index, dtype=int)
    m = len(idx)
    w = 1.0 / data.fit_sigma(pair_units(model, data, geometric.params) if data.has_body_sigma else None)
    ev0 = TermEvaluator(model, data, basis, geometric.params, idx)
    theta0 = np.concatenate([geometric.params[idx], np.zeros(basis.size)])
    _, J0 = ev0(theta0)
    Jw0 = J0 * w[:, None]
    keep = _independent(Jw0, m) - m
    dropped = tuple(n for i, n in enumerate(basis.names) if i not in set(keep.tolist()))
    basis = basis.select(keep)
    x0 = np.zeros(basis.size)
    p_start = geometric.params
    if start is not None and np.array_equal(start.chosen_index, idx):
        p_start = start.params
        known = dict(zip(start.basis.names, start.values))
        x0 = np.array([known.get(n, 0.0) for n in basis.names])
    theta0 = np.concatenate([p_start[idx], x0])
    ev = TermEvaluator(model, data, basis, geometric.params, idx)
    prob = _Problem(ev, w)
    if basis.size:
        sol = minpack_lm(prob, theta0, max_nfev)  # type: ignore[arg-type]  # fun/jac as FitProblem's
        theta, nfev, converged = sol.x, sol.nfev, sol.status > 0
    else:
        theta, nfev, converged = theta0, 0, geometric.converged
    if not converged:  # a candidate that did not converge is no model (selection skips it)
        raise IdentificationError(f"the fit with the error terms {', '.join(dict.fromkeys(map(family_of, basis.names)))} "
                                  f"did not converge in {nfev} evaluations; fit fewer terms or --model geometric")
    r, J = ev(theta)
    Jw, rw = J * w[:, None], r * w
    if not np.all(np.isfinite(rw)):
        raise IdentificationError("the fit with error terms diverged; fit --model geometric")
    p, x = ev.split(theta)
    names = tuple(model.param_names[i] for i in idx.tolist()) + basis.names
    unc = linear_uncertainty(Jw, names)
    if unc.rank < len(names):
        raise IdentificationError(f"the fit with error terms is rank deficient ({unc.rank} of {len(names)}); "
                                  f"fit fewer terms")
    ident = _term_identifiability(basis, Jw, m, names, unc, dropped)
    return TermFit(
        families=tuple(dict.fromkeys(family_of(n) for n in basis.names)), model=model, kind=data.kind, params=p,
        chosen_index=idx, basis=basis, values=x, sigma=np.asarray(unc.sigma[m:]), dropped=dropped,
        residuals=r.reshape(data.n_items, data.rows_per_item), rms_normalized=float(np.sqrt(np.mean(rw**2))),
        uncertainty=unc, identifiability=ident, jacobian_w=Jw, residuals_w=rw, weights=w,
        iterations=int(nfev), converged=bool(converged))


def _term_identifiability(basis: TermBasis, Jw: np.ndarray, m: int, names: tuple[str, ...],
                          unc: LinearUncertainty, dropped: tuple[str, ...]) -> tuple[TermIdentifiability, ...]:
    fams: dict[str, list[int]] = {}
    for i, n in enumerate(basis.names):
        fams.setdefault(family_of(n), []).append(i)
    for n in dropped:
        fams.setdefault(family_of(n), [])
    cond_geo = _condition(Jw[:, :m])
    corr = np.abs(np.nan_to_num(np.asarray(unc.correlation)) - np.eye(len(names)))
    out = []
    for fam, cols in fams.items():
        size = len(cols) + sum(family_of(n) == fam for n in dropped)
        cond = _condition(np.concatenate([Jw[:, :m], Jw[:, [m + c for c in cols]]], axis=1))
        strongest = []
        for c in cols:
            j = int(np.argmax(corr[m + c])) if len(names) > 1 else m + c
            strongest.append((names[m + c], names[j], float(unc.correlation[m + c, j])))
        out.append(TermIdentifiability(fam, size, len(cols), cond, cond_geo, tuple(strongest)))
    return tuple(out)
