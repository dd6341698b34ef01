"""The QA dashboard in the distribution's headless Chromium, driven by Selenium: the fleet page
loads, a robot opens with its plots drawn, and the run's report opens. Nothing downloads a
browser: /usr/bin/chromium and /usr/bin/chromedriver (Debian's chromium, chromium-driver)."""

from __future__ import annotations

import os
import shutil
import socket
import threading
import time

import pytest
from fleet_runs import clock, days_ago, publication

from station.fleet import store
from station.ui.dashboard.app import create_app

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMEDRIVER = shutil.which("chromedriver")


@pytest.fixture
def browser(tmp_path):
    if not (CHROMIUM and CHROMEDRIVER):
        why = "needs Debian's chromium and chromium-driver (apt-get install, as .ci/run does)"
        if os.environ.get("CI", "").lower() in ("1", "true", "yes"):
            pytest.fail(f"CI=true: {why}")
        pytest.skip(why)
    webdriver = pytest.importorskip("selenium.webdriver")
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                "--disable-background-networking", "--disable-component-update", "--disable-sync",
                "--no-first-run", f"--user-data-dir={tmp_path / 'chromium-profile'}"):
        options.add_argument(arg)
    driver = webdriver.Chrome(options=options, service=Service(executable_path=CHROMEDRIVER))
    driver.set_page_load_timeout(60)
    try:
        yield driver
    finally:
        driver.quit()


@pytest.fixture
def served(fleet_db):
    import uvicorn

    cal = publication("SR-7", "calibration", days_ago(30), after_um=11.0, cell="cell 7")
    pubs = [cal] + [publication("SR-7", "recheck", days_ago(d), drift_um=5.0 + (30 - d) * 0.3, tolerance_um=30.0,
                                cell="cell 7") for d in (25, 18, 11, 4)]
    with store.connect(fleet_db.station_url) as c:
        for p in pubs:
            store.insert_publication(c, p)
        store.insert_report(c, cal["run_uuid"], "/srv/report.html",
                            "<html><body><h1 id='title'>Calibration report of SR-7</h1></body></html>")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    server = uvicorn.Server(uvicorn.Config(create_app(fleet_db.dashboard_url, clock=clock), host="127.0.0.1", port=port,
                                           log_level="warning"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    for _ in range(200):
        if server.started:
            break
        time.sleep(0.05)
    assert server.started, "the dashboard did not start"
    try:
        yield f"http://127.0.0.1:{port}"
    finally:
        server.should_exit = True
        thread.join(10)


def test_fleet_page_robot_plots_and_report_in_chromium(browser, served):
    from selenium.webdriver.common.by import By

    browser.get(served + "/")
    rows = browser.find_elements(By.CSS_SELECTOR, "table#fleet tr.robot")
    assert [r.get_attribute("data-robot") for r in rows] == ["SR-7"]
    assert "ok" in rows[0].text
    rows[0].find_element(By.CSS_SELECTOR, "a.robot-link").click()
    assert browser.find_element(By.ID, "robot-title").text == "SR-7"
    for plot in ("plot-accuracy", "plot-drift"):
        svg = browser.find_element(By.CSS_SELECTOR, f'svg[data-testid="{plot}"]')
        assert svg.size["width"] > 200 and svg.size["height"] > 50  # laid out, not an empty box
    drift = browser.find_element(By.CSS_SELECTOR, 'svg[data-testid="plot-drift"]')
    assert len(drift.find_elements(By.CSS_SELECTOR, "circle.drift")) == 4
    assert drift.find_elements(By.CSS_SELECTOR, "polygon.band")
    browser.find_element(By.CSS_SELECTOR, "a.report-link").click()
    assert browser.find_element(By.ID, "title").text == "Calibration report of SR-7"
