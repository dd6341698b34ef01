"""What the run database stores: its SQL schema and, as Python values, its records, its errors, and the JSON
conversions of arrays and results (NaN and infinities kept). :mod:`station.cell.records.rundb` is the
database itself; this module does no I/O.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass
from datetime import datetime, timezone
from typing import Any

import numpy as np

from station.errors import Outcome, StationError

# --------------------------------------------------------------------------------------- schema

SCHEMA_VERSION = 1

RUN_STATUSES = ("created", "measuring", "measured", "identified", "uploaded", "verified",
                "failed", "aborted")
EVENT_LEVELS = ("debug", "info", "warning", "error")

_SCHEMA = """
CREATE TABLE schema_version (
    version     INTEGER NOT NULL
);
CREATE TABLE runs (
    id              INTEGER PRIMARY KEY AUTOINCREMENT,
    created_utc     TEXT NOT NULL,
    station_version TEXT NOT NULL,
    status          TEXT NOT NULL CHECK (status IN ({statuses})),
    config_toml     TEXT NOT NULL,
    plan_json       TEXT NOT NULL,
    seed            TEXT,               -- decimal integer as TEXT: seeds may exceed 64 bit
    note            TEXT NOT NULL DEFAULT ''
);
CREATE TABLE measurements (
    run_id           INTEGER NOT NULL REFERENCES runs(id) ON DELETE CASCADE,
    step_index       INTEGER NOT NULL CHECK (step_index >= 0),
    kind             TEXT NOT NULL,
    point_id         TEXT NOT NULL DEFAULT '',
    label            TEXT NOT NULL DEFAULT '',
    joints_commanded TEXT NOT NULL,     -- JSON list, rad | mm
    joints_read      TEXT,              -- JSON list or NULL, rad | mm
    raw_frames       BLOB NOT NULL,
    readings_mm      TEXT,              -- JSON list, NaN as null
    channel_status   TEXT,              -- JSON list
    pose             TEXT,              -- JSON 4x4 nested list or NULL
    pose_residual_um REAL,
    ok               INTEGER NOT NULL CHECK (ok IN (0, 1)),
    message          TEXT NOT NULL DEFAULT '',
    t_utc            TEXT NOT NULL,
    UNIQUE (run_id, step_index)
);
CREATE TABLE results (
    run_id  INTEGER NOT NULL REFERENCES runs(id) ON DELETE CASCADE,
    key     TEXT NOT NULL,
    json    TEXT NOT NULL,
    t_utc   TEXT NOT NULL,
    UNIQUE (run_id, key)
);
CREATE TABLE events (
    id      INTEGER PRIMARY KEY AUTOINCREMENT,
    run_id  INTEGER REFERENCES runs(id) ON DELETE CASCADE,
    t_utc   TEXT NOT NULL,
    level   TEXT NOT NULL,
    message TEXT NOT NULL
);
CREATE INDEX events_run ON events(run_id, id);
""".format(statuses=", ".join(f"'{s}'" for s in RUN_STATUSES))

_TABLES = {"schema_version", "runs", "measurements", "results", "events"}


# --------------------------------------------------------------------------------------- errors

class RunDatabaseError(StationError):
    """The run database cannot be opened or the requested operation is not consistent with it."""

    outcome = Outcome.DATABASE_ERROR


class SchemaVersionError(RunDatabaseError):
    """The database file was written with a schema this station does not know."""


class RunNotFoundError(RunDatabaseError, KeyError):
    """No run with the requested id."""

    def __str__(self) -> str:  # KeyError would repr() the message
        return str(self.args[0]) if self.args else ""


class DuplicateMeasurementError(RunDatabaseError):
    """A measurement for this (run, step) is already stored."""


# -------------------------------------------------------------------------------------- records

@dataclass(frozen=True)
class RunRecord:
    """One run. ``plan`` is the measurement plan as stored (a tuple of step dicts)."""

    id: int
    created_utc: str
    station_version: str
    status: str
    config_toml: str
    plan: tuple
    seed: int | None
    note: str

    @property
    def n_steps(self) -> int:
        return len(self.plan)


@dataclass(frozen=True, eq=False)
class MeasurementRecord:
    """One stored measurement. Arrays are read-only float64 arrays; NaN marks a missing value.

    ``eq=False``: records hold numpy arrays, so they compare by identity; compare fields instead.
    The field names equal the keyword arguments of :meth:`RunDB.record_measurement`, so a record
    can be written again with ``db.record_measurement(**dataclasses.asdict(rec))``.
    """

    run_id: int
    step_index: int
    kind: str
    point_id: str
    label: str
    joints_commanded: np.ndarray          # (g,) rad | mm
    joints_read: np.ndarray | None        # (g,) rad | mm, None when the controller gave none
    raw_frames: bytes                     # probe frames exactly as received
    readings_mm: np.ndarray | None        # (n_channels,) mm, NaN where a channel gave no value
    channel_status: tuple | None          # one entry per channel, as the driver reported it
    pose: np.ndarray | None               # (4, 4) measured pose of MPKS in MKKS, mm
    pose_residual_um: float | None
    ok: bool
    message: str
    t_utc: str


@dataclass(frozen=True)
class EventRecord:
    """One entry of a run's audit trail."""

    run_id: int
    t_utc: str
    level: str
    message: str



# ------------------------------------------------------------------------------------- helpers

def utc_now() -> str:
    """Current UTC time as ``YYYY-MM-DDTHH:MM:SS.ffffffZ``."""
    return datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%S.%fZ")


def _station_version() -> str:
    from importlib import metadata
    try:
        return metadata.version("calibration-station")
    except metadata.PackageNotFoundError:
        return "unknown"


def _float_list(values: Any, what: str, ndim: int = 1) -> list | None:
    """Array-like of numbers -> nested list of floats with NaN/±inf as None (JSON null)."""
    if values is None:
        return None
    try:
        a = np.asarray(values, dtype=float)
    except (TypeError, ValueError) as e:
        raise RunDatabaseError(f"{what}: not an array of numbers ({e}); pass a list or numpy "
                               f"array of floats") from e
    if a.ndim != ndim:
        raise RunDatabaseError(f"{what}: expected a {ndim}-D array, got shape {a.shape}")
    return _nan_to_none(a)


def _nan_to_none(a: np.ndarray) -> list:
    if a.ndim == 1:
        return [float(v) if math.isfinite(v) else None for v in a.tolist()]
    return [_nan_to_none(row) for row in a]


def _array_from_json(text: str | None, ndim: int = 1) -> np.ndarray | None:
    if text is None:
        return None
    data = json.loads(text)
    if ndim == 1:
        a = np.array([np.nan if v is None else v for v in data], dtype=float)
    else:
        a = np.array([[np.nan if v is None else v for v in row] for row in data], dtype=float)
    a.setflags(write=False)
    return a


def _required_array(text: str) -> np.ndarray:
    """A NOT NULL array column."""
    a = _array_from_json(text)
    assert a is not None  # the schema refuses NULL here
    return a


_FLOAT_TAG = "__float__"
_NONFINITE = {"nan": math.nan, "inf": math.inf, "-inf": -math.inf}


def _to_json_value(obj: Any, where: str = "value") -> Any:
    """Python/numpy object -> JSON-able object; non-finite floats become ``{"__float__": "nan"}``."""
    if obj is None or isinstance(obj, (bool, str)):
        return obj
    if isinstance(obj, (np.bool_,)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        f = float(obj)
        if math.isfinite(f):
            return f
        return {_FLOAT_TAG: "nan" if math.isnan(f) else ("inf" if f > 0 else "-inf")}
    if isinstance(obj, np.ndarray):
        if obj.dtype.kind not in "biuf":
            raise RunDatabaseError(f"{where}: numpy array of dtype {obj.dtype} cannot be stored; "
                                   f"convert it to numbers or a list of strings")
        return _to_json_value(obj.tolist(), where)
    if isinstance(obj, dict):
        out = {}
        for k, v in obj.items():
            if not isinstance(k, str):
                raise RunDatabaseError(f"{where}: dict key {k!r} is not a string; JSON objects "
                                       f"need string keys, convert it with str()")
            if k == _FLOAT_TAG:
                raise RunDatabaseError(f"{where}: the key {_FLOAT_TAG!r} is reserved for "
                                       f"non-finite floats; rename it")
            out[k] = _to_json_value(v, f"{where}[{k!r}]")
        return out
    if isinstance(obj, (list, tuple)):
        return [_to_json_value(v, f"{where}[{i}]") for i, v in enumerate(obj)]
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return _to_json_value({f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)},
                              where)
    raise RunDatabaseError(f"{where}: a {type(obj).__name__} cannot be stored as JSON; convert it "
                           f"to dicts, lists, numbers, strings or numpy arrays first")


def _restore_tag(obj: dict) -> Any:
    """``json.loads``'s object hook: a ``{"__float__": ...}`` tag back to its float (the decoder
    calls it for every object, innermost first, so no second walk over the parsed value is needed:
    that walk was 1.6 M Python calls in one simulated calibration)."""
    if len(obj) == 1 and _FLOAT_TAG in obj:
        return _NONFINITE[obj[_FLOAT_TAG]]
    return obj


def _dumps(obj: Any, where: str) -> str:
    return json.dumps(_to_json_value(obj, where), allow_nan=False, separators=(",", ":"))


def _loads(text: str) -> Any:
    """A stored JSON text, NaN/±inf tags restored (KeyError/TypeError for a malformed tag)."""
    return json.loads(text, object_hook=_restore_tag)


def _num(v: float | None) -> str:
    """CSV cell: shortest repr that round-trips; '' for missing, 'nan'/'inf' for non-finite."""
    if v is None:
        return ""
    return repr(float(v))
