"""What the station needs from its devices: small structural interfaces (consumer-owned).

Drivers satisfy these without inheriting from them (``typing.Protocol``), so a real cell swaps
in for the simulated one without code changes. Every device method the pipeline, the runner,
``station check`` and the verified upload call is declared here; mypy checks the drivers
against them where :mod:`station.cell.session.calibrate` builds the devices, and a test checks them at run
time against drivers connected to the simulators.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol, runtime_checkable

import numpy as np

from drivers.correction_table import TablePayload, WireTable


@runtime_checkable
class Snapshot(Protocol):
    """One (averaged) reading of every probe channel."""

    @property
    def values_mm(self) -> np.ndarray: ...  # (n_channels,) mm, NaN where a channel is not valid

    @property
    def raw(self) -> bytes: ...  # the frame(s) as received, kept in the run database

    @property
    def status(self) -> Sequence[Any]: ...  # per channel: OK, out of range, …


@runtime_checkable
class ProbeHead(Protocol):
    def identify(self) -> object: ...  # the interface unit's identification, for the record

    def read_all(self) -> Snapshot: ...

    def read_averaged(self, n: int, max_spread_mm: float) -> Snapshot: ...

    def close(self) -> None: ...


@runtime_checkable
class MotionStatus(Protocol):
    """A motion in progress; ``wait`` requires a timeout and raises the controller's typed errors."""

    def wait(self, timeout: float) -> None: ...

    @property
    def done(self) -> bool: ...


@runtime_checkable
class ControllerState(Protocol):
    """The controller's status word, as far as the station reads it."""

    @property
    def table_active(self) -> bool: ...

    @property
    def ready(self) -> bool: ...

    @property
    def error(self) -> bool: ...  # an error is latched (e-stop, drive fault, watchdog)

    @property
    def estop(self) -> bool: ...

    @property
    def error_message(self) -> str: ...

    @property
    def table_staged(self) -> bool: ...


@runtime_checkable
class RobotController(Protocol):
    def status(self) -> ControllerState: ...

    def move_joints(self, q: Sequence[float] | np.ndarray, speed: float = ...) -> MotionStatus: ...

    def move_cartesian(self, pose6: Sequence[float] | np.ndarray, elbow: int = ...,
                       speed: float = ...) -> MotionStatus: ...

    def read_joints(self) -> np.ndarray: ...

    def soft_limits(self) -> np.ndarray: ...

    def stop(self, timeout: float | None = ...) -> None: ...

    def reset_error(self, timeout: float | None = ...) -> None: ...  # clear a latched e-stop/fault

    def close(self) -> None: ...


@runtime_checkable
class TableController(Protocol):
    """The correction-table side of a controller: the verified upload and its roll back."""

    def status(self) -> ControllerState: ...

    def upload_table(self, table: TablePayload) -> None: ...

    def verify_table(self) -> WireTable: ...  # read back and compare; raises when it differs

    def stage_table(self, timeout: float | None = ...) -> None: ...

    def activate_table(self, timeout: float | None = ...) -> None: ...

    def deactivate_table(self, timeout: float | None = ...) -> None: ...

    def rollback_table(self, timeout: float | None = ...) -> None: ...

    def table_crcs(self) -> dict[str, int]: ...

    def read_slot_table(self, slot: str) -> WireTable | None: ...  # staged/active/previous

    def discard_previous_table(self, timeout: float | None = ...) -> None: ...


@runtime_checkable
class CellController(RobotController, TableController, Protocol):
    """A controller that moves the robot and takes a correction table (what ``calibrate`` needs)."""
