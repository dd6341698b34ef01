"""'station fleet' as text shows the drift forecast the dashboard shows (issue 39): when the trend
of the rechecks since the calibration reaches the tolerance, its 95 % interval, and 'due' from it
where that is earlier than the interval. States reckoned at a fixed time (--as-of), never the
wall clock."""

from __future__ import annotations

import json
from datetime import datetime, timedelta, timezone

import numpy as np
import pytest
from fleet_runs import publication

from station.fleet import store
from station.fleet.drift_forecast import forecast_crossing
from station.ui.cli.main import main

CAL = datetime(2026, 9, 1, 8, tzinfo=timezone.utc)
DAYS = (10.0, 20.0, 30.0, 40.0, 50.0)
#: 3 µm after the calibration, 0.35 µm a day, a little scatter: the trend reaches 30 µm near day 77
DRIFT = tuple(3.0 + 0.35 * d + e for d, e in zip(DAYS, (0.4, -0.3, 0.2, -0.5, 0.1)))


def _day(days: float) -> str:
    return (CAL + timedelta(days=days)).strftime("%Y-%m-%d")


@pytest.fixture
def drifting(fleet_db):
    """SR-F drifts towards its tolerance; SR-Q is calibrated, its one recheck says nothing of a trend."""
    pubs = [publication("SR-F", "calibration", CAL, interval_days=90)]
    pubs += [publication("SR-F", "recheck", CAL + timedelta(days=d), drift_um=v, tolerance_um=30.0, interval_days=90)
             for d, v in zip(DAYS, DRIFT)]
    pubs += [publication("SR-Q", "calibration", CAL, interval_days=90),
             publication("SR-Q", "recheck", CAL + timedelta(days=20), drift_um=4.0, tolerance_um=30.0, interval_days=90)]
    with store.connect(fleet_db.station_url) as c:
        for p in pubs:
            store.insert_publication(c, p)
    return fleet_db


def _line(text: str, robot: str) -> str:
    return next(line for line in text.splitlines() if line.startswith(robot + " "))


def test_the_text_table_shows_the_forecast_and_due_from_it(drifting, capsys):
    f = forecast_crossing(np.array(DAYS), np.array(DRIFT), 30.0)
    assert f is not None and 70 < f.crossing < 85  # the drift's own trend: 27 / 0.35 = 77 days
    assert f.earliest < 50 + 90  # earlier than the last recheck's interval: due from the forecast
    as_of = _day(55)
    assert main(["fleet", "--url", drifting.dashboard_url, "--as-of", as_of]) == 0
    out = capsys.readouterr().out
    assert "drift reaches tolerance [95 %]" in out.splitlines()[0]
    assert "drift µm" in out.splitlines()[0] and "trend µm/30 d" in out.splitlines()[0]  # columns say their units
    line = _line(out, "SR-F")
    assert f"{_day(f.crossing)} [{_day(f.earliest)} … {_day(f.latest)}]" in line
    assert f"{_day(f.earliest)} (forecast)" in line and line.rstrip().endswith("ok")
    assert "ILAC-G24" in out  # what '(forecast)' means is said once below the table
    quiet = _line(out, "SR-Q")  # one recheck: no trend, no forecast, due from the interval
    assert " — " in quiet and f"{_day(20 + 90)} " in quiet and "(forecast)" not in quiet
    # the JSON says the same dates
    assert main(["fleet", "--url", drifting.dashboard_url, "--as-of", as_of, "--json"]) == 0
    robot = {r["robot_key"]: r for r in json.loads(capsys.readouterr().out)["robots"]}["SR-F"]
    assert robot["due_from"] == "forecast" and robot["next_recheck_due_utc"][:10] == _day(f.earliest)
    assert (robot["drift_crossing_utc"][:10], robot["drift_crossing_latest_utc"][:10]) == (_day(f.crossing),
                                                                                           _day(f.latest))


def test_as_of_reckons_the_states_at_that_time(drifting, capsys):
    f = forecast_crossing(np.array(DAYS), np.array(DRIFT), 30.0)
    assert f is not None
    after = (CAL + timedelta(days=f.earliest + 1)).strftime("%Y-%m-%dT%H:%M:%SZ")
    assert main(["fleet", "--url", drifting.dashboard_url, "--as-of", after, "--overdue"]) == 12
    out = capsys.readouterr().out
    assert _line(out, "SR-F").rstrip().endswith("overdue")  # the forecast's date has passed, the interval's not
    assert _line(out, "SR-Q").rstrip().endswith("ok")
    assert main(["fleet", "--url", drifting.dashboard_url, "--as-of", "next tuesday"]) == 2
    err = capsys.readouterr().err
    assert "--as-of 'next tuesday'" in err and "2027-01-15" in err and "Traceback" not in err
