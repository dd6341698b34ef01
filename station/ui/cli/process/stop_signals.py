"""SIGTERM (a scheduler, systemd) and SIGINT (Ctrl-C) for the commands that run a session.

``main()`` calls :func:`catch_stop_signals` before it parses anything, so a signal from the first
moment the station runs is an outcome (ABORTED, exit 6), never the default death (exit 143) or a
``KeyboardInterrupt`` traceback:

- before the session starts, the command sees :attr:`StopSignals.requested` and ends ABORTED
  without opening a device;
- during the session (:func:`safe_stop_on_signals`), the first signal asks the run to stop at the
  next safe point; a second one raises :class:`~station.errors.RunAborted` where the program is,
  which the runner turns into an aborted, resumable run (every measurement is already committed);
- after the session, the run's own outcome stands: a signal then is only noted, and so until the
  process has exited: ``main()`` of the process itself (the ``station`` script) leaves SIGTERM and
  SIGINT ignored when it returns (``hold``), so a signal that lands after the JSON is written, while
  the interpreter shuts down, changes nothing: the exit code is the outcome's (issue 33).
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
from collections.abc import Iterator
from types import FrameType
from typing import Protocol

from station.errors import RunAborted

__all__ = ["StopSignals", "catch_stop_signals", "current", "safe_stop_on_signals"]

_SIGNALS = (signal.SIGTERM, signal.SIGINT)


class _Abortable(Protocol):
    def abort(self) -> None: ...


def _say(text: str) -> None:
    # os.write, not print: a handler that runs while the main thread is inside a buffered write
    # of stderr would otherwise raise "reentrant call"; a broken stderr only loses the line
    try:
        os.write(2, text.encode("utf-8", "replace"))
    except OSError:
        pass


class StopSignals:
    """The stop signals received so far, and what they do at this moment of the command."""

    def __init__(self) -> None:
        self.received: list[int] = []
        self.control: _Abortable | None = None  # set while a session runs
        self.decided: bool | str = False  # the session has ended: its outcome stands, whatever comes now
        self._lock = threading.Lock()

    @property
    def requested(self) -> bool:
        return bool(self.received)

    @property
    def name(self) -> str:
        return signal.Signals(self.received[0]).name if self.received else ""

    def handle(self, signum: int, frame: FrameType | None) -> None:
        self.received.append(signum)
        name = signal.Signals(signum).name
        control = self.control
        if self.decided:
            if self.decided is True:  # said once
                _say(f"\nstation: {name}: the run has already ended; its outcome stands\n")
                self.decided = "said"
            return
        if control is None:
            if len(self.received) == 1:
                _say(f"\nstation: {name}: stopping\n")
            return
        if len(self.received) == 1:
            _say(f"\nstation: {name}: stopping at the next safe point (send it again to stop at once)\n")
            control.abort()
        elif len(self.received) == 2:
            # once only: the runner's clean-up (restoring the controller's tables, marking the
            # run aborted) must not be cut short by a third signal
            _say(f"\nstation: {name} again: stopping now\n")
            control.abort()
            raise RunAborted(f"run stopped at once by a second {name}; every measurement taken is stored")


_current: StopSignals | None = None


def current() -> StopSignals | None:
    """The signals of the running command (None: not a session command, or not the main thread)."""
    return _current


@contextlib.contextmanager
def catch_stop_signals(enabled: bool = True, hold: bool = False) -> Iterator[StopSignals | None]:
    """Catch SIGTERM and SIGINT for the duration (main thread only: tests call ``main()`` from
    workers too); the previous handlers are back afterwards, or (``hold``: the process ends now,
    with the command's exit code) both signals are ignored until it has exited."""
    global _current
    if not enabled or threading.current_thread() is not threading.main_thread():
        yield None
        return
    stops = StopSignals()
    previous = {sig: signal.signal(sig, stops.handle) for sig in _SIGNALS}
    outer, _current = _current, stops
    try:
        yield stops
    finally:
        _current = outer
        for sig, old in previous.items():
            if hold:  # the outcome is decided: nothing may turn it into a death by signal now
                signal.signal(sig, signal.SIG_IGN)
                continue
            # After a stop the command is ending with exit 6: a late repeat of the signal (the
            # operator pressing twice) must not kill the process by the default action before
            # its JSON and exit code are out, so it is ignored from here instead.
            signal.signal(sig, signal.SIG_IGN if stops.requested and old == signal.SIG_DFL else old)


@contextlib.contextmanager
def safe_stop_on_signals(control: _Abortable) -> Iterator[StopSignals | None]:
    """Let the signals stop ``control``'s run for the duration (see the module's docstring)."""
    with contextlib.ExitStack() as stack:
        stops = _current or stack.enter_context(catch_stop_signals())
        if stops is None:
            yield None
            return
        stops.control = control
        if stops.requested:  # it came in between the command's check and here
            control.abort()
        try:
            yield stops
        finally:
            stops.control = None
            stops.decided = True
