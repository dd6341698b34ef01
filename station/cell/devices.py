"""What the station needs from its devices: small structural interfaces (consumer-owned).

Drivers and simulators satisfy these without inheriting from them (``typing.Protocol``), so a
real cell swaps in for the simulated one without code changes.
"""

from __future__ import annotations

from typing import Protocol, Sequence, runtime_checkable

import numpy as np


@runtime_checkable
class Snapshot(Protocol):
    """One (averaged) reading of every probe channel."""

    values_mm: np.ndarray  # (n_channels,) mm, NaN where a channel is not valid
    raw: bytes  # the frame(s) as received, kept in the run database

    @property
    def status(self) -> Sequence: ...


@runtime_checkable
class ProbeHead(Protocol):
    def read_averaged(self, n: int, max_spread_mm: float) -> Snapshot: ...

    def close(self) -> None: ...


@runtime_checkable
class MotionStatus(Protocol):
    """A motion in progress; ``wait`` requires a timeout and raises the controller's typed errors."""

    def wait(self, timeout: float) -> None: ...

    @property
    def done(self) -> bool: ...


@runtime_checkable
class RobotController(Protocol):
    def move_joints(self, q: np.ndarray, speed: float = ...) -> MotionStatus: ...

    def move_cartesian(self, pose: np.ndarray, elbow: int = ..., speed: float = ...) -> MotionStatus: ...

    def read_joints(self) -> np.ndarray: ...

    def soft_limits(self) -> np.ndarray: ...

    def stop(self) -> None: ...

    def close(self) -> None: ...


@runtime_checkable
class TableController(Protocol):
    """The correction-table side of a controller (verified upload, activate, roll back)."""

    def upload_table(self, table) -> None: ...

    def read_table(self): ...

    def stage_table(self) -> None: ...

    def activate_table(self) -> None: ...

    def deactivate_table(self) -> None: ...

    def rollback_table(self) -> None: ...
