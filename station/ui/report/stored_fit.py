"""The report's identification figures are the run's stored ones (issue 42: no view computes a
figure another view shows).

The report identifies again from the stored measurements for what the run does not store (the
fit's Jacobian structure, the registration, the notes on the base frame), but the figures people
compare across views, each parameter's value and σ, their covariance and correlation, the residual
rows, the outliers and the normalised RMS, are those the run identified, streamed (``Identified``)
and stored (result ``identification``, written from that event). A run from before they were
stored (a run database written by hand) keeps the recomputed figures; one whose stored record does
not match the parameters and rows identified again keeps them too, and the report says so.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import numpy as np

from station.core.identification.identify import IdentificationResult

__all__ = ["with_stored_figures"]


def with_stored_figures(res: IdentificationResult, stored: Any, notes: list[str]) -> IdentificationResult:
    """``res`` with the stored identification's figures (see the module); ``res`` as it is where
    ``stored`` is missing, and with a note in ``notes`` where it does not match."""
    if not isinstance(stored, Mapping):  # a run database written by hand (a test's): the figures identified again
        return res
    try:
        params = np.asarray(stored["params"], dtype=float)
        sigma = np.asarray(stored["sigma"], dtype=float)
        cov = np.asarray(stored["covariance"], dtype=float)
        residuals = np.asarray(stored["residuals"], dtype=float)
        chosen = tuple(str(n) for n in stored["chosen"])
        outliers = tuple(int(i) for i in stored["outliers"])
        rms = float(stored["rms_normalized"])
    except (KeyError, TypeError, ValueError):
        chosen = None
    p = len(res.chosen)
    if (chosen is None or chosen != tuple(res.chosen) or params.shape != res.params.shape or sigma.shape != (p,)
            or cov.shape != (p, p) or residuals.shape != res.residuals.shape):
        notes.append("the run's stored identification does not match the parameters and measurements identified "
                     "again from its measurements: the figures shown are the recomputed ones")
        return res
    # (the report's correlation is computed from this covariance: correlation_from_covariance)
    unc = dataclasses.replace(res.uncertainty, sigma=sigma, covariance=cov)
    return dataclasses.replace(res, params=params, residuals=residuals, outliers=outliers, rms_normalized=rms,
                               uncertainty=unc)
