"""Issue 39, the dashboard: the fleet table and a robot's history exported as CSV and JSON with
their units, and the fleet table fitting a 1 366 px wide screen in Chromium (its widest content:
long keys, a failed calibration, a rehearsal's chip)."""

from __future__ import annotations

import csv
import io

import pytest
from fleet_runs import clock, days_ago, publication
from starlette.testclient import TestClient

from station.fleet import store
from station.ui.dashboard.app import create_app
from tests.fleet.test_dashboard_browser import served  # noqa: F401 - the dashboard of the browser tests

HOSTILE = "=HYPERLINK(\"http://x\")"


@pytest.fixture
def fleet(fleet_db):
    pubs = [publication("SR-1", "calibration", days_ago(40), after_um=12.0, cell="cell A"),
            publication("SR-1", "recheck", days_ago(20), drift_um=8.0, tolerance_um=30.0, cell="cell A"),
            publication(HOSTILE, "calibration", days_ago(10), after_um=15.0, cell="cell B")]
    with store.connect(fleet_db.station_url) as c:
        for p in pubs:
            store.insert_publication(c, p)
    return fleet_db


def test_the_fleet_exports_as_csv_and_json_with_units(fleet):
    with TestClient(create_app(fleet.dashboard_url, clock=clock)) as client:
        assert 'href="/fleet.csv?' in client.get("/").text
        data = client.get("/fleet.json?cell=cell%20A")
        assert data.status_code == 200 and data.headers["content-type"].startswith("application/json")
        body = data.json()
        assert body["units"]["rms_after_um"] == "µm" and body["units"]["last_calibration_utc"].startswith("ISO 8601")
        assert [r["robot_key"] for r in body["rows"]] == ["SR-1"] and body["cell"] == "cell A"  # the filter held
        assert body["rows"][0]["rms_after_um"] == 12.0 and body["rows"][0]["drift_rms_um"] == 8.0
        table = client.get("/fleet.csv?sort=robot")
        assert table.headers["content-type"].startswith("text/csv")
        assert 'filename="fleet.csv"' in table.headers["content-disposition"]
        rows = list(csv.reader(io.StringIO(table.text)))
        assert "rms_after_um [µm]" in rows[0] and "robot_key" in rows[0]
        keys = [r[rows[0].index("robot_key")] for r in rows[1:]]
        assert sorted(keys) == sorted(["SR-1", "'" + HOSTILE])  # no formula reaches a spreadsheet
        assert float(rows[1 + keys.index("SR-1")][rows[0].index("rms_after_um [µm]")]) == 12.0


def test_a_robots_history_exports_as_csv_and_json(fleet):
    with TestClient(create_app(fleet.dashboard_url, clock=clock)) as client:
        page = client.get("/robots/SR-1").text
        assert 'href="/history.csv?robot=SR-1"' in page
        body = client.get("/history.json?robot=SR-1").json()
        assert [r["kind"] for r in body["rows"]] == ["calibration", "recheck"]  # oldest first
        assert body["units"]["drift_rms_um"] == "µm" and body["robot"] == "SR-1"
        assert body["rows"][0]["finished_utc"].endswith("+00:00")
        rows = list(csv.reader(io.StringIO(client.get("/history.csv?robot=SR-1").text)))
        assert len(rows) == 3 and "tolerance_um [µm]" in rows[0]
        assert client.get("/history.csv?robot=NOPE").status_code == 404
        assert client.get("/history.json?robot=%00").status_code == 404
        assert client.get("/history.json").status_code == 404


@pytest.fixture
def wide_fleet(fleet_db, served):  # noqa: F811 - served: the dashboard of fleet_db, already holding SR-7
    sim = publication("KR10-R1100-2-SN-2026-0012345", "calibration", days_ago(1), cell="welding line 3, cell B",
                      station="calibration-cart-07")
    sim["simulated"] = True
    pubs = [publication("KR10-R1100-2-SN-2026-0012345", "calibration", days_ago(9), cell="welding line 3, cell B",
                        station="calibration-cart-07", after_um=123.4),
            publication("KR10-R1100-2-SN-2026-0012345", "recheck", days_ago(5), drift_um=123.4, tolerance_um=30.0,
                        cell="welding line 3, cell B", station="calibration-cart-07"),
            publication("KR10-R1100-2-SN-2026-0012345", "calibration", days_ago(3), outcome="TARGET_MISSED",
                        cell="welding line 3, cell B", station="calibration-cart-07", after_um=99.9), sim]
    with store.connect(fleet_db.station_url) as c:
        for p in pubs:
            store.insert_publication(c, p)
    return served


def test_the_fleet_table_fits_1366_px_in_chromium(browser, wide_fleet):
    from selenium.webdriver.common.by import By

    browser.set_window_size(1366, 768)
    browser.get(wide_fleet + "/")
    viewport = browser.execute_script("return document.documentElement.clientWidth")
    assert viewport >= 1300  # the window's inner width, a scroll bar at most taken off
    table = browser.find_element(By.ID, "fleet")
    right = browser.execute_script("return arguments[0].getBoundingClientRect().right", table)
    last = browser.find_elements(By.CSS_SELECTOR, "table#fleet thead th")[-1]
    last_right = browser.execute_script("return arguments[0].getBoundingClientRect().right", last)
    assert right <= viewport and last_right <= viewport, (right, last_right, viewport)
    assert browser.execute_script("return document.documentElement.scrollWidth") <= viewport
    assert len(browser.find_elements(By.CSS_SELECTOR, "table#fleet tr.robot")) == 2
