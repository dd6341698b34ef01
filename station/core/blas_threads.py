"""One BLAS thread for the fit's small, tall factorisations.

A fit's factorisations are tall and narrow (QR of a few thousand rows by a few dozen columns).
OpenBLAS spreads them over every core, which costs more in hand-over than it saves, and on a
machine whose cores are busy with other work it waits for them: the QR of a 1000-pose fit took
4 ms on one thread and 4–140 ms on two of a loaded two-core machine. :func:`single_blas_thread`
runs a block with numpy's OpenBLAS on one thread and restores the count after (what
``threadpoolctl`` does, without the dependency). The results do not change: OpenBLAS computes
every product and factor the same way on one thread as on several. Where numpy's BLAS is not an
OpenBLAS this module recognises, it does nothing.
"""

from __future__ import annotations

import contextlib
import ctypes
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

# (get, set) symbol pairs of the OpenBLAS builds numpy ships or links
_SYMBOLS = (
    ("scipy_openblas_get_num_threads64_", "scipy_openblas_set_num_threads64_"),
    ("scipy_openblas_get_num_threads", "scipy_openblas_set_num_threads"),
    ("openblas_get_num_threads64_", "openblas_set_num_threads64_"),
    ("openblas_get_num_threads", "openblas_set_num_threads"),
)
_lock = threading.Lock()
_depth = 0
_saved = 0


def _find() -> tuple[Callable[[], int], Callable[[int], None]] | None:
    """numpy's OpenBLAS thread-count functions, or None."""
    libs = Path(np.__file__).resolve().parent.parent / "numpy.libs"
    candidates = sorted(libs.glob("lib*openblas*.so*")) if libs.is_dir() else []
    for path in candidates:
        try:
            lib = ctypes.CDLL(str(path))  # numpy has loaded it already: this is the same library
        except OSError:
            continue
        for get, set_ in _SYMBOLS:
            if hasattr(lib, get) and hasattr(lib, set_):
                fget, fset = getattr(lib, get), getattr(lib, set_)
                fget.restype, fget.argtypes = ctypes.c_int, []
                fset.restype, fset.argtypes = None, [ctypes.c_int]
                return fget, fset
    return None


_FUNCTIONS: tuple[Callable[[], int], Callable[[int], None]] | None = None
_FOUND = False


def _functions() -> tuple[Callable[[], int], Callable[[int], None]] | None:
    global _FUNCTIONS, _FOUND
    if not _FOUND:
        _FUNCTIONS, _FOUND = _find(), True
    return _FUNCTIONS


@contextlib.contextmanager
def single_blas_thread() -> Iterator[None]:
    """Run the block with numpy's OpenBLAS on one thread (nested blocks and threads share one
    setting: the count is restored when the last block ends)."""
    global _depth, _saved
    fns = _functions()
    if fns is None:
        yield
        return
    get, set_ = fns
    with _lock:
        if _depth == 0:
            _saved = get()
            if _saved > 1:
                set_(1)
        _depth += 1
    try:
        yield
    finally:
        with _lock:
            _depth -= 1
            if _depth == 0 and _saved > 1:
                set_(_saved)
