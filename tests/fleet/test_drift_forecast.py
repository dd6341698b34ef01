"""The drift forecast (ILAC-G24's control-chart method) on simulated drift histories: the stated
95 % interval covers the true crossing about 95 % of the time; no forecast without a significant
upward trend."""

from __future__ import annotations

import math
from datetime import datetime, timedelta, timezone

import numpy as np
import pytest

from station.fleet.drift_forecast import forecast_crossing


def _history(rng: np.random.Generator, n: int, slope: float, noise: float, offset: float = 3.0):
    t = np.sort(rng.uniform(5.0, 120.0, n))  # rechecks within 4 months of the calibration [days]
    return t, offset + slope * t + rng.normal(0.0, noise, n)


def test_the_interval_covers_the_true_crossing_as_stated() -> None:
    rng = np.random.default_rng(39)
    tolerance, slope, offset = 30.0, 0.12, 3.0  # µm, µm/day: the true crossing at day 225
    truth = (tolerance - offset) / slope
    covered = forecasts = 0
    for _ in range(400):
        t, d = _history(rng, 6, slope, 1.5, offset)
        f = forecast_crossing(t, d, tolerance)
        if f is None:
            continue
        forecasts += 1
        covered += f.earliest <= truth <= f.latest
        assert f.earliest <= f.crossing <= f.latest
    assert forecasts >= 380  # a clear trend: nearly always forecast
    rate = covered / forecasts
    assert 0.92 <= rate <= 0.98, rate  # 95 % stated; 400 draws: ±2.2 % at 2 σ


def test_more_rechecks_narrow_the_interval() -> None:
    rng = np.random.default_rng(7)
    widths = {}
    for n in (4, 20):
        ws = []
        for _ in range(50):
            f = forecast_crossing(*_history(rng, n, 0.12, 1.5), 30.0)
            if f is not None:
                ws.append(f.latest - f.earliest)
        widths[n] = float(np.median(ws))
    assert widths[20] < 0.5 * widths[4]


@pytest.mark.parametrize("slope", [0.0, -0.05])
def test_no_forecast_without_a_significant_rise(slope) -> None:
    rng = np.random.default_rng(3)
    made = sum(forecast_crossing(*_history(rng, 6, slope, 1.5), 30.0) is not None for _ in range(200))
    assert made <= 10 if slope == 0.0 else made == 0  # a flat drift: only the 2.5 % false upward trends


def test_degenerate_inputs_give_no_forecast() -> None:
    assert forecast_crossing(np.array([1.0, 2.0]), np.array([1.0, 2.0]), 30.0) is None  # 2 points
    assert forecast_crossing(np.array([5.0, 5.0, 5.0]), np.array([1.0, 2.0, 3.0]), 30.0) is None  # one day
    assert forecast_crossing(np.array([1.0, 2.0, np.nan]), np.array([1.0, 2.0, 3.0]), 30.0) is None
    assert forecast_crossing(np.array([1.0, 2.0, 3.0]), np.array([1.0, 2.0, 3.0]), 0.0) is None
    exact = forecast_crossing(np.array([0.0, 10.0, 20.0]), np.array([0.0, 1.0, 2.0]), 3.0)
    assert exact is not None and exact.crossing == pytest.approx(30.0) and exact.earliest == pytest.approx(30.0)


def _run(kind: str, when, drift=None, outcome="SUCCESS", interval=90):
    return {"run_uuid": f"{kind}-{when:%j%H}", "robot_key": "SR-9", "kind": kind, "outcome": outcome,
            "finished_utc": when.isoformat(), "drift_rms_um": drift, "tolerance_um": 30.0 if drift is not None else None,
            "recheck_interval_days": interval, "cell": "c", "station": "s", "robot_model": "m"}


def test_the_forecast_sets_due_when_earlier_than_the_interval() -> None:
    from station.fleet.overview import robot_status

    cal_t = datetime(2026, 9, 1, tzinfo=timezone.utc)
    rng = np.random.default_rng(5)
    days = [10, 20, 30, 40, 50]
    for slope, expect in ((0.3, "forecast"), (0.0, "interval")):  # µm/day: crossing near day 90 / never
        rechecks = [_run("recheck", cal_t + timedelta(days=d), 3.0 + slope * d + rng.normal(0, 0.5)) for d in days]
        row = {"robot_key": "SR-9", "last_calibration": _run("calibration", cal_t),
               "last_good_calibration": _run("calibration", cal_t), "last_recheck": rechecks[-1]}
        s = robot_status(row, rechecks, now=cal_t + timedelta(days=51))
        assert s.due_from == expect and s.state == "ok"
        interval_due = cal_t + timedelta(days=50 + 90)
        if expect == "forecast":
            earliest = datetime.fromisoformat(s.drift_crossing_earliest_utc.replace("Z", "+00:00"))
            assert s.next_recheck_due_utc == s.drift_crossing_earliest_utc and earliest < interval_due
            crossing = datetime.fromisoformat(s.drift_crossing_utc.replace("Z", "+00:00"))
            assert abs((crossing - cal_t).days - 90) < 15  # (30 - 3) / 0.3
            assert s.drift_crossing_earliest_utc <= s.drift_crossing_utc <= s.drift_crossing_latest_utc
            late = robot_status(row, rechecks, now=earliest + timedelta(days=1))
            assert late.state == "overdue"  # the forecast's date has passed, the interval's has not
        else:
            assert s.drift_crossing_utc is None
            assert s.next_recheck_due_utc == interval_due.strftime("%Y-%m-%dT%H:%M:%SZ")


def test_the_dashboard_shows_the_forecast(fleet_db) -> None:
    from fleet_runs import clock, days_ago, publication
    from starlette.testclient import TestClient

    from station.fleet import store
    from station.ui.dashboard.app import create_app

    pubs = [publication("SR-F", "calibration", days_ago(60))]
    pubs += [publication("SR-F", "recheck", days_ago(d), drift_um=3.0 + 0.35 * (60 - d), tolerance_um=30.0)
             for d in (50, 40, 30, 20, 10)]
    with store.connect(fleet_db.station_url) as c:
        for p in pubs:
            store.insert_publication(c, p)
    with TestClient(create_app(fleet_db.dashboard_url, interval_days=365, clock=clock)) as client:
        assert 'class="chip forecast"' in client.get("/").text
        page = client.get("/robots/SR-F").text
        assert "the trend reaches the tolerance on" in page
        row = client.get("/fleet.json").json()["rows"][0]
        assert row["due_from"] == "forecast" and row["drift_crossing_earliest_utc"] <= row["drift_crossing_utc"]


@pytest.mark.parametrize("drift, tolerance", [((0.0, 1e308, 1.7e308), 30.0), ((0.0, 1e308, 1.7e308, 1.7e308), 1e308),
                                              ((0.0, 1e200, 1.7e200, 1.7e200), 1e200)])
def test_drifts_near_the_largest_double_give_no_forecast_not_nan(drift, tolerance) -> None:
    """Issue 39's property test: a station may store a drift of 1e308 µm (finite, not negative);
    the sums of squares overflowed to a NaN crossing, and 'station fleet' ended in an internal
    error turning it into a date."""
    from station.fleet.overview import drift_trend, forecast_dates

    t = np.arange(1.0, len(drift) + 1.0)
    assert forecast_crossing(t, np.array(drift), tolerance) is None
    cal = datetime(2026, 5, 1, tzinfo=timezone.utc)
    rechecks = [{"finished_utc": (cal + timedelta(days=d)).isoformat(), "drift_rms_um": v} for d, v in zip(t, drift)]
    assert forecast_dates(rechecks, cal, {"tolerance_um": tolerance}) is None
    trend = drift_trend(rechecks)  # NaN before: JSON without a number for it
    assert trend is None or math.isfinite(trend)
