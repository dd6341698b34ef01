"""Output that cannot fail a run: stdout and stderr wrapped so that a closed or broken stream
(``station calibrate … | head -n 3``, a terminal that went away) drops what could not be
written instead of raising into the measurement loop.

:func:`guarded_streams` is what ``station``'s ``main()`` runs every command inside. Its end
follows Python's advice on SIGPIPE (the ``signal`` module's docs): a stream that broke has
``/dev/null`` put under its file descriptor, so the interpreter's own final flush has somewhere
to go and prints no "Exception ignored … BrokenPipeError".
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Iterable, Iterator
from typing import Any, TextIO

__all__ = ["SafeStream", "guarded_streams"]


class SafeStream:
    """A text stream that never raises on write or flush: the first failure (a broken pipe, a
    closed file, a descriptor that is gone) marks it ``broken`` and everything after is dropped."""

    def __init__(self, stream: TextIO | None) -> None:
        self.wrapped = stream
        # Python sets sys.stdout to None when descriptor 1 was closed before it started (>&-)
        self.broken = stream is None
        self.dropped_chars = 0

    def write(self, text: str) -> int:
        if not self.broken:
            try:
                return self.wrapped.write(text)  # type: ignore[union-attr]
            # ValueError: "I/O operation on closed file"; OSError: EPIPE, EBADF, and also a full
            # disk behind a redirect: none of them may stop a robot in the middle of a run
            except (OSError, ValueError, AttributeError):
                self.broken = True
        self.dropped_chars += len(text)
        return len(text)

    def writelines(self, lines: Iterable[str]) -> None:
        for line in lines:
            self.write(line)

    def flush(self) -> None:
        if self.broken:
            return
        try:
            self.wrapped.flush()  # type: ignore[union-attr]
        except (OSError, ValueError, AttributeError):
            self.broken = True

    def isatty(self) -> bool:
        try:
            return bool(self.wrapped.isatty())  # type: ignore[union-attr]
        except (OSError, ValueError, AttributeError):
            return False

    def __getattr__(self, name: str) -> Any:  # encoding, fileno, errors …: the wrapped stream's
        return getattr(self.wrapped, name)


def _silence(stream: TextIO) -> None:
    """Put /dev/null under a broken stream's descriptor and drop its pending bytes there."""
    try:
        fd = stream.fileno()
        null = os.open(os.devnull, os.O_WRONLY)
        try:
            os.dup2(null, fd)
        finally:
            os.close(null)
        stream.flush()
    except (OSError, ValueError):  # no descriptor (a test's capture) or already gone: nothing to do
        pass


@contextlib.contextmanager
def guarded_streams() -> Iterator[tuple[SafeStream, SafeStream]]:
    """``sys.stdout`` and ``sys.stderr`` as :class:`SafeStream` for the duration; afterwards the
    originals are back, and a broken one writes to /dev/null from then on."""
    out, err = sys.stdout, sys.stderr  # None where the descriptor was closed at start
    safe_out = out if isinstance(out, SafeStream) else SafeStream(out)
    safe_err = err if isinstance(err, SafeStream) else SafeStream(err)
    sys.stdout, sys.stderr = safe_out, safe_err
    try:
        yield safe_out, safe_err
    finally:
        safe_out.flush()
        safe_err.flush()
        sys.stdout, sys.stderr = out, err
        for safe in (safe_out, safe_err):
            if safe.broken and safe.wrapped is not None:
                _silence(safe.wrapped)
