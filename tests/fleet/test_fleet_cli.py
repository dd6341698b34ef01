"""``station fleet`` (text, --json, --overdue), ``station sync`` and the fleet's states and due
dates."""

from __future__ import annotations

import json
from datetime import datetime, timezone

import pytest
from fleet_runs import AS_OF, EXAMPLE, days_ago, example_config, finished_run, publication

from station.fleet import store
from station.fleet.overview import drift_trend, robot_status
from station.ui.cli.main import main


def _publish(fleet_db, *pubs):
    with store.connect(fleet_db.station_url) as c:
        for p in pubs:
            store.insert_publication(c, p)


def test_fleet_json_lists_each_robot_with_its_figures_state_and_due_date(fleet_db, capsys, monkeypatch):
    monkeypatch.setenv("STATION_FLEET_URL", fleet_db.dashboard_url)
    _publish(fleet_db,
             publication("OK-1", "calibration", days_ago(10), after_um=12.0),
             publication("OK-1", "recheck", days_ago(3), drift_um=4.0, tolerance_um=30.0),
             publication("LATE-1", "calibration", days_ago(45), cell="cell B"),
             publication("DRIFT-1", "calibration", days_ago(20)),
             publication("DRIFT-1", "recheck", days_ago(9), drift_um=10.0, tolerance_um=30.0),
             publication("DRIFT-1", "recheck", days_ago(5), drift_um=20.0, tolerance_um=30.0),
             publication("DRIFT-1", "recheck", days_ago(1), drift_um=40.0, tolerance_um=30.0, outcome="DRIFTED"),
             publication("NEW-1", "calibration", days_ago(1), outcome="IDENTIFICATION_FAILED"))
    assert main(["fleet", "--json", *AS_OF]) == 0
    out = json.loads(capsys.readouterr().out)
    robots = {r["robot_key"]: r for r in out["robots"]}
    assert {k: r["state"] for k, r in robots.items()} == {"OK-1": "ok", "LATE-1": "overdue", "DRIFT-1": "drifted",
                                                          "NEW-1": "failed"}  # its only attempt failed (issue 39)
    ok = robots["OK-1"]
    assert ok["rms_after_um"] == pytest.approx(12.0) and ok["last_recheck_verdict"] == "SUCCESS"
    assert ok["next_recheck_due_utc"][:10] == days_ago(3 - 30).strftime("%Y-%m-%d")
    assert robots["DRIFT-1"]["drift_trend_um_per_30d"] == pytest.approx(30 * 30 / 8, rel=0.05)
    assert robots["LATE-1"]["cell"] == "cell B" and out["overdue"] == 3
    assert main(["fleet", "--overdue", *AS_OF]) == 12
    text = capsys.readouterr().out
    assert "LATE-1" in text and "overdue" in text and "4 robot(s), 3 needing" in text


def test_overdue_exits_zero_when_every_robot_is_ok(fleet_db, capsys):
    _publish(fleet_db, publication("OK-1", "calibration", days_ago(2)))
    assert main(["fleet", "--url", fleet_db.dashboard_url, "--overdue", *AS_OF]) == 0


def test_sync_sends_the_queue_and_says_what_it_did(fleet_db, tmp_path, capsys):
    cfg = example_config()
    path = tmp_path / "runs.sqlite"
    from station.cell.publication.outbox import enqueue_run

    enqueue_run(path, finished_run(path, cfg), cfg)
    assert main(["sync", "--db", str(path), "--url", fleet_db.station_url, "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["sent"] == 1
    assert main(["sync", "--db", str(path), "--url", fleet_db.station_url]) == 0
    assert "0 run(s) sent" in capsys.readouterr().out


def test_an_unreachable_store_is_a_database_error_not_a_traceback(tmp_path, capsys):
    assert main(["fleet", "--url", "postgresql://nobody@127.0.0.1:1/none"]) == 5
    assert "cannot connect" in capsys.readouterr().err


def test_a_password_in_the_cell_file_is_refused():
    from station.cell.config.cell_config import parse_text
    from station.errors import ConfigError

    base = EXAMPLE.read_text(encoding="utf-8")
    assert "[fleet]" not in base
    for url in ("postgresql://qa:secret@fleet/db", "host=fleet password=secret"):
        with pytest.raises(ConfigError, match="pgpass"):
            parse_text(base + f'\n[fleet]\nurl = "{url}"\n', str(EXAMPLE))
    assert parse_text(base + '\n[fleet]\nurl = "service=plant"\n', str(EXAMPLE)).fleet.url == "service=plant"


def test_drift_trend_and_states_without_a_server():
    now = datetime(2026, 6, 1, tzinfo=timezone.utc)
    rechecks = [{"finished_utc": f"2026-05-{d:02d}T00:00:00Z", "drift_rms_um": v} for d, v in ((1, 10), (11, 20), (21, 30))]
    assert drift_trend(rechecks) == pytest.approx(30.0)
    assert drift_trend(rechecks[:2]) is None
    cal = {"finished_utc": "2026-04-01T00:00:00Z", "outcome": "SUCCESS", "recheck_interval_days": 90, "gain": 60.0}
    s = robot_status({"robot_key": "R", "last_calibration": cal, "last_good_calibration": cal, "last_recheck": None},
                     [], now)
    assert (s.state, s.next_recheck_due_utc) == ("ok", "2026-06-30T00:00:00Z")
    s = robot_status({"robot_key": "R", "last_calibration": cal, "last_good_calibration": cal, "last_recheck": None},
                     [], datetime(2026, 7, 1, tzinfo=timezone.utc))
    assert s.state == "overdue" and s.overdue
