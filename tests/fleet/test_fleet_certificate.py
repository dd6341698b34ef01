"""A run's Digital Calibration Certificate through the fleet (issue 41): 'station export-dcc' keeps
its bytes in the run database and sends them with the run; the QA dashboard serves them at
/runs/UUID/certificate.xml to a real HTTP client over TCP, behind the same auth as its other
pages, byte for byte the exported file, valid against the kept DCC schema (xmlschema); headless
Chromium follows the run page's link and saves the same bytes."""

from __future__ import annotations

import json
import time

import httpx
import psycopg
import pytest
from fleet_runs import days_ago, publication

from station.cell.records.certificates import stored_certificate
from station.fleet import store
from station.ui.cli.main import main
from station.ui.dashboard.app import DashboardAuth, create_app
from station.ui.report.dcc import validate_dcc
from tests.fleet.conftest import serve_dashboard
from tests.ui.test_export_dcc import ISSUER

TOKEN = "qa-token-41"
WITH_TOKEN = DashboardAuth(token=TOKEN)


def _served(url: str, auth: DashboardAuth | None = WITH_TOKEN):
    """The dashboard on a free local port (conftest's serve_dashboard), by default with a bearer token."""
    return serve_dashboard(create_app(url, auth=auth))


def _fetch(base: str, run_uuid: str) -> httpx.Response:
    return httpx.get(f"{base}/runs/{run_uuid}/certificate.xml", headers={"Authorization": f"Bearer {TOKEN}"},
                     timeout=30)


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_the_dashboard_serves_the_exported_certificate(fleet_db, tmp_path, monkeypatch, capsys, short_cell):
    db, issuer, out = tmp_path / "runs.sqlite", tmp_path / "issuer.toml", tmp_path / "run1.xml"
    issuer.write_text(ISSUER)
    monkeypatch.setenv("STATION_FLEET_URL", fleet_db.station_url)
    # the built-in cell with one visit per identification pose and one verification cycle: how the
    # certificate travels is the same on the shorter run (issue 42: the suite's time)
    assert main(["calibrate", "--simulated", str(short_cell), "--seed", "1", "--db", str(db)]) == 0  # published with its end
    monkeypatch.delenv("STATION_FLEET_URL")  # the store out of reach: the certificate is kept, not lost
    assert main(["export-dcc", "1", "--db", str(db), "--issuer", str(issuer), "-o", str(out)]) == 0
    kept = stored_certificate(db, 1)
    assert kept is not None and kept.xml == out.read_bytes() and not kept.fleet_sent
    assert fleet_db.count() == 1
    capsys.readouterr()
    assert main(["sync", "--db", str(db), "--url", fleet_db.station_url, "--json"]) == 0
    synced = json.loads(capsys.readouterr().out)
    assert (synced["sent"], synced["certificates"], synced["certificates_unsent"]) == (0, 1, 0)
    assert stored_certificate(db, 1).fleet_sent  # type: ignore[union-attr]

    with store.connect(fleet_db.dashboard_url, read_only=True) as c:
        (row,) = store.robot_history(c, store.robot_keys(c)[0])
    run_uuid = row["run_uuid"]
    with _served(fleet_db.dashboard_url) as base:
        assert httpx.get(f"{base}/runs/{run_uuid}/certificate.xml", timeout=30).status_code == 401
        got = _fetch(base, run_uuid)
        assert got.status_code == 200 and got.headers["content-type"].startswith("application/xml")
        assert got.content == out.read_bytes()
        validate_dcc(got.content)  # offline, against the kept XSD files
        page = httpx.get(f"{base}/runs/{run_uuid}", headers={"Authorization": f"Bearer {TOKEN}"}, timeout=30)
        assert f'href="/runs/{run_uuid}/certificate.xml"' in page.text

        # exported again for another approver: other bytes, sent at once (the store is reachable
        # again), and the dashboard serves the latest
        issuer.write_text(ISSUER.replace("B. Approver", "C. Approver"))
        monkeypatch.setenv("STATION_FLEET_URL", fleet_db.station_url)
        again = tmp_path / "run1-c.xml"
        assert main(["export-dcc", "1", "--db", str(db), "--issuer", str(issuer), "-o", str(again)]) == 0
        assert "certificate of run 1 sent to the fleet store" in capsys.readouterr().err
        assert again.read_bytes() != out.read_bytes()
        assert _fetch(base, run_uuid).content == again.read_bytes()


def test_no_certificate_is_a_404_and_the_store_checks_its_digest(fleet_db):
    pub = publication("SR-9", "calibration", days_ago(3))
    with store.connect(fleet_db.station_url) as c:
        store.insert_publication(c, pub)
    with _served(fleet_db.dashboard_url) as base:
        assert _fetch(base, pub["run_uuid"]).status_code == 404
        page = httpx.get(f"{base}/runs/{pub['run_uuid']}", headers={"Authorization": f"Bearer {TOKEN}"}, timeout=30)
        assert page.status_code == 200 and "certificate.xml" not in page.text
    with store.connect(fleet_db.station_url) as c:
        with pytest.raises(psycopg.errors.CheckViolation):  # bytes other than the digest names
            c.execute("INSERT INTO certificates (run_uuid, sha256, schema_version, xml) VALUES (%s, %s, '3.1.2', %s)",
                      (pub["run_uuid"], "0" * 64, b"<x/>"))
    with store.connect(fleet_db.station_url) as c:
        assert store.insert_certificate(c, pub["run_uuid"], b"<x/>", "3.1.2")
        assert not store.insert_certificate(c, pub["run_uuid"], b"<x/>", "3.1.2")  # a retry: nothing new
    with store.connect(fleet_db.dashboard_url, read_only=True) as c:
        assert store.certificate_xml(c, pub["run_uuid"]) == b"<x/>"
        with pytest.raises(psycopg.errors.ReadOnlySqlTransaction):
            store.insert_certificate(c, pub["run_uuid"], b"<y/>", "3.1.2")



def test_chromium_downloads_the_certificate_from_the_run_page(fleet_db, browser, tmp_path):
    """The run page's link, followed in the distribution's headless Chromium (the browser tests'
    fixture): the file it saves is the stored certificate, byte for byte."""
    from selenium.webdriver.common.by import By

    pub = publication("SR-8", "calibration", days_ago(2))
    xml = b'<?xml version="1.0" encoding="UTF-8"?>\n<dcc:digitalCalibrationCertificate xmlns:dcc="https://ptb.de/dcc"/>\n'
    with store.connect(fleet_db.station_url) as c:
        store.insert_publication(c, pub)
        store.insert_certificate(c, pub["run_uuid"], xml, "3.1.2")
    downloads = tmp_path / "downloads"
    downloads.mkdir()
    with _served(fleet_db.dashboard_url, auth=None) as base:
        browser.execute_cdp_cmd("Browser.setDownloadBehavior", {"behavior": "allow", "downloadPath": str(downloads)})
        browser.get(f"{base}/runs/{pub['run_uuid']}")
        browser.find_element(By.ID, "open-certificate").click()
        for _ in range(400):
            saved = [p for p in downloads.iterdir() if p.suffix == ".xml"]
            if saved:
                break
            time.sleep(0.05)
    assert [p.name for p in saved] == ["certificate-SR-8-run-1.xml"]
    assert saved[0].read_bytes() == xml
