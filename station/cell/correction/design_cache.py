"""The correction design kept on disk between processes, by everything it depends on (issue 42).

Every ``station plan`` and ``station calibrate`` designs the cell's table before the first motion
(:func:`station.cell.correction.design.design_for`: a few hundred sampled robots' tables, 6–7 s of
CPU for the built-in cell). The design is a pure function of the cell's robot, region, bound,
capacity, the sizes of the errors ``[simulation]`` states, the identification settings and the
plan's identification poses, and of the code that computes it. A rehearsal, the nightly script and
the test suite start the same cell again and again, so the design is kept in a file named by a
digest of all of these: the same inputs and code give the same file, any change gives another.

The code's part of the digest is the station's version and the source of every module the design
reads (:mod:`station.core` and :mod:`station.cell.correction`), so an edited module is never served
a design it did not make. The file is JSON (never pickle: a cache file is data, not code), written
to a temporary name and renamed, so a reader sees a whole design or none; a file that cannot be
read or does not parse is ignored and the design made again. A cache that cannot be written costs
only the time.

Where: ``$STATION_DESIGN_CACHE`` (a folder; ``off`` keeps nothing), else
``$XDG_CACHE_HOME/station/designs``, else ``~/.cache/station/designs``.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import os
import tempfile
import typing
from pathlib import Path
from typing import Any

import numpy as np

from station.core.table.design import Region, TableDesign
from station.core.table.grid import GridSpec

__all__ = ["CACHE_ENV", "cache_dir", "key_digest", "load_design", "store_design"]

#: the folder the designs are kept in, or "off"
CACHE_ENV = "STATION_DESIGN_CACHE"
#: the format of a kept design (a change makes every older file another name)
FORMAT = 1


def cache_dir() -> Path | None:
    """The folder designs are kept in; None when ``$STATION_DESIGN_CACHE`` is ``off``."""
    chosen = os.environ.get(CACHE_ENV)
    if chosen is not None:
        return None if chosen.strip().lower() in ("", "off", "0", "no", "false") else Path(chosen)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "station" / "designs"


@functools.cache
def _code_digest() -> str:
    """The station's version and the source of every module a design reads."""
    import station

    root = Path(station.__file__).resolve().parent
    h = hashlib.sha256(str(getattr(station, "__version__", "")).encode())
    for folder in (root / "core", root / "cell" / "correction"):
        for path in sorted(folder.rglob("*.py")):
            h.update(str(path.relative_to(root)).encode())
            h.update(path.read_bytes())
    return h.hexdigest()


def key_digest(key: tuple[Any, ...]) -> str:
    """The file name of the design made from ``key`` (the design's inputs: numbers, strings,
    bytes, tuples and frozen dataclasses, whose ``repr`` is exact) by this code."""
    return hashlib.sha256(f"{FORMAT}\0{_code_digest()}\0{key!r}".encode()).hexdigest()


def _plain(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return {"__array__": value.tolist(), "dtype": str(value.dtype)}
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: _plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, (tuple, list)):
        return [_plain(v) for v in value]
    return value


def _tuples(value: Any) -> Any:
    return tuple(_tuples(v) for v in value) if isinstance(value, list) else value


def _restore(cls: type, data: dict[str, Any]) -> Any:
    """``cls`` from its plain fields: arrays from their tag, nested dataclasses by their type,
    lists as the tuples the frozen dataclasses hold."""
    hints = typing.get_type_hints(cls)
    kwargs = {}
    for f in dataclasses.fields(cls):
        if f.name not in data:
            continue
        raw = data[f.name]
        hint = hints.get(f.name)
        if isinstance(raw, dict) and "__array__" in raw:
            kwargs[f.name] = np.array(raw["__array__"], dtype=raw["dtype"])
        elif hint in (GridSpec, Region):
            kwargs[f.name] = _restore(hint, raw)
        else:
            kwargs[f.name] = _tuples(raw)
    return cls(**kwargs)


def load_design(digest: str) -> TableDesign | None:
    """The kept design of ``digest``; None when none is kept, or it cannot be read."""
    folder = cache_dir()
    if folder is None:
        return None
    try:
        data = json.loads((folder / f"{digest}.json").read_text(encoding="utf-8"))
        if data.get("format") != FORMAT or data.get("digest") != digest:
            return None
        design = _restore(TableDesign, data["design"])
        return design if isinstance(design, TableDesign) else None
    except (OSError, ValueError, TypeError, KeyError, AttributeError):
        return None  # absent, partly written by a crashed writer, or from another format: made again


def store_design(digest: str, design: TableDesign) -> bool:
    """Keep ``design`` under ``digest``; False when it cannot be written (nothing else is lost)."""
    folder = cache_dir()
    if folder is None:
        return False
    try:
        folder.mkdir(parents=True, exist_ok=True)
        text = json.dumps({"format": FORMAT, "digest": digest, "design": _plain(design)})
        fd, tmp = tempfile.mkstemp(dir=folder, prefix=f".{digest[:16]}-", suffix=".tmp")
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                f.write(text)
            os.replace(tmp, folder / f"{digest}.json")
        finally:
            if os.path.exists(tmp):
                os.unlink(tmp)
        return True
    except OSError:
        return False
