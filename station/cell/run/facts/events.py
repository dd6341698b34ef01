"""Typed events of a run: one stream of run facts (issue 42).

The runner emits them; the CLI, the terminal UI, the OPC UA service and any other subscriber
(:class:`station.cell.run.facts.stream.RunStream`) read a run's figures from them. The figure events
(:class:`Identified`, :class:`TableDesigned`, :class:`Uploaded`, :class:`Verified`,
:class:`RunEnded`) carry the very summary objects the run stores (``summary`` in the run
database, the ``--json`` object), so no view computes or re-reads a figure another view shows.
Units as in the summary: µm for errors and bounds, mm and rad for parameters, s for times.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

from station.cell.records.summary import (
    CorrectionSummary,
    ErrorStats,
    IdentificationSummary,
    RunSummary,
    UploadSummary,
)

Phase = Literal["connect", "plan", "measure", "identify", "correct", "upload", "verify", "done"]


@dataclass(frozen=True)
class Event:
    """Base of all events."""


@dataclass(frozen=True)
class PhaseChanged(Event):
    phase: Phase
    detail: str = ""


@dataclass(frozen=True, eq=False)
class RunPlanned(Event):
    """A new run, planned and checked before anything moves: the configuration's text, one record
    per planned step (``PlannedStep.to_record``), a simulated cell's seed, where the configuration's
    files lie (``config_source``) and the cell's fingerprint. The run database's writer
    (:class:`station.cell.run.facts.writer.RunWriter`) creates the run from it; its number is the
    database's, and :class:`RunStarted` carries it."""

    config_toml: str
    plan: tuple[Mapping[str, Any], ...]
    seed: int | None
    config_source: str  # where the configuration was read, absolute (resolves its files)
    fingerprint: Mapping[str, Any]


@dataclass(frozen=True, eq=False)
class CellChanged(Event):
    """A resumed run whose cell changed where the measurements stay valid (post-processing
    sections, the files moved): the table, the figures and the report follow this text from now on."""

    run_id: int
    config_toml: str
    config_source: str  # where the configuration was read, absolute (resolves its files)
    fingerprint: Mapping[str, Any]


@dataclass(frozen=True)
class RunStarted(Event):
    run_id: int
    n_steps: int
    resumed_from: int = 0  # steps already on disk from an earlier attempt
    kind: Literal["calibration", "recheck"] = "calibration"  # which session's run
    resume: bool = False  # an attempt of a run that was started before (resumed_from may be 0)
    devices: tuple[tuple[str, str], ...] = ()  # what the devices said they are (for the report)


@dataclass(frozen=True)
class StatusChanged(Event):
    """The run's status (one of the run database's ``RUN_STATUSES``) where no figure event says it:
    measuring, measured, verified, and failed or aborted with what stopped it (``error``) and what
    was done about the controller's tables (``note``). :class:`Identified` says 'identified' and
    :class:`Uploaded` 'uploaded'."""

    status: str
    error: str = ""
    note: str = ""


@dataclass(frozen=True)
class StepStarted(Event):
    index: int
    total: int
    label: str  # e.g. "point C2.a, elbow +1"


@dataclass(frozen=True, eq=False)
class StepMeasured(Event):
    """A planned step's reading, all the run database stores of it: the run database's writer
    (:class:`station.cell.run.facts.recorder.RunRecorder`, the runner's first subscriber) commits it
    before any view hears of it and before the next motion, and a failure to store it stops the
    run. Joints [rad | mm], readings [mm], the pose solved (4×4, mm), its residual [µm]; the
    re-centring displacement (6: mm, rad) stored with it, None where the step was not re-centred."""

    run_id: int
    index: int
    kind: str
    point_id: str
    label: str
    joints_commanded: Any
    joints_read: Any
    raw: bytes
    readings_mm: Any
    channel_status: Any
    pose: Any
    residual_um: float | None
    ok: bool
    message: str
    recentring: Any
    replace: bool  # a step stored invalid by an earlier attempt, measured again


@dataclass(frozen=True)
class MeasurementRecorded(Event):
    index: int
    total: int
    label: str
    ok: bool
    residual_um: float  # plane residual of the pose solve (RMS), µm
    message: str = ""


@dataclass(frozen=True)
class Progress(Event):
    """k of n: the run's touches done (``done``) of all it will make (``total``), counted in the
    order measured. ``total`` starts at the plan's steps and grows by one for each touch the plan
    did not hold (a body-locating search touch, a warm-up cycle's reference touch, a step measured
    again in the same attempt); ``done`` never goes back. A run that ends needing fewer steps (an
    upload declined: no verification after it) ends at ``done`` of ``done``. Progress bars show
    this, never the plan's index (:mod:`station.cell.run.facts.progress`)."""

    done: int
    total: int
    label: str = ""  # the touch just done, e.g. "identification: point C2.a, elbow +1"


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
class Identified(Event):
    """The identification the run accepted (converged, plausible): the summary's figures (each
    chosen parameter with its σ [mm | rad], the residual RMS [µm]) and the whole model's parameter
    vector [mm | rad] (set-up first); with the chosen parameters' covariance [(mm | rad)²] and the
    fit's residual rows, all the run database's ``identification`` holds (its writer stores it
    from this event)."""

    identification: IdentificationSummary
    params: tuple[float, ...]
    covariance: tuple[tuple[float, ...], ...] | None = None
    residuals: tuple[Any, ...] | None = None  # the fit's residual rows, nested tuples of floats


@dataclass(frozen=True)
class TableDesigned(Event):
    """The correction table built for the identified robot: its grid's node counts, its values,
    its CRC-32 and its interpolation bound [µm], the one stored value the run judges against
    ``limit_um`` (``correction.interpolation_bound_um`` of the summary). With the grid it was built
    on (``grid_to_json``), the bounds sampled before motion [µm] and whether its nodes carry error
    terms: the run database's ``correction_grid``, which its writer stores from this event."""

    correction: CorrectionSummary
    grid: Mapping[str, Any] | None = None
    sampled_bounds_um: tuple[float, ...] = ()
    error_terms: bool = False


@dataclass(frozen=True)
class Uploaded(Event):
    """The table read back identical and activated: the summary's upload (CRC-32, seconds) and the
    controller's table slots as read after activation (8 hex digits, 'none' when empty)."""

    upload: UploadSummary
    active_crc32: str
    previous_crc32: str  # the roll-back slot: the table that was active before


@dataclass(frozen=True)
class Verified(Event):
    """The verification after correction: RMS before and after [µm] and the gain (before / after),
    the summary's own ``before``, ``after`` and ``gain``."""

    before: ErrorStats | None
    after: ErrorStats
    gain: float | None


@dataclass(frozen=True)
class RunEnded(Event):
    """The run ended, however: its summary, outcome and exit code (the last event of a run)."""

    summary: RunSummary

    @property
    def outcome(self) -> str:
        return self.summary.outcome.name

    @property
    def exit_code(self) -> int:
        return self.summary.exit_code


@dataclass(frozen=True)
class RunFinished(RunEnded):
    """The pipeline ran to its end; ``summary.outcome`` says how well (success, target missed,
    upload skipped)."""


@dataclass(frozen=True)
class RunFailed(RunEnded):
    """An error stopped the run; ``summary.failure`` says what and what to do, everything
    measured so far is in the run database."""
