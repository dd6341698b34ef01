"""The QA dashboard without a browser: its pages, sorting and filtering, its auth, the report
served sandboxed, and 'station serve' refusing an open remote bind."""

from __future__ import annotations

import base64

import pytest
from fleet_runs import clock, days_ago, publication
from starlette.testclient import TestClient

from station.fleet import store
from station.ui.cli.main import main
from station.ui.dashboard.app import DashboardAuth, create_app


@pytest.fixture
def populated(fleet_db):
    pubs = [publication("SR-1", "calibration", days_ago(40), after_um=12.0, cell="cell A"),
            publication("SR-1", "recheck", days_ago(20), drift_um=8.0, tolerance_um=30.0, cell="cell A"),
            publication("SR-1", "recheck", days_ago(2), drift_um=9.0, tolerance_um=30.0, cell="cell A"),
            publication("SR-2", "calibration", days_ago(50), after_um=15.0, cell="cell B")]
    with store.connect(fleet_db.station_url) as c:
        for p in pubs:
            store.insert_publication(c, p)
        store.insert_report(c, pubs[0]["run_uuid"], "/srv/r/report.html",
                            "<html><body><h1>Calibration report SR-1</h1></body></html>")
    return fleet_db, pubs


def test_fleet_page_sorts_and_filters(populated):
    fleet_db, _ = populated
    with TestClient(create_app(fleet_db.dashboard_url, clock=clock)) as client:
        page = client.get("/")
        assert page.status_code == 200 and "SR-1" in page.text and "SR-2" in page.text
        assert "script-src 'none'" in page.headers["content-security-policy"]
        assert client.get("/?state=overdue").text.count('class="robot"') == 1  # SR-2: 50 days, no recheck
        only_b = client.get("/?cell=cell%20B").text
        assert "SR-2" in only_b and "/robots/SR-1" not in only_b
        desc = client.get("/?sort=rms&order=desc").text
        assert desc.index("/robots/SR-2") < desc.index("/robots/SR-1")
        assert client.get("/static/dashboard.css").status_code == 200


def test_robot_history_has_its_plots_and_the_report_opens_sandboxed(populated):
    fleet_db, pubs = populated
    with TestClient(create_app(fleet_db.dashboard_url, clock=clock)) as client:
        page = client.get("/robots/SR-1")
        assert page.status_code == 200
        assert 'data-testid="plot-accuracy"' in page.text and 'data-testid="plot-drift"' in page.text
        assert 'class="band"' in page.text  # the tolerance band
        run = client.get(f"/runs/{pubs[0]['run_uuid']}")
        assert run.status_code == 200 and "R.x" not in run.text  # a publication without parameters
        report = client.get(f"/runs/{pubs[0]['run_uuid']}/report")
        assert "Calibration report SR-1" in report.text
        assert report.headers["content-security-policy"].startswith("sandbox")
        assert client.get("/robots/NOPE").status_code == 404
        assert client.get(f"/runs/{pubs[1]['run_uuid']}/report").status_code == 404


def test_with_a_token_or_basic_auth_every_request_needs_it(populated):
    fleet_db, _ = populated
    with TestClient(create_app(fleet_db.dashboard_url, auth=DashboardAuth(token="s3cret-token"), clock=clock)) as client:
        assert client.get("/").status_code == 401
        assert client.get("/static/dashboard.css").status_code == 401
        assert client.get("/", headers={"Authorization": "Bearer wrong"}).status_code == 401
        assert client.get("/", headers={"Authorization": "Bearer s3cret-token"}).status_code == 200
    basic = DashboardAuth(basic=("qa", "pw"))
    with TestClient(create_app(fleet_db.dashboard_url, auth=basic, clock=clock)) as client:
        denied = client.get("/")
        assert denied.status_code == 401 and denied.headers["www-authenticate"].startswith("Basic")
        good = base64.b64encode(b"qa:pw").decode()
        assert client.get("/", headers={"Authorization": f"Basic {good}"}).status_code == 200


def test_the_dashboard_cannot_write_even_as_the_stores_owner(fleet_db):
    """The connection itself is read-only: a bug in the app could not change the store."""
    import psycopg

    with store.connect(fleet_db.admin_url, read_only=True, autocommit=True) as c:
        with pytest.raises(psycopg.errors.ReadOnlySqlTransaction):
            c.execute("DELETE FROM runs")


def test_serve_refuses_a_remote_bind_without_auth_or_tls(tmp_path, capsys):
    assert main(["serve", "--fleet", "postgresql://x@127.0.0.1:1/x", "--host", "0.0.0.0"]) == 2
    assert "needs --token-file" in capsys.readouterr().err
    token = tmp_path / "token"
    token.write_text("abc\n")
    assert main(["serve", "--fleet", "postgresql://x@127.0.0.1:1/x", "--host", "0.0.0.0", "--token-file",
                 str(token)]) == 2
    assert "--tls-cert" in capsys.readouterr().err


def test_a_store_that_is_down_is_a_503_page_not_a_traceback(fleet_db, pg_server):
    client = TestClient(create_app(fleet_db.dashboard_url, clock=clock), raise_server_exceptions=False)
    pg_server.stop()
    try:
        page = client.get("/")
    finally:
        pg_server.start()
    assert page.status_code == 503 and "unavailable" in page.text
    assert client.get("/").status_code == 200  # back when the store is
