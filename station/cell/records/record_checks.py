"""Checks of what the run database gives back: every stored plan, step, result and table is
validated when it is read, so a damaged record (edited by hand, half-restored, written by a
foreign tool) is a :class:`DamagedRecordError` (exit 5) that names the run and the record, never a
``JSONDecodeError`` or an ``IndexError`` deep in the numerics. This module does no I/O.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any, TypeVar

import numpy as np

from station.cell.records.run_records import MeasurementRecord, RunDatabaseError, RunRecord, _loads

T = TypeVar("T")

#: what to do about a damaged record of a run: the run's other records cannot be trusted either
_ADVICE = "keep the database file for inspection and start a new run (or restore a backup)"

#: the columns each table must have (the station's schema, docs/run-database.md)
TABLE_COLUMNS: dict[str, tuple[str, ...]] = {
    "schema_version": ("version",),
    "runs": ("id", "created_utc", "station_version", "status", "config_toml", "plan_json", "seed", "note"),
    "measurements": ("run_id", "step_index", "kind", "point_id", "label", "joints_commanded", "joints_read",
                     "raw_frames", "readings_mm", "channel_status", "pose", "pose_residual_um", "ok", "message",
                     "t_utc"),
    "results": ("run_id", "key", "json", "t_utc"),
    "events": ("id", "run_id", "t_utc", "level", "message"),
}

#: the JSON type each result the station stores must have when read back
_RESULT_TYPES: dict[str, type] = {
    "summary": dict, "identification": dict, "fingerprint": dict, "devices": dict, "recheck": dict,
    "recheck_baseline": dict, "warmup": dict, "articulated": dict, "table_at_start": dict, "config_source": str,
}


class DamagedRecordError(RunDatabaseError):
    """A record of the run database does not hold what the station stored there."""


def damaged(run_id: int | None, record: str, why: str) -> DamagedRecordError:
    where = f"run {run_id}: " if run_id is not None else ""
    return DamagedRecordError(f"{where}the stored {record} is damaged ({why}); {_ADVICE}")


def damaged_field(run_id: int | None, table: str, row: str, field: str, why: str,
                  advice: str = _ADVICE) -> DamagedRecordError:
    """A damaged field: the message names the run, the table, the row and the field."""
    where = f"run {run_id}: " if run_id is not None else ""
    return DamagedRecordError(f"{where}the stored record is damaged: table {table}, row {row}, field {field}: "
                              f"{why}; {advice}")


def check_columns(path: object, table: str, have: Sequence[str]) -> None:
    """Refuse a table that lacks a column the station reads."""
    missing = [c for c in TABLE_COLUMNS[table] if c not in have]
    if missing:
        raise DamagedRecordError(
            f"{path}: the {table} table lacks the station's columns {', '.join(missing)} (it has "
            f"{', '.join(have) or 'none'}); the file is damaged or not written by the station: keep it for "
            f"inspection and restore a backup, or give another --db")


def parse_json(text: object, run_id: int | None, record: str) -> Any:
    """A stored JSON text, NaN/±inf tags restored."""
    if not isinstance(text, str):
        raise damaged(run_id, record, f"a {type(text).__name__} where JSON text belongs")
    try:
        return _loads(text)
    except (ValueError, RecursionError) as exc:  # JSONDecodeError is a ValueError
        raise damaged(run_id, record, f"not JSON: {str(exc)[:80]}") from None
    except (KeyError, TypeError) as exc:  # a malformed {"__float__": ...} tag
        raise damaged(run_id, record, f"a bad non-finite float tag {exc}") from None


def check_plan(plan: object, run_id: int) -> tuple[dict, ...]:
    """The stored plan: a list of step objects, each with its index in place."""
    if not isinstance(plan, list) or not all(isinstance(s, dict) for s in plan):
        raise damaged(run_id, "plan", f"a {type(plan).__name__} where a list of step objects belongs")
    for i, step in enumerate(plan):
        if "index" in step and step["index"] != i:
            raise damaged(run_id, f"plan step {i}", f"it says it is step {step['index']!r}")
    return tuple(plan)


def check_step_joints(plan: Sequence[Mapping[str, Any]], run_id: int, n_joints: int | None) -> None:
    """Every planned step names one finite number per joint of the robot (``n_joints``; None: as
    many as the first step)."""
    for i, step in enumerate(plan):
        q = step.get("joints")
        if not isinstance(q, list) or not all(_is_number(v) for v in q):
            raise damaged(run_id, f"plan step {i}", "its joints are not a list of finite numbers")
        if n_joints is None:
            n_joints = len(q)
        if len(q) != n_joints:
            raise damaged(run_id, f"plan step {i}", f"{len(q)} joints for a robot with {n_joints}")


def check_against_plan(records: Sequence[MeasurementRecord], plan: Sequence[Mapping[str, Any]],
                       run_id: int) -> None:
    """Each measurement belongs to a step of the stored plan and has that step's joint count: a
    plan emptied or shortened under its measurements, or joints of another robot, is damage."""
    for r in records:
        what = f"measurement of step {r.step_index}"
        if not 0 <= r.step_index < len(plan):
            raise damaged(run_id, what, f"the stored plan has {len(plan)} steps")
        n = len(plan[r.step_index].get("joints") or ())
        for name, q in (("joints commanded", r.joints_commanded), ("joints read", r.joints_read)):
            if q is not None and n and (q.ndim != 1 or q.shape[0] != n):
                raise damaged(run_id, f"{what} ({name})", f"{q.size} values for a step of {n} joints")


def check_result(value: Any, run_id: int, key: str) -> Any:
    """A stored result of a key the station knows must have the type the station wrote."""
    want = _RESULT_TYPES.get(key)
    if want is not None and value is not None and not isinstance(value, want):
        raise damaged(run_id, f"result {key!r}", f"a JSON {type(value).__name__} where an "
                                                  f"{'object' if want is dict else 'string'} belongs")
    return value


def array(text: object, run_id: int, record: str, ndim: int = 1, required: bool = False) -> np.ndarray | None:
    """A stored JSON array of numbers (null: NaN), read-only; ``ndim`` 2 is a 4x4 pose."""
    if text is None:
        if required:
            raise damaged(run_id, record, "missing")
        return None
    data = parse_json(text, run_id, record)
    try:
        if ndim == 1:
            a = np.array([np.nan if v is None else _number(v) for v in data], dtype=float)
        else:
            a = np.array([[np.nan if v is None else _number(v) for v in row] for row in data], dtype=float)
    except (TypeError, ValueError) as exc:
        raise damaged(run_id, record, f"not an array of numbers ({exc})") from None
    if a.ndim != ndim or (ndim == 2 and a.shape != (4, 4)):
        raise damaged(run_id, record, f"an array of shape {a.shape}")
    a.setflags(write=False)
    return a


def run_record(row: tuple) -> RunRecord:
    """A row of ``runs`` (its columns in :data:`TABLE_COLUMNS` order), checked."""
    rid, created, version, status, config, plan_json, seed, note = row
    plan = check_plan(parse_json(plan_json, rid, "plan"), rid)
    if seed is not None and not (isinstance(seed, (str, int)) and str(seed).isascii() and str(seed).isdigit()
                                 and len(str(seed)) <= 100):
        raise damaged_field(rid, "runs", f"run {rid}", "seed", f"{str(seed)[:40]!r} is not a seed (a whole number "
                                                              f"≥ 0 of at most 100 digits)")
    return checked(rid, "run record", lambda: RunRecord(
        id=rid, created_utc=str(created), station_version=str(version), status=str(status),
        config_toml=str(config), plan=plan, seed=None if seed is None else int(seed), note=str(note)))


def measurement_record(r: tuple) -> MeasurementRecord:
    """A row of ``measurements`` (its columns in :data:`TABLE_COLUMNS` order), checked."""
    (run_id, step, kind, point_id, label, jc, jr, raw, rd, cs, pose, res, ok, msg, t) = r
    what = f"measurement of step {step}"
    if not isinstance(raw, (bytes, bytearray, memoryview)):  # bytes(5) would be five zero bytes
        raise damaged_field(run_id, "measurements", f"step {step}", "raw_frames",
                            f"a {type(raw).__name__} where the probe's frames (bytes) belong")
    status = None if cs is None else parse_json(cs, run_id, f"{what} (channel status)")
    if status is not None and not isinstance(status, list):
        raise damaged(run_id, f"{what} (channel status)", "not a list")
    return checked(run_id, what, lambda: MeasurementRecord(
        run_id=run_id, step_index=int(step), kind=str(kind), point_id=str(point_id), label=str(label),
        joints_commanded=_required(array(jc, run_id, f"{what} (joints commanded)", required=True)),
        joints_read=array(jr, run_id, f"{what} (joints read)"),
        raw_frames=bytes(raw), readings_mm=array(rd, run_id, f"{what} (readings)"),
        channel_status=None if status is None else tuple(status),
        pose=array(pose, run_id, f"{what} (pose)", ndim=2),
        pose_residual_um=None if res is None else float(res), ok=bool(ok), message=str(msg), t_utc=str(t)))


def checked(run_id: int, record: str, build: Callable[..., T], *args: Any) -> T:
    """``build(*args)``, its data errors turned into :class:`DamagedRecordError`."""
    try:
        return build(*args)
    except (KeyError, TypeError, ValueError, AttributeError, IndexError) as exc:
        raise damaged(run_id, record, f"{type(exc).__name__}: {str(exc)[:80]}") from None


def _required(a: np.ndarray | None) -> np.ndarray:
    assert a is not None  # array(required=True) raised for a missing one
    return a


def _is_number(v: object) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _number(v: object) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise TypeError(f"{v!r} is not a number")
    return float(v)
