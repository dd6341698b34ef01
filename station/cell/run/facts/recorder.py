"""The run database's writer as a subscriber of the runner's stream (issue 42).

The runner no longer writes its measurements itself: it emits each as a
:class:`~station.cell.run.facts.events.StepMeasured` and :class:`RunRecorder`, subscribed first for the
run's measuring, stores it. The guarantees stay the runner's: the recorder is called synchronously
on the runner's thread before any other subscriber (the views hear of a measurement when it is on
disk, committed; the next motion waits for it), and a recorder that fails (a full disk, a damaged
database) raises through the emit and stops the run at that step.
"""

from __future__ import annotations

from station.cell.records.rundb import RunDB
from station.cell.run.facts.events import StepMeasured
from station.cell.run.recentring import RecentringLog

__all__ = ["RunRecorder"]


class RunRecorder:
    """Stores the measurements of run ``run_id`` in ``db`` as they are streamed."""

    def __init__(self, db: RunDB, run_id: int) -> None:
        self.db, self.run_id = db, run_id
        self._recentring = RecentringLog(db, run_id)

    def __call__(self, e: StepMeasured) -> None:
        if e.run_id != self.run_id:  # another run's stream: a slip that must not write here
            raise ValueError(f"run {e.run_id}'s measurement streamed to the recorder of run {self.run_id}")
        self._recentring.record(e.index, e.recentring)  # before the measurement it belongs to
        self.db.record_measurement(
            e.run_id, e.index, kind=e.kind, point_id=e.point_id, label=e.label,
            joints_commanded=e.joints_commanded, joints_read=e.joints_read, raw_frames=e.raw,
            readings_mm=e.readings_mm, channel_status=e.channel_status, pose=e.pose,
            pose_residual_um=e.residual_um, ok=e.ok, message=e.message, replace=e.replace)
