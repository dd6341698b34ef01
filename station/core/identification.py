"""Parameter identification: weighted least squares on a minimal parameter set (brief §4).

Pose objective (eq. 7.3): Σ ((model − measured)/σ)² over x, y, z, rx, ry, rz of every pose.
Position objective: the same on x, y, z only. Distance objective (7.6): plain sum of squares of
distance residuals (one σ for all, so the weighting is only a scale).

Solved by Levenberg–Marquardt (scipy ``least_squares``, MINPACK) on the minimal set chosen by
:mod:`station.core.identifiability`, with the analytic Jacobian. Everything reported is recomputed at
the returned parameters (MINPACK does not always evaluate last at its result).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from station.core.identifiability import Identifiability, analyze, structural_params
from station.core.measurements import MeasurementSet, residuals_and_jacobian
from station.core.model import RobotModel
from station.core.uncertainty import LinearUncertainty, linear_uncertainty
from station.errors import IdentificationError

OUTLIER_SIGMAS = 4.0


@dataclass(frozen=True)
class IdentificationResult:
    """An identified model and how well it is known.

    ``params``: ``(n_params,)`` full parameter vector [mm, rad] (held parameters at their
    start values). ``chosen``: names of the identified parameters, ``estimates`` their values.
    ``residuals``: ``(n_items, rows_per_item)`` model − measured at the solution [mm, rad].
    ``normalized``: per-measurement RMS of residual/σ. ``outliers``: indices of measurements
    whose normalized residual exceeds ``OUTLIER_SIGMAS`` (robustly scaled).
    """

    model: RobotModel
    kind: str
    params: np.ndarray
    start: np.ndarray
    chosen: tuple[str, ...]
    chosen_index: np.ndarray
    residuals: np.ndarray
    normalized: np.ndarray
    rms_normalized: float
    outliers: tuple[int, ...]
    iterations: int
    converged: bool
    message: str
    identifiability: Identifiability
    uncertainty: LinearUncertainty

    @property
    def estimates(self) -> np.ndarray:
        return self.params[self.chosen_index]

    @property
    def identified_model(self) -> RobotModel:
        return self.model.with_params(self.params)

    def rms_position_mm(self) -> float:
        if self.kind == "distance":
            return float(np.sqrt(np.mean(self.residuals**2)))
        return float(np.sqrt(np.mean(np.sum(self.residuals[:, :3] ** 2, axis=1))))


def identify(model: RobotModel, data: MeasurementSet, start=None, prefer=None, fix=(), exclude=(),
             chosen=None, max_nfev: int = 200, max_rms_normalized: float = 1e3) -> IdentificationResult:
    """Identify ``model``'s parameters from ``data``.

    ``start``: start parameters (default nominal). ``prefer`` / ``fix`` / ``exclude``: minimal
    set preferences (default: the robot file's ``prefer`` list). ``chosen``: identify exactly
    these parameters instead (must be identifiable). Raises :class:`IdentificationError` on
    rank deficiency or divergence.
    """
    p0 = np.array(model.nominal if start is None else start, dtype=float)
    if p0.shape != (model.n_params,) or not np.all(np.isfinite(p0)):
        raise IdentificationError("start parameters must be a finite vector of the model's size")
    ident = analyze(model, data, structural_params(model, p0), prefer=model.prefer if prefer is None else prefer,
                    fix=fix, exclude=exclude, describe=False)
    if chosen is not None:
        idx = np.array(model.param_indices(chosen), dtype=int)
        J = residuals_and_jacobian(model, data, p0)[1][:, idx] / data.sigma[:, None]
        Js = J / np.maximum(np.linalg.norm(J, axis=0), 1e-300)
        s = np.linalg.svd(Js, compute_uv=False)
        if s[-1] <= 1e-9 * s[0]:
            raise IdentificationError(
                f"the parameters {list(chosen)} are not all identifiable from these "
                f"{data.kind} measurements (rank {int(np.sum(s > 1e-9 * s[0]))} of {len(idx)}); "
                f"run 'station analyze' to see a minimal set"
            )
    else:
        idx = ident.chosen_indices()
    n_rows = data.sigma.size
    if n_rows < len(idx):
        raise IdentificationError(
            f"{n_rows} residual rows cannot determine {len(idx)} parameters; measure more poses"
        )
    w = 1.0 / data.sigma

    def full(x):
        p = p0.copy()
        p[idx] = x
        return p

    def fun(x):
        r, _ = residuals_and_jacobian(model, data, full(x), with_jacobian=False)
        return r * w

    def jac(x):
        _, J = residuals_and_jacobian(model, data, full(x))
        return J[:, idx] * w[:, None]

    method = "lm" if n_rows >= len(idx) else "trf"
    sol = least_squares(fun, p0[idx], jac=jac, method=method, x_scale="jac", max_nfev=max_nfev,
                        xtol=1e-15, ftol=1e-15, gtol=1e-15)
    p = full(sol.x)
    r, J = residuals_and_jacobian(model, data, p)  # recomputed at the result, on purpose
    Jw = J[:, idx] * w[:, None]
    unc = linear_uncertainty(Jw, tuple(model.param_names[i] for i in idx))
    rn = (r * w).reshape(data.n_items, data.rows_per_item)
    per_item = np.sqrt(np.mean(rn**2, axis=1))
    rms = float(np.sqrt(np.mean(rn**2)))
    if not np.all(np.isfinite(p)) or rms > max_rms_normalized:
        raise IdentificationError(
            f"identification diverged (normalised RMS residual {rms:.3g} after {sol.nfev} "
            f"evaluations): the start model is too far from the robot or the data are wrong. "
            f"Check units (mm, deg/rad in the file header), joint order and sign conventions"
        )
    if unc.rank < len(idx):
        raise IdentificationError(
            f"rank deficient at the solution ({unc.rank} of {len(idx)} parameters determined); "
            f"spread the poses over the workspace or identify fewer parameters"
        )
    med = np.median(per_item)
    mad = 1.4826 * np.median(np.abs(per_item - med)) or 1.0
    outliers = tuple(int(i) for i in np.nonzero((per_item - med) / mad > OUTLIER_SIGMAS)[0]
                     if per_item[i] > 3.0)
    converged = bool(sol.status > 0)
    return IdentificationResult(
        model=model, kind=data.kind, params=p, start=p0,
        chosen=tuple(model.param_names[i] for i in idx), chosen_index=idx,
        residuals=r.reshape(data.n_items, data.rows_per_item), normalized=per_item,
        rms_normalized=rms, outliers=outliers, iterations=int(sol.nfev), converged=converged,
        message=str(sol.message), identifiability=ident, uncertainty=unc,
    )
