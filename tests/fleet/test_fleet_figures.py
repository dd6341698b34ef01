"""Issue 39: the figures the plant view shows are right and say their kind. Real PostgreSQL (the
tests' throwaway server), the dashboard in-process; each test failed before the fix."""

from __future__ import annotations

import json
import math
import re

import psycopg
import pytest
from fleet_runs import AS_OF, clock, days_ago, publication
from starlette.testclient import TestClient

from station.fleet import store
from station.fleet.migrate import migrate
from station.ui.cli.main import main
from station.ui.dashboard.app import create_app
from station.ui.dashboard.plots import _nice_max, history_svg
from tests.fleet.conftest import new_database

#: the migration that brought the rows' CHECK constraints (0004_kinds_and_checks.sql): rows stored
#: before it may be anything the columns' types allow
CHECKS_MIGRATION = 4

#: an SR 800's 36-value vector as a run stores it, and the 20 names of its chosen parameters
_NAMES36 = [f"{t}.{s}" for t in ("R", "A1", "A2", "A3", "A4", "K") for s in ("x", "y", "z", "roll", "pitch", "yaw")]


def _publish(fleet_db, *pubs):
    with store.connect(fleet_db.station_url) as c:
        for p in pubs:
            store.insert_publication(c, p)


def _old_form_detail() -> dict:
    """A run's detail as a station before issue 39 published it: 20 names beside the 36 values."""
    chosen = ["R.x", "R.y", "R.z", "R.roll", "R.pitch", "R.yaw", "A1.x", "A1.y", "A2.x", "A2.yaw", "A3.x",
              "A3.roll", "A3.pitch", "A3.yaw", "K.x", "K.y", "K.z", "K.roll", "K.pitch", "K.yaw"]
    params = [-100.0 + i for i in range(36)]
    params[_NAMES36.index("A2.yaw")] = 0.0012
    params[_NAMES36.index("R.roll")] = 0.0005
    estimates = [{"name": n, "value": params[_NAMES36.index(n)], "sigma": 2e-6} for n in chosen]
    return {"identification": {"names": chosen, "chosen": chosen, "params": params, "sigma": [2e-6] * 20},
            "summary": {"identification": {"parameters": estimates}}}


def test_a_runs_parameters_are_paired_by_name_with_their_units(fleet_db):
    old = publication("SR-1", "calibration", days_ago(3))
    old["detail"] = _old_form_detail()
    new = publication("SR-1", "calibration", days_ago(1))
    new["detail"] = {"identification": {"parameters": [
        {"name": "A2.x", "unit": "mm", "nominal": 445.0, "value": 445.0123, "sigma": 0.0021},
        {"name": "A2.yaw", "unit": "rad", "nominal": 0.0, "value": math.radians(0.01), "sigma": math.radians(2 / 3600)}]}}
    _publish(fleet_db, old, new)
    with TestClient(create_app(fleet_db.dashboard_url, clock=clock)) as client:
        page = client.get(f"/runs/{old['run_uuid']}").text
        cells = dict(re.findall(r"<tr><td>([A-Z0-9]+\.[a-z]+)</td><td class=\"num\">([^<]*)</td>", page))
        assert cells["R.roll"] == f"{math.degrees(0.0005):.5f} °"  # not −97, the vector's 4th value
        assert cells["A2.yaw"] == f"{math.degrees(0.0012):.5f} °"
        assert cells["A2.x"] == f"{_NAMES36.index('A2.x') - 100.0:.4f} mm" and len(cells) == 20
        page = client.get(f"/runs/{new['run_uuid']}").text
        assert "445.0123 mm" in page and "12.3 µm" in page and "2.1 µm" in page  # value, Δ, σ
        assert "0.01000 °" in page and "36.0 ″" in page and "2.0 ″" in page


def test_simulated_runs_are_marked_everywhere_and_never_make_a_robot_ok(fleet_db, capsys):
    rehearsal = publication("SIM-1", "calibration", days_ago(1))
    rehearsal["simulated"] = True
    _publish(fleet_db, rehearsal)
    with psycopg.connect(fleet_db.admin_url) as c:
        assert c.execute("SELECT simulated FROM runs").fetchone() == (True,)  # the store's column
    assert main(["fleet", "--url", fleet_db.dashboard_url, "--json", *AS_OF]) == 0
    (robot,) = json.loads(capsys.readouterr().out)["robots"]
    assert robot["state"] == "uncalibrated" and robot["gain"] is None and robot["last_simulated_utc"]
    assert main(["fleet", "--url", fleet_db.dashboard_url, "--json", "--include-simulated", *AS_OF]) == 0
    assert json.loads(capsys.readouterr().out)["robots"][0]["state"] == "ok"  # where the plant asks
    with TestClient(create_app(fleet_db.dashboard_url, clock=clock)) as client:
        assert 'class="chip sim"' in client.get("/").text
        assert 'id="simulated-banner"' in client.get(f"/runs/{rehearsal['run_uuid']}").text
        assert 'class="chip sim"' in client.get("/robots/SIM-1").text


@pytest.mark.parametrize("outcome", ["ABORTED", "TARGET_MISSED"])
def test_the_state_and_figures_are_the_latest_calibration_attempts(fleet_db, capsys, outcome):
    attempt = publication("SR-1", "calibration", days_ago(1), outcome=outcome, after_um=40.0)
    if outcome == "ABORTED":  # an aborted run has no figures
        attempt.update(rms_before_um=None, rms_after_um=None, gain=None, ap_max_um=None)
    _publish(fleet_db, publication("SR-1", "calibration", days_ago(20), after_um=11.0), attempt)
    assert main(["fleet", "--url", fleet_db.dashboard_url, "--json", *AS_OF]) == 0
    (robot,) = json.loads(capsys.readouterr().out)["robots"]
    assert robot["state"] == "failed" and robot["last_calibration_outcome"] == outcome
    assert robot["last_calibration_utc"][:10] == days_ago(1).strftime("%Y-%m-%d")
    assert robot["rms_after_um"] == (None if outcome == "ABORTED" else 40.0)  # never the older run's 11.0
    assert robot["last_good_calibration_utc"][:10] == days_ago(20).strftime("%Y-%m-%d")


@pytest.mark.parametrize("column, value", [("finished_utc", "infinity"), ("finished_utc", "10000-01-01"),
                                           ("finished_utc", "0044-03-15 BC"), ("recheck_interval_days", 2**31 - 1),
                                           ("recheck_interval_days", -2**31), ("rms_after_um", "NaN")])
def test_impossible_rows_are_refused_on_the_way_in_and_survived_on_the_way_out(pg_server, capsys, column, value):
    db = new_database(pg_server, target=CHECKS_MIGRATION - 1)  # a row stored before the checks (0004)
    bad = publication("BAD-1", "calibration", days_ago(2))
    _insert_raw(db.admin_url, bad, column, value)
    with db.admin() as c:
        migrate(c)
    _insert_raw(db.admin_url, publication("OK-1", "calibration", days_ago(2)), "cell", "cell A")
    with pytest.raises(store.FleetStoreError, match="check constraint|violates"):  # now refused as the station
        with store.connect(db.station_url) as c, store.store_errors(db.station_url):
            _insert_raw_conn(c, publication("BAD-2", "calibration", days_ago(1)), column, value)
    assert main(["fleet", "--url", db.dashboard_url, "--json", *AS_OF]) == 0
    robots = {r["robot_key"]: r for r in json.loads(capsys.readouterr().out)["robots"]}
    assert robots["OK-1"]["state"] == "ok"
    if column != "rms_after_um":
        assert robots["BAD-1"]["state"] == "damaged" and column in robots["BAD-1"]["damaged"]
    else:
        assert robots["BAD-1"]["rms_after_um"] is None  # NaN is no figure
    with TestClient(create_app(db.dashboard_url, clock=clock)) as client:
        for path in ("/", "/robots/BAD-1", f"/runs/{bad['run_uuid']}", "/?sort=due", "/?sort=calibrated"):
            assert client.get(path).status_code == 200, path


def test_a_run_whose_detail_is_a_list_is_a_page_not_a_500(pg_server):
    db = new_database(pg_server, target=CHECKS_MIGRATION - 1)
    bad = publication("SR-1", "calibration", days_ago(1))
    bad["detail"] = ["not", "an", "object"]
    _insert_raw(db.admin_url, bad, "cell", "cell A")
    with db.admin() as c:
        migrate(c)
    with TestClient(create_app(db.dashboard_url, clock=clock)) as client:
        assert client.get(f"/runs/{bad['run_uuid']}").status_code == 200


def test_the_drift_axis_fits_its_values_and_one_rechecks_band_is_visible():
    assert _nice_max(122.7) == 200 and _nice_max(9.0) == 10 and _nice_max(0.3) == 0.5
    runs = [{"finished_utc": days_ago(10), "kind": "calibration", "outcome": "SUCCESS", "rms_after_um": 11.0},
            {"finished_utc": days_ago(2), "kind": "recheck", "drift_rms_um": 122.7, "tolerance_um": 30.0}]
    _, drift = history_svg(runs)
    assert ">200<" in drift and ">1000<" not in drift
    (points,) = re.findall(r'<polygon points="([^"]+)" class="band"', drift)
    xs = {float(p.split(",")[0]) for p in points.split()}
    assert max(xs) - min(xs) > 100  # a band across the plot, not a line of no width


def _insert_raw(url: str, pub: dict, column: str, value) -> None:
    with psycopg.connect(url, autocommit=True) as c:
        _insert_raw_conn(c, pub, column, value)


def _insert_raw_conn(c: psycopg.Connection, pub: dict, column: str, value) -> None:
    """A row as any client of the role could write it (not through the station's code)."""
    cols = ["run_uuid", "robot_key", "robot_model", "cell", "station", "station_version", "local_run_id", "kind",
            "outcome", "started_utc", "finished_utc", "rms_after_um", "gain", "recheck_interval_days", "detail"]
    row = {**{k: pub[k] for k in cols if k != "detail"}, "detail": json.dumps(pub["detail"]), column: value}
    c.execute("INSERT INTO robots (robot_key) VALUES (%s) ON CONFLICT DO NOTHING", (pub["robot_key"],))
    c.execute(f"INSERT INTO runs ({', '.join(cols)}) VALUES ({', '.join(['%s'] * len(cols))})",
              [row[k] for k in cols])
