"""The fleet store on a real PostgreSQL server: migrations, the two roles, publishing and its
idempotency, store and forward through an outage, two stations syncing at once."""

from __future__ import annotations

import contextlib
import threading
import time

import psycopg
import pytest
from fleet_runs import example_config, finished_run, recheck_summary

from station.cell.publication.outbox import attach_report, enqueue_run, pending, publish_or_queue, queue_state, sync
from station.fleet import store
from station.fleet.migrate import current_version, latest_version, migrate
from tests.fleet.conftest import new_database


def test_migrations_from_empty_make_the_latest_schema_and_run_once(pg_server):
    db = new_database(pg_server, target=0)
    with db.admin() as c:
        assert current_version(c) == 0
        assert migrate(c) == list(range(1, latest_version() + 1))
        assert migrate(c) == []  # a second run changes nothing
        assert current_version(c) == latest_version()
        indexes = {r[0] for r in c.execute("SELECT indexname FROM pg_indexes WHERE tablename = 'runs'")}
    assert "runs_robot_kind_time" in indexes


def test_migration_from_the_previous_version_keeps_the_runs(pg_server, tmp_path):
    db = new_database(pg_server, target=latest_version() - 1)
    with db.admin() as c:
        c.execute("INSERT INTO robots (robot_key) VALUES ('R1')")
        c.execute("INSERT INTO runs (run_uuid, robot_key, robot_model, cell, station, station_version, local_run_id, "
                  "kind, outcome, started_utc, finished_utc) VALUES (gen_random_uuid(), 'R1', 'sr800', 'c', 's', '0.1', "
                  "1, 'calibration', 'SUCCESS', now(), now())")
        with pytest.raises(store.FleetStoreError, match="schema version"):
            store.connect(db.admin_url).close()  # a station refuses a store behind its schema
        assert migrate(c) == [latest_version()]
    with store.connect(db.dashboard_url, read_only=True) as c:
        assert [r["robot_key"] for r in store.latest_runs(c)] == ["R1"]


def test_a_finished_run_is_published_with_its_figures_and_parameters(fleet_db, tmp_path):
    cfg = example_config()
    path = tmp_path / "runs.sqlite"
    run_id = finished_run(path, cfg)
    line = publish_or_queue(path, run_id, cfg, url=fleet_db.station_url)
    assert line is not None and "published" in line
    with store.connect(fleet_db.dashboard_url, read_only=True) as c:
        (row,) = store.robot_history(c, "SR-0001")
        detail = store.run_detail(c, row["run_uuid"])
    assert row["kind"] == "calibration" and row["outcome"] == "SUCCESS" and row["station"] == "cart-1"
    assert row["rms_after_um"] == pytest.approx(11.0) and row["gain"] == pytest.approx(680 / 11)
    assert detail is not None
    ident = detail["detail"]["identification"]
    assert ident["names"] == ["R.x", "R.y"] and ident["covariance"] == [[4e-6, 1e-7], [1e-7, 2e-6]]
    assert detail["fingerprint"] == {"[cell]": "5d3478fb28c75e88"}
    assert detail["detail"]["controller"] == "controller X"
    assert pending(path) == []


def test_a_recheck_is_published_with_its_verdict_and_drift(fleet_db, tmp_path):
    cfg = example_config()
    path = tmp_path / "runs.sqlite"
    run_id = finished_run(path, cfg, recheck_summary, drift_um=45.0)
    publish_or_queue(path, run_id, cfg, url=fleet_db.station_url)
    with store.connect(fleet_db.dashboard_url, read_only=True) as c:
        (row,) = store.robot_history(c, "SR-0001")
    assert (row["kind"], row["outcome"], row["drift_rms_um"], row["tolerance_um"]) == ("recheck", "DRIFTED", 45.0, 30.0)


def test_no_fleet_store_configured_leaves_the_run_database_as_it_was(tmp_path, monkeypatch):
    monkeypatch.delenv("STATION_FLEET_URL", raising=False)
    cfg = example_config()
    path = tmp_path / "runs.sqlite"
    run_id = finished_run(path, cfg)
    assert publish_or_queue(path, run_id, cfg) is None
    assert queue_state(path) == []


def test_an_outage_queues_the_run_and_sync_publishes_it_exactly_once(fleet_db, pg_server, tmp_path):
    cfg = example_config()
    path = tmp_path / "runs.sqlite"
    pg_server.stop()
    try:
        run_id = finished_run(path, cfg)
        line = publish_or_queue(path, run_id, cfg, url=fleet_db.station_url)
        assert line is not None and "queued" in line and "station sync" in line
        (entry,) = pending(path)
        assert entry.attempts == 1 and entry.last_error
        assert not sync(path, fleet_db.station_url).ok  # still down: still queued
    finally:
        pg_server.start()
    first = sync(path, fleet_db.station_url)
    assert (first.sent, first.already, first.failed) == (1, 0, 0)
    again = sync(path, fleet_db.station_url)
    assert (again.sent, again.already, again.failed) == (0, 0, 0)
    assert fleet_db.count() == 1


def test_a_sync_that_died_after_the_store_committed_is_not_published_twice(fleet_db, tmp_path):
    """The store committed, the station's queue did not hear of it (the link dropped, the PC
    died): the retry finds the run UUID there and inserts nothing."""
    cfg = example_config()
    path = tmp_path / "runs.sqlite"
    run_id = finished_run(path, cfg)
    enqueue_run(path, run_id, cfg)
    (entry,) = pending(path)
    with store.connect(fleet_db.station_url) as c:
        assert store.insert_publication(c, entry.publication)
    result = sync(path, fleet_db.station_url)
    assert (result.sent, result.already, result.failed) == (0, 1, 0)
    assert fleet_db.count() == 1 and pending(path) == []


def test_two_stations_and_two_syncs_of_one_queue_at_once_publish_each_run_once(fleet_db, tmp_path):
    paths = []
    for n, serial in enumerate(("SR-A", "SR-B")):
        cfg = example_config(serial, station=f"cart-{n}")
        path = tmp_path / f"station{n}.sqlite"
        for drift in (5.0, 6.0, 7.0):
            enqueue_run(path, finished_run(path, cfg, recheck_summary, drift_um=drift), cfg)
        paths.append(path)
    barrier = threading.Barrier(4)
    results = []

    def go(path):
        barrier.wait()
        results.append(sync(path, fleet_db.station_url))

    threads = [threading.Thread(target=go, args=(p,)) for p in (*paths, *paths)]  # each queue twice at once
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert all(r.ok for r in results) and len(results) == 4
    assert sum(r.sent for r in results) == 6
    assert fleet_db.count() == 6 and fleet_db.count("robots") == 2
    assert all(pending(p) == [] for p in paths)


def test_the_report_follows_its_run(fleet_db, tmp_path):
    cfg = example_config()
    path = tmp_path / "runs.sqlite"
    run_id = finished_run(path, cfg)
    run_uuid = enqueue_run(path, run_id, cfg)
    report = tmp_path / "report.html"
    report.write_text("<html><body><h1>Calibration report</h1></body></html>", encoding="utf-8")
    assert attach_report(path, run_id, report)
    result = sync(path, fleet_db.station_url)
    assert (result.sent, result.reports) == (1, 1)
    with store.connect(fleet_db.dashboard_url, read_only=True) as c:
        assert "Calibration report" in (store.report_html(c, run_uuid) or "")


def test_the_dashboard_role_is_refused_a_write_and_the_station_role_a_read(fleet_db, tmp_path):
    cfg = example_config()
    path = tmp_path / "runs.sqlite"
    publish_or_queue(path, finished_run(path, cfg), cfg, url=fleet_db.station_url)
    with psycopg.connect(fleet_db.dashboard_url, autocommit=True) as c:
        for sql in ("INSERT INTO robots (robot_key) VALUES ('intruder')", "UPDATE runs SET outcome = 'SUCCESS'",
                    "DELETE FROM runs", "DROP TABLE runs"):
            with pytest.raises((psycopg.errors.InsufficientPrivilege, psycopg.errors.ReadOnlySqlTransaction)):
                c.execute(sql)
    with psycopg.connect(fleet_db.station_url, autocommit=True) as c:
        for sql in ("SELECT * FROM runs", "UPDATE runs SET outcome = 'SUCCESS'", "DELETE FROM runs"):
            with pytest.raises(psycopg.errors.InsufficientPrivilege):
                c.execute(sql)
    assert fleet_db.count() == 1


def test_a_station_joining_the_fleet_sends_its_history_once(fleet_db, tmp_path, capsys):
    """'station sync --all': the runs made before [fleet] url was set, each with the
    configuration it was made with."""
    from station.ui.cli.main import main

    cfg = example_config(serial="")
    path = tmp_path / "runs.sqlite"
    for _ in range(3):
        finished_run(path, cfg)
    assert main(["sync", "--all", "--db", str(path), "--url", fleet_db.station_url]) == 0
    assert "3 run(s) sent" in capsys.readouterr().out
    assert main(["sync", "--all", "--db", str(path), "--url", fleet_db.station_url]) == 0
    assert fleet_db.count() == 3
    with store.connect(fleet_db.dashboard_url, read_only=True) as c:
        (key,) = store.robot_keys(c)
    assert key.endswith("/" + cfg.name)  # no serial: station/cell


def _until_the_clock_passes_the_summary(path, run_id: int, timeout_s: float = 5.0) -> None:
    """Wait until the run database's clock (``utc_now``, µs) reads later than the stored summary's
    time stamp, so that the next summary is another ending: the condition itself, not a pause."""
    import sqlite3

    from station.cell.records.run_records import utc_now

    with contextlib.closing(sqlite3.connect(path)) as conn:
        (stamp,) = conn.execute("SELECT t_utc FROM results WHERE run_id = ? AND key = 'summary'", (run_id,)).fetchone()
    deadline = time.monotonic() + timeout_s
    while utc_now() <= stamp:  # the same ISO format: the strings order as the times
        assert time.monotonic() < deadline, f"the clock did not pass {stamp} within {timeout_s} s"


def test_a_run_that_ends_again_after_a_resume_is_a_new_publication(fleet_db, tmp_path):
    """A stopped run is published with its outcome; resumed and finished, its new ending is
    published beside it (its history), and neither is ever sent twice."""
    from station.cell.records.rundb import RunDB

    cfg = example_config()
    path = tmp_path / "runs.sqlite"
    run_id = finished_run(path, cfg, lambda rid, cell: {"outcome": "DEVICE_FAULT", "run_id": rid, "cell": cell})
    first = publish_or_queue(path, run_id, cfg, url=fleet_db.station_url)
    assert first is not None and "published" in first
    assert "published" in (publish_or_queue(path, run_id, cfg, url=fleet_db.station_url) or "")  # the same ending
    assert fleet_db.count() == 1
    _until_the_clock_passes_the_summary(path, run_id)  # the summary's time stamp tells the endings apart
    with RunDB(path) as db:
        db.save_result(run_id, "summary", {"outcome": "SUCCESS", "run_id": run_id, "cell": cfg.name,
                                           "after": {"rms_um": 11.0, "ap_max_um": 14.0}, "gain": 60.0})
    publish_or_queue(path, run_id, cfg, url=fleet_db.station_url)
    assert fleet_db.count() == 2
    with store.connect(fleet_db.dashboard_url, read_only=True) as c:
        assert [r["outcome"] for r in store.robot_history(c, "SR-0001")] == ["DEVICE_FAULT", "SUCCESS"]
