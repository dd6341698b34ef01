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
import errno
import os
import sys
from collections.abc import Iterable, Iterator
from typing import Any, TextIO

from station.errors import ConfigError

__all__ = ["DISK_ERRNOS", "SafeStream", "guarded_streams", "write_file"]

#: a disk that is full, over quota, at a file-size limit or read-only: the operator's to fix, not a bug
DISK_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS})


def write_file(path: str | os.PathLike[str], text: str) -> None:
    """Write a file the user named (``-o``): a full disk (ENOSPC, also ``/dev/full``), a read-only
    folder or a missing one is a :class:`ConfigError` that names the file, never an internal error."""
    try:
        with open(path, "w", encoding="utf-8") as f:
            f.write(text)
    except OSError as exc:
        raise ConfigError(f"{os.fspath(path)}: cannot write it ({exc.strerror or exc}); free space on its disk "
                          f"or choose another path") from None


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
