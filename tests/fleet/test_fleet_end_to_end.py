"""Issue 31's 'done when', end to end with the real parts: a simulated calibration with the
fleet store down ends SUCCESS and queued, with its report; 'station sync' after the restart
publishes it exactly once; 'station fleet --json' lists the robot with its figures."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from station.fleet import store


def _station(*args: str, url: str, cwd) -> subprocess.CompletedProcess:
    env = {**os.environ, "STATION_FLEET_URL": url}
    return subprocess.run([sys.executable, "-m", "station.ui.cli.main", *args], capture_output=True, text=True,
                          env=env, cwd=cwd, timeout=300)


@pytest.mark.slow
@pytest.mark.timeout(400)
def test_a_run_during_an_outage_is_queued_then_synced_once_and_listed(fleet_db, pg_server, tmp_path, short_cell):
    db = tmp_path / "a.sqlite"
    pg_server.stop()
    try:  # the built-in cell, one visit per identification pose and one verification cycle (issue 42)
        run = _station("calibrate", "--simulated", str(short_cell), "--db", str(db), "--report", str(tmp_path / "report"), "--json",
                       url=fleet_db.station_url, cwd=tmp_path)
    finally:
        pg_server.start()
    assert run.returncode == 0, run.stderr[-3000:]
    summary = json.loads(run.stdout.strip().splitlines()[-1])
    assert summary["outcome"] == "SUCCESS"
    assert "queued, not yet published" in run.stderr and fleet_db.count() == 0
    runs = _station("runs", "--db", str(db), "--json", url=fleet_db.station_url, cwd=tmp_path)
    assert runs.returncode == 0, runs.stderr  # the queue's table leaves the run database readable

    for expected_sent in (1, 0):  # the second sync finds nothing left to send
        synced = _station("sync", "--db", str(db), "--json", url=fleet_db.station_url, cwd=tmp_path)
        assert synced.returncode == 0, synced.stderr
        assert json.loads(synced.stdout)["sent"] == expected_sent
    assert (fleet_db.count(), fleet_db.count("reports")) == (1, 1)

    listed = _station("fleet", "--json", url=fleet_db.dashboard_url, cwd=tmp_path)
    assert listed.returncode == 0, listed.stderr
    (rehearsal,) = json.loads(listed.stdout)["robots"]  # a simulated run never makes a robot calibrated (39)
    assert rehearsal["state"] == "uncalibrated" and rehearsal["last_simulated_utc"] is not None
    listed = _station("fleet", "--json", "--include-simulated", url=fleet_db.dashboard_url, cwd=tmp_path)
    assert listed.returncode == 0, listed.stderr
    (robot,) = json.loads(listed.stdout)["robots"]
    assert robot["cell"] == summary["cell"] and robot["last_calibration_outcome"] == "SUCCESS"
    assert robot["gain"] == pytest.approx(summary["gain"]) and robot["rms_after_um"] == pytest.approx(summary["after"]["rms_um"])
    with store.connect(fleet_db.dashboard_url, read_only=True) as c:
        (row,) = store.robot_history(c, robot["robot_key"])
        detail = store.run_detail(c, row["run_uuid"])
    assert detail is not None and row["has_report"] and row["simulated"] is True
    ident = detail["detail"]["identification"]
    n = len(ident["chosen"])
    assert len(ident["covariance"]) == n and len(ident["covariance"][0]) == n  # parameters with covariance
    # each parameter published with its own value and unit, paired by name (39: not by position)
    by_name = {p["name"]: p for p in ident["parameters"]}
    assert list(by_name) == ident["chosen"] and {p["unit"] for p in by_name.values()} <= {"mm", "rad"}
    estimates = {p["name"]: p["value"] for p in summary["identification"]["parameters"]}
    assert all(by_name[k]["value"] == pytest.approx(v) for k, v in estimates.items())
