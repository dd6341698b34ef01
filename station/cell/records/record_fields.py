"""Field by field checks of the run database's records, applied where :class:`RunDB` reads them
(issue 33): every measurement field the station uses (kind, point, channel count and status, finite
and plausible values, time stamps, joint ranges against the run's robot), the stored results the
station reads back (re-centring, tools, identification, baseline) and the run-lock rows. A damaged
field is a :class:`DamagedRecordError` (exit 5) naming the run, the table, the row and the field.
This module does no I/O.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import datetime
from typing import Any

import numpy as np

from station.cell.plan.steps import MEASUREMENT_KINDS
from station.cell.records.record_checks import DamagedRecordError, damaged_field
from station.cell.records.run_records import MeasurementRecord

#: SQLite's integers (run ids, step indices) are 64-bit
MAX_SQL_INT = 2**63 - 1
#: the largest PID a Linux or Windows host hands out (Linux: 2^22; Windows: 32-bit)
MAX_PID = 2**32 - 1
#: a joint value beyond this is no robot's (100 m for a prismatic joint in mm; 2π·10 rad is far below)
JOINT_BOUND = 100_000.0
#: a probe reading beyond this cannot come from the interface (it sends at most ±999.9999 mm)
READING_BOUND_MM = 1000.0
#: a measured pose's translation beyond this (mm) is not in any cell
POSE_BOUND_MM = 100_000.0
#: the channel statuses the probe driver reports (drivers.probe_protocol.ChannelStatus)
CHANNEL_STATUSES = ("ok", "over_range", "under_range", "invalid")
#: the time stamps the station writes (run_records.utc_now)
_T_UTC = re.compile(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d(\.\d{1,9})?Z\Z")


@dataclass(frozen=True)
class RunContext:
    """What the run's stored configuration says about its records: the robot's joint count and
    range (a margin beyond the soft limits), the body's point ids and the probe head's probes. Any
    field None where the configuration does not read (its robot file moved)."""

    n_joints: int | None = None
    joint_lo: tuple[float, ...] | None = None
    joint_hi: tuple[float, ...] | None = None
    point_ids: tuple[str, ...] | None = None
    n_probes: int | None = None


def run_id_param(value: object, what: str = "run number") -> int:
    """A run id (or step index) before it reaches SQLite: an integer in 1 … 2^63−1."""
    from station.cell.records.run_records import RunNotFoundError

    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 1 <= int(value) <= MAX_SQL_INT:
        raise RunNotFoundError(f"{value!r} is not a {what} (a whole number 1 … {MAX_SQL_INT}); check the run "
                               f"number ('station runs' lists them)")
    return int(value)


# ----------------------------------------------------------------------------------- measurements

def check_measurement(m: MeasurementRecord, step: Mapping[str, Any] | None, ctx: RunContext | None) -> None:
    """Every field of one stored measurement, against its planned step and the run's context."""
    def bad(field: str, why: str) -> DamagedRecordError:
        return damaged_field(m.run_id, "measurements", f"step {m.step_index}", field, why)

    if m.kind not in MEASUREMENT_KINDS:
        raise bad("kind", f"{m.kind[:40]!r} is not a measurement kind ({', '.join(MEASUREMENT_KINDS)})")
    if step is not None:
        if "kind" in step and step["kind"] != m.kind:
            raise bad("kind", f"{m.kind!r}, but the plan's step {m.step_index} is {step['kind']!r}")
        if "point_id" in step and step["point_id"] != m.point_id:
            raise bad("point_id", f"{m.point_id[:40]!r}, but the plan's step {m.step_index} measures "
                                  f"{str(step['point_id'])[:40]!r}")
    if ctx is not None and ctx.point_ids is not None and m.point_id not in ctx.point_ids:
        raise bad("point_id", f"{m.point_id[:40]!r} is no point of the run's body")
    if not _T_UTC.match(m.t_utc) or _timestamp(m.t_utc) is None:
        raise bad("t_utc", f"{m.t_utc[:40]!r} is not a UTC time stamp YYYY-MM-DDTHH:MM:SS.ffffffZ")
    for field, q, nan_ok in (("joints_commanded", m.joints_commanded, False), ("joints_read", m.joints_read, True)):
        if q is not None:
            _check_joints(q, ctx, field, nan_ok, bad)
    _check_channels(m, ctx, bad)
    if m.pose is not None:
        p = m.pose
        if not np.all(np.isfinite(p)):
            raise bad("pose", "not finite")
        if not np.allclose(p[3], (0.0, 0.0, 0.0, 1.0)) or not np.allclose(p[:3, :3] @ p[:3, :3].T, np.eye(3), atol=1e-6):
            raise bad("pose", "not a rigid transformation (its rotation is not orthonormal, or its last row is not "
                              "0 0 0 1)")
        if np.max(np.abs(p[:3, 3])) > POSE_BOUND_MM:
            raise bad("pose", f"a position beyond ±{POSE_BOUND_MM:g} mm")
    if m.pose_residual_um is not None and not (math.isfinite(m.pose_residual_um) and m.pose_residual_um >= 0):
        raise bad("pose_residual_um", f"{m.pose_residual_um!r} is not a finite residual ≥ 0")


def _check_joints(q: np.ndarray, ctx: RunContext | None, field: str, nan_ok: bool, bad: Any) -> None:
    if np.any(np.isnan(q)) and not nan_ok or np.any(np.isinf(q)):
        raise bad(field, "not finite")
    v = np.where(np.isnan(q), 0.0, q)
    if np.max(np.abs(v), initial=0.0) > JOINT_BOUND:
        raise bad(field, f"a joint beyond ±{JOINT_BOUND:g} (no robot's)")
    if ctx is None or ctx.joint_lo is None or ctx.joint_hi is None or len(ctx.joint_lo) != q.size:
        return
    for i, (x, lo, hi) in enumerate(zip(v, ctx.joint_lo, ctx.joint_hi)):
        if not lo <= x <= hi:
            raise bad(field, f"joint {i + 1} = {x:.6g} outside the robot's range {lo:.6g} … {hi:.6g}")


def _check_channels(m: MeasurementRecord, ctx: RunContext | None, bad: Any) -> None:
    status, rd = m.channel_status, m.readings_mm
    if status is not None:
        junk = [s for s in status if s not in CHANNEL_STATUSES]
        if junk:
            raise bad("channel_status", f"{str(junk[0])[:40]!r} is not a channel status "
                                        f"({', '.join(CHANNEL_STATUSES)})")
    if rd is None:
        if status is not None:
            raise bad("readings_mm", f"missing beside {len(status)} channel statuses")
        return
    if np.any(np.isinf(rd)) or np.nanmax(np.abs(rd), initial=0.0) > READING_BOUND_MM:
        raise bad("readings_mm", f"a reading beyond ±{READING_BOUND_MM:g} mm (the probe interface sends at most "
                                 f"±999.9999)")
    if status is not None and len(status) != rd.size:
        raise bad("channel_status", f"{len(status)} statuses for {rd.size} readings")
    if ctx is not None and ctx.n_probes is not None and rd.size != ctx.n_probes:
        raise bad("readings_mm", f"{rd.size} readings for a head of {ctx.n_probes} probes")


def check_measurements(records: Sequence[MeasurementRecord], plan: Sequence[Mapping[str, Any]],
                       ctx: RunContext | None) -> None:
    """Every measurement of a run (each against its planned step), and the run's channel count: one
    head, one count, whatever the configuration says."""
    for m in records:
        check_measurement(m, plan[m.step_index] if 0 <= m.step_index < len(plan) else None, ctx)
    check_channel_count(records)


def check_channel_count(records: Sequence[MeasurementRecord]) -> None:
    """One head, one channel count: over all of a run's records (also those checked before)."""
    counts: dict[int, int] = {}
    for m in records:
        if m.readings_mm is not None:
            counts.setdefault(m.readings_mm.size, m.step_index)
    if len(counts) > 1:
        (n0, s0), (n1, s1) = sorted(counts.items(), key=lambda kv: kv[1])[:2]
        raise damaged_field(records[0].run_id, "measurements", f"step {s1}", "readings_mm",
                            f"{n1} readings where step {s0} has {n0}: one head, one channel count")


def check_plan_against(plan: Sequence[Mapping[str, Any]], run_id: int, ctx: RunContext) -> None:
    """The stored plan's points and joints against the run's robot and body."""
    for i, step in enumerate(plan):
        pid = step.get("point_id")
        if ctx.point_ids is not None and pid is not None and pid not in ctx.point_ids:
            raise damaged_field(run_id, "runs", f"run {run_id}", f"plan_json step {i} point_id",
                                f"{str(pid)[:40]!r} is no point of the run's body")
        q = step.get("joints")
        if ctx.joint_lo is None or ctx.joint_hi is None or not isinstance(q, list) or len(q) != len(ctx.joint_lo):
            continue
        for j, (x, lo, hi) in enumerate(zip(q, ctx.joint_lo, ctx.joint_hi)):
            if isinstance(x, (int, float)) and not lo <= x <= hi:
                raise damaged_field(run_id, "runs", f"run {run_id}", f"plan_json step {i} joints",
                                    f"joint {j + 1} = {x:.6g} outside the robot's range {lo:.6g} … {hi:.6g}")


def _timestamp(text: str) -> datetime | None:
    try:
        return datetime.fromisoformat(text[:-1][:26])
    except ValueError:
        return None


# ---------------------------------------------------------------------------------------- results

def check_result_fields(value: Any, run_id: int, key: str, n_steps: int) -> None:
    """The structure of the stored results the station reads back field by field."""
    def bad(field: str, why: str) -> DamagedRecordError:
        return damaged_field(run_id, "results", f"key {key!r}", field, why)

    if key == "recentring":
        if not isinstance(value, dict):
            raise bad("json", f"a JSON {_json_type(value)} where an object of displacements by step belongs")
        for k, d in value.items():
            if not (k.isdigit() and int(k) < n_steps):
                raise bad(f"json[{k[:20]!r}]", f"not a step of the run's plan of {n_steps} steps")
            if not _numbers(d, 6):
                raise bad(f"json[{k!r}]", "not a displacement of six finite numbers (x, y, z, roll, pitch, yaw)")
    elif key == "identification" and value is not None:
        if not isinstance(value, dict) or not _numbers(value.get("params")):
            raise bad("json.params", "not a list of finite parameters")
    elif key == "error_model" and value is not None:
        _check_error_model(value, bad)
    elif key == "recheck_baseline" and value is not None:
        rid = value.get("run_id") if isinstance(value, dict) else None
        if isinstance(rid, bool) or not isinstance(rid, int) or not 1 <= rid <= MAX_SQL_INT:
            raise bad("json.run_id", f"{str(rid)[:40]} is not a run number")
    elif key.startswith("tool:"):  # the station stores an object, also for a tool that failed
        _check_tool(value, bad)


def _check_error_model(value: Any, bad: Any) -> None:
    """The fields a recheck rebuilds the baseline's terms from (pipeline_terms.stored_error_model)."""
    if not isinstance(value, dict):
        raise bad("json", f"a JSON {_json_type(value)} where an object belongs")
    chosen = value.get("chosen")
    if not isinstance(chosen, list) or not all(isinstance(c, str) for c in chosen):
        raise bad("json.chosen", "not a list of term families")
    if not _numbers(value.get("params")):
        raise bad("json.params", "not a list of finite parameters")
    terms = value.get("terms")
    if not isinstance(terms, list):
        raise bad("json.terms", "not a list")
    for i, t in enumerate(terms):
        if not isinstance(t, dict) or not isinstance(t.get("name"), str) or not _numbers([t.get("value")], 1):
            raise bad(f"json.terms[{i}]", "not a term with a name and a finite value")
    g = value.get("gravity")
    if g is not None and (not isinstance(g, dict) or not _numbers(g.get("gravity"), 3)
                          or (g.get("masses") is not None and not _numbers(g.get("masses")))):
        raise bad("json.gravity", "not a gravity model (a finite gravity vector, masses a list of numbers or null)")
    ratios = value.get("gear_ratios")
    if ratios is not None and not _numbers(ratios):
        raise bad("json.gear_ratios", "not a list of finite numbers")


def _check_tool(value: Any, bad: Any) -> None:
    if not isinstance(value, dict):
        raise bad("json", f"a JSON {_json_type(value)} where an object belongs")
    if "error" in value:
        if not isinstance(value["error"], str):
            raise bad("json.error", "not a text")
        return
    for field in ("tool_params_identified", "tool_params_nominal"):
        if not _numbers(value.get(field)):
            raise bad(f"json.{field}", "not a list of finite numbers")
    if not isinstance(value.get("summary", {}), dict):
        raise bad("json.summary", f"a JSON {_json_type(value['summary'])} where an object belongs")
    for field in ("targets", "tcp_mm_deg"):
        if field in value and not isinstance(value[field], list):
            raise bad(f"json.{field}", "not a list")


def _numbers(v: Any, n: int | None = None) -> bool:
    return (isinstance(v, list) and (n is None or len(v) == n) and bool(v)
            and all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v))


def _json_type(v: Any) -> str:
    return {dict: "object", list: "list", str: "string", bool: "boolean", type(None): "null"}.get(type(v), "number")


# -------------------------------------------------------------------------------------- lock rows

def check_lock_row(row: Sequence[Any]) -> tuple[int, str, int, str, str, str]:
    """A row of ``run_locks`` (run_id, host, pid, pid_start, since_utc, token), checked."""
    run_id, host, pid, start, since, token = row
    rid = run_id if isinstance(run_id, int) else None

    def bad(field: str, why: str) -> DamagedRecordError:
        return damaged_field(rid, "run_locks", f"run {run_id}", field, why,
                             advice=f"if no station works on run {run_id}, clear the lock with 'station runs --unlock "
                                    f"{run_id}' (and --db) and resume again")

    if isinstance(pid, bool) or not isinstance(pid, int) or not 1 <= pid <= MAX_PID:
        raise bad("pid", f"{str(pid)[:40]!r} is not a process id (1 … {MAX_PID})")
    for field, v in (("host", host), ("pid_start", start), ("since_utc", since), ("token", token)):
        if not isinstance(v, str):
            raise bad(field, f"a {_json_type(v)} where a text belongs")
    if not host or not token:
        raise bad("host" if not host else "token", "empty")
    return int(run_id), host, pid, start, since, token
