"""Plausibility of the soft limits a robot program publishes (info page 0): what tells a wrong
word order or a broken program from real limits. Re-exported by :mod:`drivers.controller_map`.
Nothing in here knows about the station."""

from __future__ import annotations

from typing import Sequence

import numpy as np

__all__ = ["PLAUSIBLE_LIMIT_MAX", "PLAUSIBLE_LIMIT_MIN", "implausible_limits"]

#: Largest magnitude a plausible soft limit has (mm or rad); the smallest non-zero one.
PLAUSIBLE_LIMIT_MAX = 1e5
PLAUSIBLE_LIMIT_MIN = 1e-6


def implausible_limits(soft_limits: Sequence[float] | np.ndarray, n_joints: int) -> str | None:
    """Why the decoded ``soft_limits`` (lower_1, upper_1, ...) cannot be a robot's soft limits,
    or None if they can: every value finite, zero or of magnitude within
    [1e-6, 1e5] (mm or rad), and lower < upper for each of the ``n_joints`` joints."""
    v = np.asarray(soft_limits, dtype=float)[:2 * n_joints]
    if v.size != 2 * n_joints:
        return f"expected {2 * n_joints} values, got {v.size}"
    for i, x in enumerate(v):
        name = f"{'lower' if i % 2 == 0 else 'upper'}_{i // 2 + 1}"
        if not np.isfinite(x):
            return f"{name} = {x}"
        if x != 0.0 and not PLAUSIBLE_LIMIT_MIN <= abs(x) <= PLAUSIBLE_LIMIT_MAX:
            return f"{name} = {x:.6g}"
    for j in range(n_joints):
        if not v[2 * j] < v[2 * j + 1]:
            return f"joint {j + 1}: lower {v[2 * j]:.6g} is not below upper {v[2 * j + 1]:.6g}"
    return None
