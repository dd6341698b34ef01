"""Thread-safe pause / resume / abort of a running calibration.

The UI (or the CLI's signal handler) owns a :class:`RunControl` and flips its flags from its own
thread; the blocking runner calls :meth:`RunControl.checkpoint` at every *safe point* (between
motions, never in the middle of a probe touch).  A pause therefore takes effect when the robot is
standing still at the next safe point, and an abort ends the run there with :class:`RunAborted`.
"""

from __future__ import annotations

import threading
from typing import Callable

from station.cell.run.facts.events import Event, Paused, Resumed
from station.errors import RunAborted

__all__ = ["RunAborted", "RunControl"]


class RunControl:
    """Pause / resume / abort flags shared between a UI thread and the runner thread.

    All methods are safe to call from any thread.  ``abort()`` also releases a runner that is
    waiting in a paused ``checkpoint()``; an abort cannot be undone.
    """

    def __init__(self) -> None:
        self._go = threading.Event()  # set = may proceed (not paused); cleared = paused
        self._go.set()
        self._abort = threading.Event()
        self._waiting = threading.Event()  # set while the runner sits in a paused checkpoint

    # --- operator side -------------------------------------------------------------------
    def pause(self) -> None:
        """Ask the runner to stop at its next safe point (no effect once aborted)."""
        if not self._abort.is_set():
            self._go.clear()

    def resume(self) -> None:
        """Let a paused runner continue."""
        self._go.set()

    def abort(self) -> None:
        """End the run at the next safe point: ``checkpoint()`` raises :class:`RunAborted`."""
        self._abort.set()
        self._go.set()  # wake a runner that waits in a paused checkpoint

    @property
    def paused(self) -> bool:
        """A pause was requested and not yet resumed (the runner may still be moving)."""
        return not self._go.is_set()

    @property
    def aborted(self) -> bool:
        return self._abort.is_set()

    @property
    def waiting(self) -> bool:
        """The runner is standing still in a paused ``checkpoint()`` right now."""
        return self._waiting.is_set()

    # --- runner side ---------------------------------------------------------------------
    def checkpoint(
        self,
        timeout: float | None = None,
        *,
        emit: Callable[[Event], None] | None = None,
        index: int = 0,
    ) -> bool:
        """Safe point of the runner: block while paused, raise :class:`RunAborted` if aborted.

        ``timeout`` bounds the wait while paused (None: wait until resumed or aborted).  Returns
        True when the runner may go on, False when ``timeout`` expired while still paused (the
        caller decides, e.g. call again).  With ``emit`` the wait is announced as
        ``Paused(index)`` and its end as ``Resumed(index)``.
        """
        if self._abort.is_set():
            raise RunAborted("run aborted by the operator at a safe point")
        if self._go.is_set():
            return True
        if emit is not None:
            emit(Paused(index=index))
        self._waiting.set()
        try:
            released = self._go.wait(timeout)
        finally:
            self._waiting.clear()
        if self._abort.is_set():
            raise RunAborted("run aborted by the operator while paused at a safe point")
        if released and emit is not None:
            emit(Resumed(index=index))
        return released
