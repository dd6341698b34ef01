"""The robot's repeatability in the noise model, and the a-posteriori check of that model.

* :func:`sigma_from_rp` — the data sheet's pose repeatability RP (ISO 9283:1998 §7.2.2:
  ``RP = l̄ + 3 S_l``, l_j the distance of the j-th attained position from the barycentre) as the
  σ per axis of the tool point's scatter. Assumption: the scatter is isotropic Gaussian with σ per
  axis, so l is Maxwell-distributed: ``l̄ = 2 √(2/π) σ ≈ 1.596 σ``, ``S_l = √(3 − 8/π) σ ≈
  0.673 σ``, and ``RP = (2 √(2/π) + 3 √(3 − 8/π)) σ ≈ 3.617 σ`` (:data:`RP_PER_SIGMA`). A data
  sheet states the worst RP of its test poses, so the σ it gives is an upper figure where the arm
  repeats better elsewhere.
* :func:`with_repeatability` — that σ added in quadrature to the position rows of one measurement
  (x, y, z): the robot stands σ off where its joints say, independently at every visit, which the
  measurement sees as position noise (the orientation scatter of a repeatability is left out: RP
  states none, and a few µm at a wrist's lever are ~1″ against the head's several ″).
* :func:`variance_factor` — after a fit, the a-posteriori variance factor ``s0² = rᵀWr / (m − n)``
  (m rows, n parameters) against its a-priori value 1 (Koch, *Parameter Estimation and Hypothesis
  Testing in Linear Models*, §4.2/§4.4): where ``(m − n) s0²`` exceeds the χ²(m − n) quantile at
  :data:`CHI2_LEVEL`, the residuals say the noise is larger than the weights assume, and the
  parameters' σ are scaled by s0 (:func:`scaled`). Never scaled down: a fit whose residuals are
  smaller than assumed keeps the a-priori σ (a lucky draw must not make a claim smaller).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from station.core.measurement.uncertainty import LinearUncertainty

#: RP / σ per axis for an isotropic Gaussian scatter (ISO 9283 §7.2.2's l̄ + 3 S_l of a Maxwell
#: distribution): 2√(2/π) + 3√(3 − 8/π) ≈ 3.617
RP_PER_SIGMA = 2.0 * math.sqrt(2.0 / math.pi) + 3.0 * math.sqrt(3.0 - 8.0 / math.pi)
#: the χ² test's level: the residuals say "more noise than assumed" when (m − n) s0² exceeds the
#: χ²(m − n) quantile 1 − CHI2_LEVEL (a 5 % chance of scaling a fit whose noise is as assumed)
CHI2_LEVEL = 0.05


def sigma_from_rp(rp_mm: float | None) -> float:
    """σ per axis [mm] of the tool point's scatter whose ISO 9283 RP is ``rp_mm`` (0 for None)."""
    return 0.0 if rp_mm is None else float(rp_mm) / RP_PER_SIGMA


def with_repeatability(pose_sigma: np.ndarray, rp_mm: float | None) -> np.ndarray:
    """The six pose rows' σ (x, y, z [mm], rx, ry, rz [rad]) with the repeatability ``rp_mm``'s σ
    added in quadrature to x, y, z (see the module)."""
    s = np.array(pose_sigma, dtype=float)
    s[:3] = np.sqrt(s[:3] ** 2 + sigma_from_rp(rp_mm) ** 2)
    return s


@dataclass(frozen=True)
class VarianceFactor:
    """The a-posteriori check of one fit: ``s0`` = √(rᵀWr / dof), ``dof`` = rows − parameters,
    ``limit`` the s0 above which the χ² test at ``level`` says the noise is larger than assumed,
    ``scaled``: the parameters' σ were multiplied by ``s0``. ``p_value``: P(χ²(dof) ≥ dof·s0²)."""

    s0: float
    dof: int
    limit: float
    level: float
    p_value: float
    scaled: bool

    @property
    def factor(self) -> float:
        """What the reported σ were multiplied by (1 where not scaled)."""
        return self.s0 if self.scaled else 1.0

    def note(self) -> str:
        if self.scaled:
            return (f"a-posteriori variance factor s0 = {self.s0:.3g} (χ² test at {self.level:g}: above {self.limit:.3g} "
                    f"with {self.dof} degrees of freedom): the residuals say the noise is larger than the weights "
                    f"assume, so the σ are scaled by {self.s0:.3g}")
        return (f"a-posteriori variance factor s0 = {self.s0:.3g} (≤ {self.limit:.3g}, χ² test at {self.level:g}, "
                f"{self.dof} degrees of freedom): the residuals agree with the assumed noise; σ as propagated")

    def as_dict(self) -> dict:
        return {"s0": self.s0, "degrees_of_freedom": self.dof, "limit": self.limit, "level": self.level,
                "p_value": self.p_value, "scaled": self.scaled, "factor": self.factor,
                "unit": "1 (ratio of the residuals' scatter to the assumed σ)"}


def variance_factor(weighted_residuals: np.ndarray, n_params: int, level: float = CHI2_LEVEL) -> VarianceFactor | None:
    """The a-posteriori check of a fit with residuals already divided by their σ; None where the
    fit has no redundancy (rows ≤ parameters)."""
    # χ²(k)'s tail is the regularised upper incomplete gamma Q(k/2, x/2): scipy.special's kernels
    # cost microseconds where scipy.stats' distribution objects cost ~0.1 ms a call, beside a fit of 1.3 ms
    from scipy.special import gammaincc, gammainccinv

    r = np.asarray(weighted_residuals, dtype=float).ravel()
    dof = r.size - int(n_params)
    if dof < 1 or not np.all(np.isfinite(r)):
        return None
    q = float(r @ r)
    s0 = math.sqrt(q / dof)
    limit = math.sqrt(2.0 * float(gammainccinv(dof / 2.0, level)) / dof)
    return VarianceFactor(s0, dof, limit, level, float(gammaincc(dof / 2.0, q / 2.0)), s0 > limit)


def scaled(unc: LinearUncertainty, factor: float) -> LinearUncertainty:
    """``unc`` with its σ multiplied by ``factor`` (covariance by factor²; correlations unchanged)."""
    if factor == 1.0:
        return unc
    sig = np.array(unc.sigma) * factor
    cov = np.array(unc.covariance) * factor**2
    sig.setflags(write=False)
    cov.setflags(write=False)
    return dataclasses.replace(unc, sigma=sig, covariance=cov)
