"""Joint configurations spread over the workspace, for studies and identifiability checks."""

from __future__ import annotations

import numpy as np

from station.core.kinematics.model import RobotModel


def spread_joints(model: RobotModel, n: int, rng: np.random.Generator, planar: bool = False,
                  margin: float = 0.05) -> np.ndarray:
    """``(n, g)`` joint values drawn uniformly inside the limits (shrunk by ``margin`` of the
    range at each end). ``planar`` fixes every prismatic joint at mid-range, so that all tool
    positions of a SCARA lie in one plane normal to its z axis."""
    lim = model.joint_limits
    span = lim[:, 1] - lim[:, 0]
    lo, hi = lim[:, 0] + margin * span, lim[:, 1] - margin * span
    q = rng.uniform(lo, hi, size=(n, model.n_joints))
    if planar:
        for j, kind in enumerate(model.joint_types):
            if kind == "prismatic":
                q[:, j] = 0.5 * (lo[j] + hi[j])
    return q
