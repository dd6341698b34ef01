"""Fixtures of the fleet tests: a throwaway PostgreSQL server (the real one, no mock), one fresh
database per test with the schema migrated, and login roles in the station's and the
dashboard's group roles. Without the server's binaries the tests are skipped, saying why;
under CI=true that is a failure (.ci/run installs them)."""

from __future__ import annotations

import itertools
import os
import shutil
import socket
import threading
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import psycopg
import pytest
from pg_server import PgServer, find_bin

from station.fleet.migrate import migrate

STATION_ROLE, DASHBOARD_ROLE = "station_login", "dashboard_login"
_numbers = itertools.count()


def _in_ci() -> bool:
    return os.environ.get("CI", "").strip().lower() in ("1", "true", "yes")


@pytest.fixture(scope="session")
def pg_server():
    bin_dir = find_bin()
    if bin_dir is None:
        why = ("the PostgreSQL server binaries are not installed (no /usr/lib/postgresql/*/bin/initdb); "
               "apt-get install postgresql, as .ci/run does")
        if _in_ci():
            pytest.fail(f"CI=true: {why}")
        pytest.skip(why)
    server = PgServer(bin_dir)
    try:
        server.start()
        yield server
    finally:
        server.cleanup()


@dataclass
class FleetDB:
    server: PgServer
    name: str

    @property
    def admin_url(self) -> str:
        return self.server.url(self.name)

    @property
    def station_url(self) -> str:
        return self.server.url(self.name, STATION_ROLE)

    @property
    def dashboard_url(self) -> str:
        return self.server.url(self.name, DASHBOARD_ROLE)

    def admin(self) -> psycopg.Connection:
        return psycopg.connect(self.admin_url, autocommit=True)

    def count(self, table: str = "runs") -> int:
        assert table in ("runs", "robots", "reports")
        with self.admin() as c:
            row = c.execute(f"SELECT count(*) FROM {table}").fetchone()
        assert row is not None
        return int(row[0])


def new_database(server: PgServer, target: int | None = None) -> FleetDB:
    # unique whatever module instance runs it (tests import this file as tests.fleet.conftest: a
    # bare "conftest" is whichever folder's conftest an xdist worker imported first)
    name = f"fleet_{os.getpid()}_{next(_numbers)}_{uuid.uuid4().hex[:8]}"
    with psycopg.connect(server.url(), autocommit=True) as c:
        c.execute(f'CREATE DATABASE "{name}"')
    db = FleetDB(server, name)
    with db.admin() as c:
        migrate(c, target)
        if target is None or target >= 2:  # the group roles exist: the login roles join them
            c.execute(f"""DO $$ BEGIN
                IF NOT EXISTS (SELECT 1 FROM pg_roles WHERE rolname = '{STATION_ROLE}') THEN
                    CREATE ROLE {STATION_ROLE} LOGIN IN ROLE fleet_station; END IF;
                IF NOT EXISTS (SELECT 1 FROM pg_roles WHERE rolname = '{DASHBOARD_ROLE}') THEN
                    CREATE ROLE {DASHBOARD_ROLE} LOGIN IN ROLE fleet_dashboard; END IF;
                END $$""")
    return db


@pytest.fixture
def fleet_db(pg_server) -> FleetDB:
    """A fresh, migrated fleet store in the throwaway server."""
    return new_database(pg_server)


@contextmanager
def serve_dashboard(app: Any) -> Iterator[str]:
    """The dashboard ``app`` on a free local port (uvicorn in a thread) until the block ends; yields
    its base URL."""
    import uvicorn

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning"))
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


#: the distribution's headless Chromium for the browser tests (nothing downloads a browser)
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMEDRIVER = shutil.which("chromedriver")


@pytest.fixture
def browser(tmp_path):
    if not (CHROMIUM and CHROMEDRIVER):
        why = "needs Debian's chromium and chromium-driver (apt-get install, as .ci/run does)"
        if _in_ci():
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
