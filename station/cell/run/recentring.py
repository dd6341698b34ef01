"""Re-centring, kept with the measurement it moved (issue 18).

A touch whose probes come near the end of their stroke is re-centred: the robot is moved by the
measured offset so that the probes read near mid-stroke, and read again. The reading is then
taken where the robot was moved to, not where it was commanded. For the identification this is
harmless (the joints read go with the pose); for verification it would hide the robot's error:
a robot 500 µm off, re-centred onto the corner, reads a few µm.

So every re-centred measurement keeps the displacement from the first commanded pose to the one
it was read at, as a pose in the head frame of the first command (x, y, z [mm], roll, pitch, yaw
[rad]). The run database holds these under the result :data:`RESULT_KEY`, by step index; a
verification error adds the displacement back (:func:`head_as_commanded`), the same way before,
after and with the oracle. The robot's error changes little over a displacement of a few mm, so
the figure is the error at the commanded pose.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from station.cell.plan.steps import PlannedStep, StepKind
from station.cell.records.rundb import RunDB
from station.cell.records.summary import RecentringStats
from station.core.kinematics.transforms import invert, matrix_to_pose, pose_to_matrix

__all__ = ["RESULT_KEY", "displacement", "head_as_commanded", "stored_recentring", "RecentringLog",
           "recentring_stats"]

#: the run database's result that holds the re-centring displacements: {"<step index>": [6 floats]}
RESULT_KEY = "recentring"


def displacement(T_first: np.ndarray, T_last: np.ndarray) -> np.ndarray:
    """The move from the first commanded head pose to the last (base←head ``(4, 4)`` each), in
    the first one's head frame: x, y, z [mm], roll, pitch, yaw [rad]."""
    return matrix_to_pose(invert(np.asarray(T_first, dtype=float)) @ np.asarray(T_last, dtype=float))


def head_as_commanded(head_measured: np.ndarray, d: np.ndarray | None) -> np.ndarray:
    """The measured world←head pose ``(4, 4)`` of a re-centred reading, moved back by its
    displacement ``d``: where the robot stood at its first command (the re-centring's move is
    part of its error)."""
    if d is None:
        return head_measured
    return head_measured @ invert(pose_to_matrix(np.asarray(d, dtype=float)))


def stored_recentring(db: RunDB, run_id: int) -> dict[int, np.ndarray]:
    """The displacement of each re-centred measurement of a run, by step index (empty for a run
    that re-centred nothing, or one stored before displacements were kept)."""
    raw = db.load_result(run_id, RESULT_KEY, default=None) or {}
    return {int(k): np.asarray(v, dtype=float) for k, v in raw.items()}


class RecentringLog:
    """The run's displacements as the runner records them: written to the run database before the
    measurement they belong to, so a measurement on disk never lacks its displacement."""

    def __init__(self, db: RunDB, run_id: int) -> None:
        self._db = db
        self._run_id = run_id
        self._by_step = {k: v.tolist() for k, v in stored_recentring(db, run_id).items()}

    def record(self, step_index: int, d: np.ndarray | None) -> None:
        """Keep ``d`` for the step (None: it was not re-centred, e.g. a re-measured step that no
        longer needs it); writes only when that changes what is stored."""
        before = self._by_step.get(step_index)
        if d is None:
            if before is None:
                return
            del self._by_step[step_index]
        else:
            self._by_step[step_index] = [float(v) for v in d]
        self._db.save_result(self._run_id, RESULT_KEY, {str(k): v for k, v in sorted(self._by_step.items())})


def recentring_stats(steps: Sequence[PlannedStep], records_by_kind: Mapping[StepKind, Sequence[Any]],
                     recentring: Mapping[int, np.ndarray]) -> tuple[RecentringStats, ...]:
    """Per kind of measurement with records: how many readings were re-centred, and by how much
    (the position part of the displacement [µm])."""
    out = []
    for kind, records in records_by_kind.items():
        if not records:
            continue
        moved = [float(np.linalg.norm(recentring[r.step_index][:3])) * 1e3
                 for r in records if r.step_index in recentring and steps[r.step_index].kind is kind]
        d = np.array(moved)
        out.append(RecentringStats(kind=kind.value, n_readings=len(records), n_recentred=int(d.size),
                                   max_um=float(d.max()) if d.size else 0.0,
                                   rms_um=float(np.sqrt(np.mean(d**2))) if d.size else 0.0))
    return tuple(out)
