"""The fleet at a glance, per robot: its last calibration and recheck, the drift trend, the date
its next recheck is due, and its state. Read by ``station fleet`` and the dashboard alike.

State, from the robot's latest calibration attempt whatever its outcome (issue 39: an ABORTED or
TARGET_MISSED attempt after a good one is not "ok"): ``uncalibrated`` (no calibration attempt),
``failed`` (the latest attempt did not succeed), ``drifted`` (the latest recheck after it failed:
recalibrate), ``overdue`` (the next recheck's date has passed), ``damaged`` (a stored row this
reader cannot take at its word, e.g. an impossible date: shown, never a failed page), ``ok``.
Simulated runs (rehearsals) are none of these unless the plant asks (``include_simulated``); the
latest one is shown beside the state. A robot is *overdue* for ``--overdue`` in all but ``ok``.

Due: the last recheck (or calibration) plus the interval, or earlier where the drift forecast
(ILAC-G24's control chart over the rechecks since the calibration) says the drift may cross its
tolerance before then: the earliest date of the crossing's 95 % interval (``due_from``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from datetime import datetime, timedelta, timezone
from typing import Any

import numpy as np
import psycopg

from station.fleet import store
from station.fleet.drift_forecast import forecast_crossing

__all__ = ["RobotStatus", "STATES", "fleet_status", "drift_trend", "robot_status"]

STATES = ("ok", "overdue", "drifted", "failed", "uncalibrated", "damaged")

#: the fleet's recheck interval where a run names none
DEFAULT_INTERVAL_DAYS = 30
#: the intervals a run may name (schema 4's check): beyond, the row is damaged
INTERVAL_RANGE_DAYS = (1, 3650)
#: the dates a run may carry (schema 4's check): beyond, the row is damaged
PLAUSIBLE_DATES = (datetime(2000, 1, 1, tzinfo=timezone.utc), datetime(2200, 1, 1, tzinfo=timezone.utc))


@dataclass(frozen=True)
class RobotStatus:
    robot_key: str
    serial: str | None
    cell: str
    station: str
    robot_model: str
    last_calibration_utc: str | None  # the latest attempt, whatever its outcome; its figures follow
    last_calibration_outcome: str | None
    gain: float | None
    rms_after_um: float | None
    ap_max_um: float | None
    last_recheck_utc: str | None
    last_recheck_verdict: str | None
    drift_rms_um: float | None
    tolerance_um: float | None
    drift_trend_um_per_30d: float | None  # slope of the drift over the rechecks since the last calibration
    next_recheck_due_utc: str | None
    state: str
    last_good_calibration_utc: str | None = None  # the latest SUCCESS (the same as above when it is the latest)
    last_simulated_utc: str | None = None  # the latest rehearsal on the simulator (never counted unless asked)
    last_simulated_kind: str | None = None
    damaged: str | None = None  # why a stored row could not be read at its word
    # the drift forecast (ILAC-G24 control chart, station.fleet.drift_forecast): when the
    # trend of the rechecks since the calibration reaches the tolerance, and that date's 95 % interval
    drift_crossing_utc: str | None = None
    drift_crossing_earliest_utc: str | None = None
    drift_crossing_latest_utc: str | None = None
    due_from: str | None = None  # what set next_recheck_due_utc: "interval", "forecast" or "drifted"

    @property
    def overdue(self) -> bool:
        return self.state != "ok"

    def to_json(self) -> dict[str, Any]:
        return {**asdict(self), "overdue": self.overdue}


def _ts(v: Any) -> datetime | None:
    """A stored time; None for none and for one Python cannot hold ('infinity', a year beyond
    9999, a BC date: to_jsonb writes them as text fromisoformat refuses)."""
    if v is None:
        return None
    if isinstance(v, datetime):
        return v if v.tzinfo else v.replace(tzinfo=timezone.utc)
    try:
        t = datetime.fromisoformat(str(v).replace("Z", "+00:00"))
    except ValueError:
        return None
    return t if t.tzinfo else t.replace(tzinfo=timezone.utc)


def _iso(v: datetime | None) -> str | None:
    return None if v is None else v.astimezone(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


def drift_trend(rechecks: Sequence[Mapping[str, Any]]) -> float | None:
    """Least-squares slope of the drift RMS over time [µm per 30 days]; None with fewer than 3
    rechecks, all on one day, or figures so large that the sums overflow."""
    pts = [(t.timestamp() / 86400.0, v) for r in rechecks
           if (v := _num(r.get("drift_rms_um"))) is not None and (t := _ts(r.get("finished_utc"))) is not None]
    if len(pts) < 3:
        return None
    mx = sum(p[0] for p in pts) / len(pts)
    my = sum(p[1] for p in pts) / len(pts)
    sxx = sum((p[0] - mx) ** 2 for p in pts)
    if sxx < 1e-6:
        return None
    slope = 30.0 * sum((p[0] - mx) * (p[1] - my) for p in pts) / sxx
    return slope if math.isfinite(slope) else None  # drifts near the largest double overflow the sums


def _unreadable(*runs: Mapping[str, Any] | None) -> str | None:
    """Why one of a robot's latest rows cannot be taken at its word (None: all can)."""
    for run in runs:
        if not run:
            continue
        t = _ts(run.get("finished_utc"))
        if t is None or not PLAUSIBLE_DATES[0] <= t < PLAUSIBLE_DATES[1]:
            return f"run {run.get('run_uuid', '?')}: finished_utc {str(run.get('finished_utc'))[:40]!r} is no date"
        days = run.get("recheck_interval_days")
        if days is not None and not (isinstance(days, int) and INTERVAL_RANGE_DAYS[0] <= days <= INTERVAL_RANGE_DAYS[1]):
            return f"run {run.get('run_uuid', '?')}: recheck_interval_days {str(days)[:20]} is beyond 1 … 3650"
    return None


def _num(v: Any) -> float | None:
    """A stored figure; None for one that is not a finite number (a row written before schema 4)."""
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) else None


def robot_status(row: Mapping[str, Any], rechecks: Sequence[Mapping[str, Any]], now: datetime,
                 default_interval_days: int = DEFAULT_INTERVAL_DAYS) -> RobotStatus:
    """One robot's status from :func:`station.fleet.store.latest_runs`'s row and its rechecks since
    the last good calibration."""
    rows = [row.get(k) if isinstance(row.get(k), Mapping) else None
            for k in ("last_calibration", "last_good_calibration", "last_recheck", "last_simulated")]
    cal, good, rec, sim = rows
    damaged = _unreadable(cal, good, rec)
    latest = max((r for r in (cal, rec) if r), key=lambda r: _ts(r["finished_utc"]) or now, default=None)
    ident = latest or {}
    cal_t, good_t = (_ts(cal["finished_utc"]) if cal else None), (_ts(good["finished_utc"]) if good else None)
    rec_t = _ts(rec["finished_utc"]) if rec else None
    rec_current = rec is not None and cal_t is not None and rec_t is not None and rec_t > cal_t
    interval = (latest or {}).get("recheck_interval_days")
    if damaged or not isinstance(interval, int):
        interval = default_interval_days
    due: datetime | None = None
    due_from: str | None = None
    forecast = forecast_dates(rechecks, cal_t, rec) if rec_current and not damaged and cal_t is not None else None
    if damaged:
        state = "damaged"
    elif cal is None or cal_t is None:
        state = "uncalibrated"
    elif cal.get("outcome") != "SUCCESS":
        state = "failed"  # the figures beside it are this attempt's, not an older good run's
    else:
        last = rec_t if rec_current and rec_t is not None else cal_t
        due, due_from = last + timedelta(days=interval), "interval"
        if forecast is not None and forecast[1] < due:  # the drift may cross before the interval ends
            due, due_from = forecast[1], "forecast"
        if rec_current and rec is not None and rec.get("outcome") != "SUCCESS":
            state, due, due_from = "drifted", rec_t, "drifted"
        else:
            state = "overdue" if due < now else "ok"
    return RobotStatus(
        robot_key=str(row["robot_key"]), serial=_text(ident.get("robot_serial")), cell=str(ident.get("cell", "")),
        station=str(ident.get("station", "")), robot_model=str(ident.get("robot_model", "")),
        last_calibration_utc=_iso(cal_t), last_calibration_outcome=_text(cal.get("outcome")) if cal else None,
        gain=_num((cal or {}).get("gain")), rms_after_um=_num((cal or {}).get("rms_after_um")),
        ap_max_um=_num((cal or {}).get("ap_max_um")),
        last_recheck_utc=_iso(rec_t), last_recheck_verdict=_text(rec.get("outcome")) if rec else None,
        drift_rms_um=_num(rec.get("drift_rms_um")) if rec else None,
        tolerance_um=_num(rec.get("tolerance_um")) if rec else None,
        drift_trend_um_per_30d=drift_trend(rechecks) if rec_current and not damaged else None,
        next_recheck_due_utc=_iso(due), state=state, last_good_calibration_utc=_iso(good_t),
        last_simulated_utc=_iso(_ts(sim.get("finished_utc"))) if sim else None,
        last_simulated_kind=_text(sim.get("kind")) if sim else None, damaged=damaged,
        drift_crossing_utc=_iso(forecast[0]) if forecast else None,
        drift_crossing_earliest_utc=_iso(forecast[1]) if forecast else None,
        drift_crossing_latest_utc=_iso(forecast[2]) if forecast else None, due_from=due_from)


def forecast_dates(rechecks: Sequence[Mapping[str, Any]], cal_t: datetime,
              rec: Mapping[str, Any] | None) -> tuple[datetime, datetime, datetime] | None:
    """The dates the drift trend crosses the latest recheck's tolerance (central, earliest,
    latest at 95 %), from the rechecks since the calibration; None where there is no forecast."""
    tolerance = _num((rec or {}).get("tolerance_um"))
    pts = [((t - cal_t).total_seconds() / 86400.0, v) for r in rechecks
           if (v := _num(r.get("drift_rms_um"))) is not None and (t := _ts(r.get("finished_utc"))) is not None]
    if tolerance is None or not pts:
        return None
    f = forecast_crossing(np.array([p[0] for p in pts]), np.array([p[1] for p in pts]), tolerance)
    if f is None:
        return None
    try:  # a crossing centuries away is no date to show: no forecast
        return cal_t + timedelta(days=f.crossing), cal_t + timedelta(days=f.earliest), cal_t + timedelta(days=f.latest)
    except OverflowError:
        return None


def _text(v: Any) -> str | None:
    return None if v is None else str(v)


def fleet_status(conn: psycopg.Connection, now: datetime | None = None,
                 default_interval_days: int = DEFAULT_INTERVAL_DAYS, *,
                 include_simulated: bool = False) -> list[RobotStatus]:
    """Every robot of the store, in robot-key order (rehearsals counted only with ``include_simulated``)."""
    now = now or datetime.now(timezone.utc)
    out = []
    for row in store.latest_runs(conn, include_simulated=include_simulated):
        cal = row.get("last_calibration")
        since = _ts(cal.get("finished_utc")) if isinstance(cal, Mapping) else None
        rechecks = (store.recent_rechecks(conn, row["robot_key"], since, include_simulated=include_simulated)
                    if row.get("last_recheck") and since else [])
        out.append(robot_status(row, rechecks, now, default_interval_days))
    return out


def history_forecast(runs: Sequence[Mapping[str, Any]]) -> tuple[datetime, datetime, datetime] | None:
    """:func:`forecast_dates` from a robot's history (:func:`station.fleet.store.robot_history`):
    the rechecks after its latest calibration, rehearsals left out, as the fleet table has it."""
    real = [r for r in runs if not r.get("simulated") and _ts(r.get("finished_utc")) is not None]
    cals = [r for r in real if r.get("kind") == "calibration"]
    if not cals or cals[-1].get("outcome") != "SUCCESS":
        return None
    cal_t = _ts(cals[-1]["finished_utc"])
    assert cal_t is not None
    rechecks = [r for r in real if r.get("kind") == "recheck" and (_ts(r["finished_utc"]) or cal_t) > cal_t]
    return forecast_dates(rechecks, cal_t, rechecks[-1]) if rechecks else None
