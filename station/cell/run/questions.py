"""Questions the pipeline asks the operator before it changes the controller's state.

The pipeline calls ``confirm(question) -> bool`` (``Options.confirm``); the TUI shows the
question and waits for the operator, a script passes no ``confirm`` (the upload then goes ahead,
as ``--no-upload`` is the way to keep the controller untouched).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass


@dataclass(frozen=True)
class UploadProposal:
    """Before the upload: the table that would be activated."""

    n_values: int
    grid_shape: tuple[int, ...]
    #: the run's stored bound (``RunSummary.correction``): the same figure the report and JSON give
    interpolation_bound_um: float
    crc32: str
    max_correction: tuple[float, ...]  # per joint [rad | mm]
    joint_types: tuple[str, ...]


@dataclass(frozen=True)
class KeepCorrection:
    """After verification: keep the new table active, or roll back to the previous one."""

    rms_before_um: float
    rms_after_um: float
    gain: float
    crc32: str


Question = UploadProposal | KeepCorrection
Confirm = Callable[[Question], bool]
