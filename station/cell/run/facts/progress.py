"""Progress "k of n" of a run (issue 42): what the progress bars of the CLI, the terminal UI and
OPC UA's step counter show, counted once, here, and streamed as :class:`~station.cell.run.facts.events.Progress`.

The plan's index is no measure of how far a run got: locating the body touches the plan's first,
farthest and next-farthest points before the rest, and its search touches (issue 37) and the
warm-up's cycles are touches the plan does not hold. So the count is of touches in the order they
were made: ``done`` goes up by one per touch and never back; ``total`` starts at the plan's steps
(those valid on disk already counted as done, for a resumed run) and grows with each touch the
plan did not hold, so that a run that measures its whole plan ends at n of n.
"""

from __future__ import annotations

from collections.abc import Callable

from station.cell.run.facts.events import Event, Progress

__all__ = ["RunProgress"]


class RunProgress:
    """The touch count of one run attempt; each change is emitted as a :class:`Progress`."""

    def __init__(self, emit: Callable[[Event], None]) -> None:
        self._emit = emit
        self.done = 0
        self.total = 0
        self.started = False
        self._measured: set[int] = set()  # plan steps measured in this attempt

    def start(self, total: int, done: int = 0) -> None:
        """A run attempt of ``total`` planned steps, ``done`` of them valid on disk already."""
        if not 0 <= done <= total:
            raise ValueError(f"progress: {done} steps done of {total}")
        self.done, self.total, self.started = done, total, True
        self._measured.clear()
        self._send("")

    def measured(self, index: int, label: str) -> None:
        """Plan step ``index`` was measured (and stored). A step measured again in this attempt
        (a locating touch that found nothing, measured again with the identification poses) is a
        touch the plan did not count: it adds to the total as well."""
        if index in self._measured:
            self.total += 1
        self._measured.add(index)
        self._count(label)

    def inserted(self, label: str) -> None:
        """A touch the plan does not hold (a search touch, a warm-up cycle) was made."""
        self.total += 1
        self._count(label)

    def finish(self) -> None:
        """The run ended needing no more steps (some planned ones were not needed: an upload not
        made has no verification after it): the total is what was done."""
        if self.started and self.total != self.done:
            self.total = self.done
            self._send("")

    def _count(self, label: str) -> None:
        self.done += 1
        self.total = max(self.total, self.done)  # a runner used without a plan's start (a test's)
        self._send(label)

    def _send(self, label: str) -> None:
        self._emit(Progress(self.done, self.total, label))
