"""The fleet at a glance, per robot: its last calibration and recheck, the drift trend, the date
its next recheck is due, and its state. Read by ``station fleet`` and the dashboard alike.

State: ``uncalibrated`` (no successful calibration), ``drifted`` (the latest recheck after the
last calibration failed: recalibrate), ``overdue`` (the next recheck's date has passed), ``ok``.
A robot is *overdue* for ``--overdue`` in all but ``ok``: each needs someone to act.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from datetime import datetime, timedelta, timezone
from typing import Any

import psycopg

from station.fleet import store

__all__ = ["RobotStatus", "STATES", "fleet_status", "drift_trend", "robot_status"]

STATES = ("ok", "overdue", "drifted", "uncalibrated")

#: the fleet's recheck interval where a run names none
DEFAULT_INTERVAL_DAYS = 30


@dataclass(frozen=True)
class RobotStatus:
    robot_key: str
    serial: str | None
    cell: str
    station: str
    robot_model: str
    last_calibration_utc: str | None
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

    @property
    def overdue(self) -> bool:
        return self.state != "ok"

    def to_json(self) -> dict[str, Any]:
        return {**asdict(self), "overdue": self.overdue}


def _ts(v: Any) -> datetime | None:
    if v is None:
        return None
    if isinstance(v, datetime):
        return v if v.tzinfo else v.replace(tzinfo=timezone.utc)
    return datetime.fromisoformat(str(v).replace("Z", "+00:00"))


def _iso(v: datetime | None) -> str | None:
    return None if v is None else v.astimezone(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


def drift_trend(rechecks: Sequence[Mapping[str, Any]]) -> float | None:
    """Least-squares slope of the drift RMS over time [µm per 30 days]; None with fewer than 3
    rechecks or all on one day."""
    pts = [(t.timestamp() / 86400.0, float(r["drift_rms_um"])) for r in rechecks
           if r.get("drift_rms_um") is not None and (t := _ts(r.get("finished_utc"))) is not None]
    if len(pts) < 3:
        return None
    mx = sum(p[0] for p in pts) / len(pts)
    my = sum(p[1] for p in pts) / len(pts)
    sxx = sum((p[0] - mx) ** 2 for p in pts)
    if sxx < 1e-6:
        return None
    return 30.0 * sum((p[0] - mx) * (p[1] - my) for p in pts) / sxx


def robot_status(row: Mapping[str, Any], rechecks: Sequence[Mapping[str, Any]], now: datetime,
                 default_interval_days: int = DEFAULT_INTERVAL_DAYS) -> RobotStatus:
    """One robot's status from :func:`station.fleet.store.latest_runs`'s row and its rechecks since
    the last good calibration."""
    cal, good, rec = row.get("last_calibration"), row.get("last_good_calibration"), row.get("last_recheck")
    latest = max((r for r in (cal, rec) if r), key=lambda r: _ts(r["finished_utc"]) or now, default=None)
    ident = latest or {}
    good_t = _ts(good["finished_utc"]) if good else None
    rec_t = _ts(rec["finished_utc"]) if rec else None
    rec_current = rec is not None and good_t is not None and rec_t is not None and rec_t > good_t
    interval = int((latest or {}).get("recheck_interval_days") or default_interval_days)
    due: datetime | None
    if good_t is None:
        state, due = "uncalibrated", None
    else:
        last = max(good_t, rec_t) if rec_current and rec_t is not None else good_t
        due = last + timedelta(days=interval)
        if rec_current and rec is not None and rec["outcome"] != "SUCCESS":
            state, due = "drifted", rec_t
        elif due < now:
            state = "overdue"
        else:
            state = "ok"
    return RobotStatus(
        robot_key=str(row["robot_key"]), serial=ident.get("robot_serial"), cell=str(ident.get("cell", "")),
        station=str(ident.get("station", "")), robot_model=str(ident.get("robot_model", "")),
        last_calibration_utc=_iso(_ts(cal["finished_utc"])) if cal else None,
        last_calibration_outcome=cal["outcome"] if cal else None,
        gain=(good or {}).get("gain"), rms_after_um=(good or {}).get("rms_after_um"),
        ap_max_um=(good or {}).get("ap_max_um"),
        last_recheck_utc=_iso(rec_t), last_recheck_verdict=rec["outcome"] if rec else None,
        drift_rms_um=rec.get("drift_rms_um") if rec else None, tolerance_um=rec.get("tolerance_um") if rec else None,
        drift_trend_um_per_30d=drift_trend(rechecks) if rec_current else None,
        next_recheck_due_utc=_iso(due), state=state)


def fleet_status(conn: psycopg.Connection, now: datetime | None = None,
                 default_interval_days: int = DEFAULT_INTERVAL_DAYS) -> list[RobotStatus]:
    """Every robot of the store, in robot-key order."""
    now = now or datetime.now(timezone.utc)
    out = []
    for row in store.latest_runs(conn):
        good = row.get("last_good_calibration")
        since = good["finished_utc"] if good else None
        rechecks = store.recent_rechecks(conn, row["robot_key"], since) if row.get("last_recheck") and good else []
        out.append(robot_status(row, rechecks, now, default_interval_days))
    return out
