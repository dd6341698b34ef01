"""When will a robot's drift cross its tolerance? The control-chart method of ILAC-G24 / OIML D 10
(2007), §"Control charts": the rechecks since the last calibration are plotted against time, a
straight trend line is fitted, and the date it reaches the tolerance, with its uncertainty, sets
the next check.

The fit is ordinary least squares of drift on time. The crossing's uncertainty is Fieller's
interval for the time at which the line's *mean* equals the tolerance (the inverse-regression
interval: the set of times where the line's two-sided 1 - alpha confidence band contains the
tolerance; Draper & Smith, "Applied Regression Analysis", 3rd ed., §3.2). Under the model (a
straight drift, independent normal scatter) it covers the true crossing with probability
1 - alpha. It is bounded only when the slope is significantly positive at that level; otherwise
there is no forecast (a flat or falling drift, or too much scatter to say).

Arrays in, a frozen result out; times in days (any origin), drift and tolerance in one unit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import stdtrit

#: two-sided confidence of the crossing interval (the band of ILAC-G24's control chart: 95 %)
CONFIDENCE = 0.95
#: rechecks needed for a trend with a scatter estimate (a line and at least one degree of freedom)
MIN_POINTS = 3


@dataclass(frozen=True)
class DriftForecast:
    """The fitted trend and when it crosses the tolerance, in the inputs' time unit (days)."""

    slope_per_day: float
    slope_sigma_per_day: float
    intercept: float  # the line at time 0 (the inputs' origin)
    scatter: float  # residual standard deviation, the drift's unit
    n: int
    crossing: float  # when the line reaches the tolerance (may be in the past)
    earliest: float  # the crossing's interval at CONFIDENCE: [earliest, latest]
    latest: float
    confidence: float = CONFIDENCE


# figures near the largest double overflow the sums of squares: the result is checked for it, so
# numpy's warning says nothing more
@np.errstate(over="ignore", invalid="ignore")
def forecast_crossing(t_days: np.ndarray, drift: np.ndarray, tolerance: float,
                      confidence: float = CONFIDENCE) -> DriftForecast | None:
    """The forecast of ``drift`` (measured at ``t_days``) reaching ``tolerance``; None with fewer
    than :data:`MIN_POINTS` points, all at one time, a non-finite input, a slope that is not
    significantly positive at ``confidence`` (the interval would be unbounded), or figures so large
    that the arithmetic overflows."""
    t = np.asarray(t_days, dtype=float)
    y = np.asarray(drift, dtype=float)
    n = int(t.size)
    if n < MIN_POINTS or t.shape != y.shape or not (np.all(np.isfinite(t)) and np.all(np.isfinite(y))) \
            or not math.isfinite(tolerance) or tolerance <= 0:
        return None
    tm, ym = float(t.mean()), float(y.mean())
    sxx = float(((t - tm) ** 2).sum())
    if sxx <= 1e-12 * max(1.0, tm * tm):
        return None
    b = float(((t - tm) * (y - ym)).sum()) / sxx
    resid = y - (ym + b * (t - tm))
    s2 = float((resid ** 2).sum()) / (n - 2)
    # Student's t quantile: scipy.special's, as stats.t.ppf computes it without its ~0.3 ms of
    # argument handling per call (200 robots on the fleet page)
    k = float(stdtrit(n - 2, 0.5 + confidence / 2.0))
    # Fieller: (c - b u)^2 = k^2 s^2 (1/n + u^2 / Sxx), u = t - tm, c = tolerance - ym
    c = tolerance - ym
    qa = b * b - k * k * s2 / sxx
    if not (math.isfinite(b) and math.isfinite(qa)) or b <= 0 or qa <= 0:
        return None  # the slope is not significantly positive (or its squares overflow): no bounded crossing
    qb = -2.0 * b * c
    qc = c * c - k * k * s2 / n
    disc = max(qb * qb - 4.0 * qa * qc, 0.0)
    u1, u2 = sorted(((-qb - math.sqrt(disc)) / (2 * qa), (-qb + math.sqrt(disc)) / (2 * qa)))
    if not all(math.isfinite(v) for v in (u1, u2, c / b, s2)):
        # figures near the largest double (a stored drift of 1e308 µm) overflow the sums of
        # squares: NaN, which no date can hold (issue 39: 'station fleet' ended in an internal error)
        return None
    return DriftForecast(slope_per_day=b, slope_sigma_per_day=math.sqrt(s2 / sxx), intercept=ym - b * tm,
                         scatter=math.sqrt(s2), n=n, crossing=tm + c / b, earliest=tm + u1, latest=tm + u2,
                         confidence=confidence)
