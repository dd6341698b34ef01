"""The motion guard: the one place that decides whether a motion may be commanded.

Invariants (property-tested in ``tests/cell/test_safety.py``):

* the soft limits are finite and ordered (lower < upper) for every joint, or no guard exists;
* no joint target is commanded unless every joint is finite and inside the soft limits;
* a Cartesian target is checked on the joints the controller will actually command: its nominal
  inverse kinematics **plus the correction of the table that is active** (the controller's own
  rule, :func:`station.core.table.values.interpolate_table`), so a correction cannot push a joint
  over a limit unnoticed.

The plan checks every planned motion with the same guard before the first motion; the runner
checks each motion again right before commanding it.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from station.cell.limits.joint_text import joint_value
from station.core.table.values import CorrectionTableData, TableRangeError, interpolate_table
from station.errors import ConfigError, UnreachableError


class MotionGuard:
    """Soft limits ``(n_joints, 2)`` [rad | mm] and the correction table the controller applies
    to Cartesian moves (None while no table is active)."""

    def __init__(self, soft_limits: np.ndarray, *, elbows: Sequence[int] = (1, -1),
                 joint_types: Sequence[str] | None = None) -> None:
        lim = np.array(soft_limits, dtype=float)
        if lim.ndim != 2 or lim.shape[1] != 2 or lim.shape[0] == 0:
            raise ConfigError(f"soft limits must be (n_joints, 2) [lower, upper], got shape {lim.shape}")
        for j, (lo, hi) in enumerate(lim):
            if not (np.isfinite(lo) and np.isfinite(hi)):
                raise ConfigError(f"limits.joints: joint {j + 1} has a limit that is not a finite number "
                                  f"({lo}, {hi}); give both limits as numbers")
            if not lo < hi:
                raise ConfigError(f"limits.joints: joint {j + 1} needs lower < upper, got [{lo}, {hi}]")
        lim.setflags(write=False)
        self.limits = lim
        self.elbows = tuple(int(e) for e in elbows)
        self.table: CorrectionTableData | None = None
        #: "revolute" / "prismatic" per joint: messages then read in deg / mm (None: as computed)
        self.joint_types = None if joint_types is None else tuple(joint_types)

    def check_joints(self, q: np.ndarray | Sequence[float], what: str) -> np.ndarray:
        """``q`` as a float array when it may be commanded; :class:`UnreachableError` otherwise
        (the motion is then not commanded)."""
        q = np.asarray(q, dtype=float)
        if q.shape != (self.limits.shape[0],):
            raise UnreachableError(f"{what}: {q.size} joint values for a robot with {self.limits.shape[0]} "
                                   f"joints; the motion was not commanded")
        lo, hi = self.limits[:, 0], self.limits[:, 1]
        bad = np.nonzero(~np.isfinite(q) | (q < lo) | (q > hi))[0]
        if bad.size:
            j = int(bad[0])
            if self.joint_types is not None and len(self.joint_types) == len(q) and np.isfinite(q[j]):
                kind = self.joint_types[j]
                side, limit = ("lower", lo[j]) if q[j] < lo[j] else ("upper", hi[j])
                where = (f"joint {j + 1} = {joint_value(q[j], kind)} is {joint_value(abs(q[j] - limit), kind)} "
                         f"beyond its {side} soft limit {joint_value(limit, kind)}")
            else:
                where = f"joint {j + 1} = {q[j]:.5g} is outside the soft limits [{lo[j]:.5g}, {hi[j]:.5g}]"
            raise UnreachableError(
                f"{what}: {where}; the motion was not commanded. Move the point or widen "
                f"[limits] if the robot allows it")
        return q

    def commanded_joints(self, pose6: np.ndarray, elbow: int, q_nominal: np.ndarray) -> np.ndarray:
        """The joints the controller commands for a Cartesian target: the nominal IK ``q_nominal``
        plus the active table's interpolated correction."""
        q = np.asarray(q_nominal, dtype=float)
        if self.table is None:
            return q
        pose6 = np.asarray(pose6, dtype=float)
        point = np.array([pose6[0], pose6[1], pose6[2], pose6[5]])[: len(self.table.axes)]
        config = 0 if (elbow == 1 or self.table.n_configs == 1) else 1
        try:
            return q + interpolate_table(self.table, point[None], config)[0]
        except TableRangeError as exc:
            raise UnreachableError(f"Cartesian target outside the active correction table's grid ({exc}); "
                                   f"the motion was not commanded") from exc

    def check_cartesian(self, pose6: np.ndarray, elbow: int, q_nominal: np.ndarray, what: str) -> np.ndarray:
        """Check a Cartesian target on the joints the controller will command (see above)."""
        pose6 = np.asarray(pose6, dtype=float)
        if pose6.shape != (6,) or not np.all(np.isfinite(pose6)):
            raise UnreachableError(f"{what}: the Cartesian target {pose6.tolist()} is not six finite numbers; "
                                   f"the motion was not commanded")
        return self.check_joints(self.commanded_joints(pose6, elbow, q_nominal), what)
