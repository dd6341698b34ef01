"""The fleet outbox as a subscriber of the run's stream (issue 42): a session subscribes it to its
:class:`~station.cell.run.facts.stream.RunStream` once the cell is loaded, and the run's end
(:class:`~station.cell.run.facts.events.RunEnded`: ``RunFinished`` from the pipeline, ``RunFailed`` from
the session once the failure's summary is stored) queues the run for the fleet store and tries to
send it (:func:`station.cell.publication.outbox.publish_or_queue`), instead of the session calling
the outbox itself.

Exactly once: each run of a session is queued at its first end only (a session whose run finished
and whose devices then failed to close does not queue the run's failure over its finish); the
queue's (run, ending) key and the store's UUID keep a retry or a ``station sync`` from making a
second row. A subscriber that raises stops the run (the stream's rule), so this one never does: a
run's outcome never depends on the network, and a publication that fails is said and logged.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path

from station.cell.config.cell_config import CellConfig
from station.cell.run.facts.events import Event, Notice, RunEnded
from station.cell.run.facts.stream import RunStream

log = logging.getLogger(__name__)

__all__ = ["FleetOutbox"]


class FleetOutbox:
    """Queues and sends each run that ends in one session (``[fleet] url`` or STATION_FLEET_URL;
    nothing when neither is set), saying on ``emit`` what became of it."""

    def __init__(self, db_path: str | Path, cfg: CellConfig, emit: Callable[[Event], None],
                 url: str | None = None) -> None:
        self.db_path, self.cfg, self._emit, self._url = db_path, cfg, emit, url
        self.published: set[int] = set()  # the runs queued in this session

    @classmethod
    def subscribe(cls, stream: RunStream, db_path: str | Path, cfg: CellConfig, url: str | None = None) -> int:
        """Subscribe an outbox to ``stream``'s run ends, its notices said on the same stream; returns
        the token."""
        return stream.subscribe(cls(db_path, cfg, stream, url), RunEnded)

    def __call__(self, event: RunEnded) -> None:
        run_id = event.summary.run_id
        if run_id is None or run_id in self.published:
            return
        self.published.add(run_id)
        try:
            from station.cell.publication.outbox import publish_or_queue  # psycopg only where a run ends

            line = publish_or_queue(self.db_path, run_id, self.cfg, url=self._url)
            if line is not None:
                # "queued, not yet published" is a warning too (it said 'info' while the session called the outbox)
                self._emit(Notice("info" if " published to the fleet store" in line else "warning", line))
        except Exception as exc:  # noqa: BLE001 - the run's outcome stands whatever publishing does
            log.warning("run %s: not published to the fleet store: %s", run_id, exc)
