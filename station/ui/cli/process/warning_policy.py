"""What a command does with Python warnings from numpy, scipy and the libraries below it.

A warning's default form is two lines naming a source file, which reads like a crash to an
operator. Floating-point warnings of numpy's ufuncs (overflow, invalid value, divide by zero,
underflow) are expected: the station checks every result it uses for finiteness and refuses
with its own message (a non-finite model, a probe out of range), so they are silenced. Any other
warning is shown once, as one line of the station's ("station: note: …"), on stderr.
"""

from __future__ import annotations

import sys
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from typing import TextIO

#: numpy's floating-point messages (numpy/core/_ufunc_config: "… encountered in …")
_FLOATING_POINT = r"(overflow|invalid value|divide by zero|underflow) encountered"


@contextmanager
def station_warnings(stream: TextIO | None = None) -> Iterator[None]:
    """Within the block, numerical warnings follow this module's policy (restored after)."""
    seen: set[tuple[str, str]] = set()

    def show(message, category, filename, lineno, file=None, line=None) -> None:
        key = (category.__name__, str(message))
        if key in seen:
            return
        seen.add(key)
        out = stream if stream is not None else sys.stderr
        try:
            print(f"station: note: {message} ({category.__name__})", file=out)
        except (OSError, ValueError, AttributeError):  # a closed stderr drops the note, not the command
            return

    with warnings.catch_warnings():
        warnings.simplefilter("default")
        warnings.filterwarnings("ignore", message=_FLOATING_POINT, category=RuntimeWarning)
        warnings.showwarning = show
        yield
