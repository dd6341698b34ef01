"""One stream of run facts (issue 42): the run's events, handed to every subscriber in order.

Modelled on bluesky's ``RunEngine.subscribe``: a callback subscribes (to every event, or to one
kind of event and its subclasses) and gets a token; ``unsubscribe(token)`` removes it. A
:class:`RunStream` is itself an ``emit`` callable, so the sessions and the pipeline take it where
they took one callback: the terminal UI, the OPC UA service, the CLI's progress and a test's
recorder subscribe to the same stream and read the same figures.

A subscriber's exception propagates to the run, as a single ``emit`` callback's always did: a
view that cannot follow stops the run at the step it was told of (the run database keeps what was
measured). Views that must never hold the robot (OPC UA) hand the event on to their own thread.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from itertools import count
from typing import TypeVar

from station.cell.run.facts.events import Event

__all__ = ["RunStream", "Subscriber"]

E = TypeVar("E", bound=Event)
Subscriber = Callable[[E], None]


class RunStream:
    """The subscribers of one session's events; call it with an event to hand it to each one
    that subscribed to the event's kind, in the order they subscribed."""

    def __init__(self, *subscribers: Callable[[Event], None]) -> None:
        self._subscribers: dict[int, tuple[type[Event], Callable[[Event], None]]] = {}
        self._tokens = count(1)
        self._lock = threading.Lock()  # a view may subscribe from its own thread while the run emits
        for callback in subscribers:
            self.subscribe(callback)

    def subscribe(self, callback: Callable[[E], None], kind: type[E] = Event,  # type: ignore[assignment]
                  first: bool = False) -> int:
        """Hand ``callback`` every event of ``kind`` (default: every event) from now on; returns
        the token :meth:`unsubscribe` takes. ``first``: before the subscribers there are (the run
        database's writer: a view hears of a measurement once it is on disk)."""
        if not (isinstance(kind, type) and issubclass(kind, Event)):
            raise TypeError(f"subscribe to an Event type, not {kind!r}")
        with self._lock:
            token = next(self._tokens)
            entry = (kind, callback)
            if first:
                self._subscribers = {token: entry, **self._subscribers}  # type: ignore[dict-item]
            else:
                self._subscribers[token] = entry  # type: ignore[assignment]
        return token

    def unsubscribe(self, token: int) -> None:
        """Stop handing events to the subscriber of ``token`` (an unknown token: nothing)."""
        with self._lock:
            self._subscribers.pop(token, None)

    def __call__(self, event: Event) -> None:
        with self._lock:
            subscribers = list(self._subscribers.values())
        for kind, callback in subscribers:
            if isinstance(event, kind):
                callback(event)

    def __len__(self) -> int:
        return len(self._subscribers)
