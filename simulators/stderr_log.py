"""Logging for the simulator process that never blocks on a full stderr pipe.

``python -m simulators`` is often run as a subprocess whose stderr is a pipe nobody reads. The
pymodbus server logs every malformed frame and every request it cannot serve (with a traceback)
at ERROR level; without a handler these went to Python's last-resort handler, a blocking write
to stderr. A hostile or fuzzing client fills the 64 KiB pipe within a few hundred frames, and
then the server's event loop blocks in ``write(2)`` for good: the controller stops answering.

:class:`NonBlockingStderrHandler` writes a record only if the stream can take it now
(``select`` says writable; one record is at most :data:`MAX_RECORD_BYTES`, below a pipe's
atomic-write size), keeps a token bucket so that a flood cannot flood the reader either, and
otherwise drops the record and counts it; the count is reported with the next record written.
"""

from __future__ import annotations

import logging
import os
import select
import sys
import threading
import time

__all__ = ["NonBlockingStderrHandler", "install"]

#: One record on the wire at most (a pipe write of <= PIPE_BUF bytes is atomic and fits in a
#: pipe that select() reports writable).
MAX_RECORD_BYTES = 1024


class NonBlockingStderrHandler(logging.Handler):
    """Write records to a file descriptor without ever blocking; drop (and count) the rest.

    ``burst`` records may be written at once, then ``rate`` per second.
    """

    def __init__(self, fd: int | None = None, level: int = logging.WARNING, burst: int = 50,
                 rate: float = 5.0) -> None:
        super().__init__(level)
        self.fd = sys.stderr.fileno() if fd is None else int(fd)
        self.burst = float(burst)
        self.rate = float(rate)
        self._tokens = float(burst)
        self._last = time.monotonic()
        self._count_lock = threading.Lock()
        self.written = 0
        self.dropped = 0
        self._unreported = 0
        self.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))

    def _take_token(self) -> bool:
        now = time.monotonic()
        self._tokens = min(self.burst, self._tokens + (now - self._last) * self.rate)
        self._last = now
        if self._tokens >= 1.0:
            self._tokens -= 1.0
            return True
        return False

    def _writable(self) -> bool:
        try:
            _, w, _ = select.select([], [self.fd], [], 0)
        except (OSError, ValueError):
            return False
        return bool(w)

    def emit(self, record: logging.LogRecord) -> None:
        with self._count_lock:
            if not self._take_token() or not self._writable():
                self.dropped += 1
                self._unreported += 1
                return
            try:
                text = self.format(record)
            except Exception:  # a broken record must not take the server down
                text = f"unformattable log record from {record.name}"
            if self._unreported:
                text = f"[{self._unreported} log record(s) dropped: stderr was not read] " + text
            data = text.replace("\r", " ").encode("utf-8", "replace")
            if len(data) > MAX_RECORD_BYTES - 1:
                data = data[:MAX_RECORD_BYTES - 5] + b" ..."
            try:
                os.write(self.fd, data + b"\n")
            except OSError:
                self.dropped += 1
                self._unreported += 1
                return
            self._unreported = 0
            self.written += 1


def install(level: int = logging.WARNING) -> NonBlockingStderrHandler:
    """Make the root logger write through a :class:`NonBlockingStderrHandler` only (for the
    simulator process; the station configures its own logging)."""
    handler = NonBlockingStderrHandler(level=level)
    root = logging.getLogger()
    for h in list(root.handlers):
        root.removeHandler(h)
    root.addHandler(handler)
    root.setLevel(level)
    return handler
