"""The QA dashboard in the distribution's headless Chromium, driven by Selenium: the fleet page
loads, a robot opens with its plots drawn, and the run's report opens. Nothing downloads a
browser: /usr/bin/chromium and /usr/bin/chromedriver (Debian's chromium, chromium-driver); the
``browser`` fixture is the fleet tests' (conftest.py)."""

from __future__ import annotations

import pytest
from fleet_runs import clock, days_ago, publication

from station.fleet import store
from station.ui.dashboard.app import create_app
from tests.fleet.conftest import serve_dashboard


@pytest.fixture
def served(fleet_db):
    cal = publication("SR-7", "calibration", days_ago(30), after_um=11.0, cell="cell 7")
    pubs = [cal] + [publication("SR-7", "recheck", days_ago(d), drift_um=5.0 + (30 - d) * 0.3, tolerance_um=30.0,
                                cell="cell 7") for d in (25, 18, 11, 4)]
    with store.connect(fleet_db.station_url) as c:
        for p in pubs:
            store.insert_publication(c, p)
        store.insert_report(c, cal["run_uuid"], "/srv/report.html",
                            "<html><body><h1 id='title'>Calibration report of SR-7</h1></body></html>")
    with serve_dashboard(create_app(fleet_db.dashboard_url, clock=clock)) as base:
        yield base


def test_fleet_page_robot_plots_and_report_in_chromium(browser, served):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support import expected_conditions as loaded
    from selenium.webdriver.support.ui import WebDriverWait

    def after_click(element_id: str):
        """The next page's element, once that page is there: a click's navigation may still be under
        way when click() returns, and the old page has no such element (a hang guard, not a pace)"""
        return WebDriverWait(browser, 60).until(loaded.presence_of_element_located((By.ID, element_id)))

    browser.get(served + "/")
    rows = browser.find_elements(By.CSS_SELECTOR, "table#fleet tr.robot")
    assert [r.get_attribute("data-robot") for r in rows] == ["SR-7"]
    assert "ok" in rows[0].text
    rows[0].find_element(By.CSS_SELECTOR, "a.robot-link").click()
    assert after_click("robot-title").text == "SR-7"
    for plot in ("plot-accuracy", "plot-drift"):
        svg = browser.find_element(By.CSS_SELECTOR, f'svg[data-testid="{plot}"]')
        assert svg.size["width"] > 200 and svg.size["height"] > 50  # laid out, not an empty box
    drift = browser.find_element(By.CSS_SELECTOR, 'svg[data-testid="plot-drift"]')
    assert len(drift.find_elements(By.CSS_SELECTOR, "circle.drift")) == 4
    assert drift.find_elements(By.CSS_SELECTOR, "polygon.band")
    browser.find_element(By.CSS_SELECTOR, "a.report-link").click()
    assert after_click("title").text == "Calibration report of SR-7"
