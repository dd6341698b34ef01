"""The standard uncertainty of one pose's ISO 9283 AP and RP (issue 41: the certificate states
them with their uncertainty). Pure functions; inputs in mm.

Per pose, from what the run measured (GUM, JCGM 100:2008, and its Supplement 1, JCGM 101:2008):

* **AP** ``= |x̄ − c|``. Each axis of the barycentre x̄ has ``u²(x̄_i) = s_i²/n + u_c²``: the
  cycles' own scatter (Type A, GUM 4.2: ``s_i`` the experimental standard deviation of the n
  attained positions along axis i; it holds the robot's repeatability and the probe's noise
  together), and the target's standard uncertainty ``u_c`` per axis (Type B: the CMM's σ of the
  body point, which every cycle shares and no averaging reduces). With one cycle there is no
  scatter to take: ``s_i`` is the configured σ of one reading (``[identification]
  sigma_position_um``). Then ``u²(AP) = Σ (AP_i/AP)² u²(x̄_i)`` (GUM 5.1.2); at AP = 0 the
  derivative is undefined and the root mean square of the ``u(x̄_i)`` is taken.
* **RP** ``= l̄ + 3 S_l`` (n ≥ 2) is no smooth function of a few means: the first-order formula
  (``u(l̄) = S_l/√n``, ``u(S_l) ≈ S_l/√(2(n − 1))``) assumes normal distances and understated
  the spread by 15 % for isotropic scatter and by half for anisotropic scatter (σ 1 : 0.5 : 2)
  in a simulation of 4000 poses of 3 to 30 cycles. RP's u is therefore propagated by Monte Carlo (GUM
  Supplement 1, JCGM 101:2008, 7): the cycles as a normal distribution with the pose's own sample
  covariance, :data:`DRAWS` sets of n cycles drawn (seeded: the same cycles give the same u), RP
  of each, u their standard deviation. With few cycles the sample covariance is uncertain itself
  and u comes out larger than the true spread (up to 1.6× at n = 3 in the simulation), never
  smaller by more than a few per cent: ISO 9283 asks for 30 cycles. The target does not enter RP
  (a shift of all cycles leaves it as it is).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from station.errors import ConfigError

__all__ = ["DRAWS", "PoseUncertainty", "iso9283_uncertainty"]


@dataclass(frozen=True)
class PoseUncertainty:
    """Standard uncertainties [mm] of AP and RP; ``u_rp`` None with one cycle (no RP)."""

    u_ap: float
    u_rp: float | None


def iso9283_uncertainty(errors, u_reading: float, u_target: float) -> PoseUncertainty:
    """``errors`` ``(n, 3)`` attained minus commanded positions [mm] of one pose's cycles;
    ``u_reading`` the σ of one reading per axis [mm] (used with one cycle only); ``u_target``
    the σ of the target position per axis [mm]."""
    e = np.asarray(errors, dtype=float)
    if e.ndim != 2 or e.shape[1] != 3 or not len(e):
        raise ConfigError(f"position errors must have shape (n_cycles ≥ 1, 3), got {e.shape}")
    if not np.all(np.isfinite(e)) or not (np.isfinite(u_reading) and np.isfinite(u_target)) \
            or u_reading < 0 or u_target < 0:
        raise ConfigError("position errors and standard uncertainties must be finite, the uncertainties ≥ 0")
    n = len(e)
    ap = e.mean(axis=0)
    s = e.std(axis=0, ddof=1) if n >= 2 else np.full(3, u_reading)
    u_axis2 = s**2 / n + u_target**2
    norm = float(np.linalg.norm(ap))
    u_ap = float(np.sqrt(np.sum((ap / norm) ** 2 * u_axis2))) if norm > 0 else float(np.sqrt(u_axis2.mean()))
    if n < 2:
        return PoseUncertainty(u_ap, None)
    return PoseUncertainty(u_ap, _u_rp(e))


#: Monte Carlo draws for RP's uncertainty (its relative standard error is about 1/√(2·DRAWS): 1.6 %)
DRAWS = 2000
_SEED = 9283


def _u_rp(e: np.ndarray) -> float:
    """RP's standard uncertainty [mm]: the spread of RP over sets of n cycles drawn from the normal
    distribution with the cycles' sample covariance (any rank: two cycles span a line)."""
    n = len(e)
    w, V = np.linalg.eigh(np.cov(e.T))
    root = V * np.sqrt(np.clip(w, 0.0, None))  # root @ root.T is the covariance
    X = np.random.default_rng(_SEED).standard_normal((DRAWS, n, 3)) @ root.T
    d = np.linalg.norm(X - X.mean(axis=1, keepdims=True), axis=2)
    rp = d.mean(axis=1) + 3.0 * d.std(axis=1, ddof=1)
    return float(rp.std(ddof=1))
