"""Typed progress events of a run, consumed alike by the CLI and the terminal UI."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from station.cell.records.summary import RunSummary

Phase = Literal["connect", "plan", "measure", "identify", "correct", "upload", "verify", "done"]


@dataclass(frozen=True)
class Event:
    """Base of all events."""


@dataclass(frozen=True)
class PhaseChanged(Event):
    phase: Phase
    detail: str = ""


@dataclass(frozen=True)
class RunStarted(Event):
    run_id: int
    n_steps: int
    resumed_from: int = 0  # steps already on disk from an earlier attempt


@dataclass(frozen=True)
class StepStarted(Event):
    index: int
    total: int
    label: str  # e.g. "point C2.a, elbow +1"


@dataclass(frozen=True)
class MeasurementRecorded(Event):
    index: int
    total: int
    label: str
    ok: bool
    residual_um: float  # plane residual of the pose solve (RMS), µm
    message: str = ""


@dataclass(frozen=True)
class DeviceSnapshot(Event):
    """What the devices reported at the last reading: every probe's value within its stroke,
    the joints and the controller's state (for the operator's device panel)."""

    probe_mm: tuple[float, ...]  # NaN where a channel did not read
    probe_status: tuple[str, ...]  # 'ok', 'over_range', 'under_range', 'invalid'
    stroke_mm: float  # each probe reads within ±stroke/2
    joints: tuple[float, ...]  # [rad | mm]
    joint_types: tuple[str, ...]
    controller: str  # e.g. 'ready', 'moving', 'error: …'
    heartbeat_age_s: float | None = None
    #: the head file's probe ids, one per entry of probe_mm (head order, wired channels only);
    #: () : probe_mm holds every channel of the interface (shown as P1, P2, …)
    probe_ids: tuple[str, ...] = ()


@dataclass(frozen=True)
class Notice(Event):
    level: Literal["info", "warning"]
    message: str


@dataclass(frozen=True)
class Paused(Event):
    index: int


@dataclass(frozen=True)
class Resumed(Event):
    index: int


@dataclass(frozen=True)
class RunFinished(Event):
    """The pipeline ran to its end; ``summary.outcome`` says how well (success, target missed,
    upload skipped)."""

    summary: RunSummary


@dataclass(frozen=True)
class RunFailed(Event):
    """An error stopped the run; ``summary.failure`` says what and what to do, everything
    measured so far is in the run database."""

    summary: RunSummary
