"""Issue 39: 'station sync --all' publishes a station's history under its configured name, with its
operator and reports; a queued report is read only as the station wrote it; adding [fleet] to a
cell file leaves its earlier calibrations usable as recheck baselines. Real PostgreSQL."""

from __future__ import annotations

import dataclasses
import json
import os
import shutil

import pytest
from fleet_runs import EXAMPLE, example_config, finished_run

from station.cell.config.cell_config import load_config, parse_text
from station.cell.publication.outbox import MAX_REPORT_BYTES, attach_report, enqueue_run, pending, sync
from station.cell.recheck.measure import check_baseline_cell
from station.cell.records.fingerprint import check_same_cell, current_like
from station.cell.records.rundb import RunDB
from station.fleet import store
from station.ui.cli.main import main
from station.ui.report.paths import report_dir

_FLEET = '\n[fleet]\nstation = "cart-9"\nrecheck_interval_days = 14\n'


@pytest.fixture
def cell_with_fleet(tmp_path):
    """The example cell copied, with a [fleet] section naming this station."""
    folder = tmp_path / "cell"
    shutil.copytree(EXAMPLE.parent, folder)
    (folder / "cell.toml").write_text(EXAMPLE.read_text(encoding="utf-8") + _FLEET, encoding="utf-8")
    return folder / "cell.toml"


def test_sync_all_publishes_under_the_configured_station_with_operator_and_report(fleet_db, tmp_path, cell_with_fleet,
                                                                                   capsys):
    cfg = dataclasses.replace(example_config(), fleet=dataclasses.replace(example_config().fleet, station=None))
    path = tmp_path / "runs.sqlite"
    run_id = finished_run(path, cfg)  # made before the station joined the fleet: no [fleet] station
    with RunDB(path) as db:
        db.save_result(run_id, "operator", "A. Operator")  # as 'calibrate --report --operator' records it
    folder = report_dir(path, run_id)
    folder.mkdir()
    (folder / "report.html").write_text("<html><body>report of run 1</body></html>", encoding="utf-8")
    assert main(["sync", str(cell_with_fleet), "--db", str(path), "--url", fleet_db.station_url, "--all",
                 "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert (out["sent"], out["reports"]) == (1, 1)
    with store.connect(fleet_db.dashboard_url, read_only=True) as c:
        (key,) = store.robot_keys(c)
        (row,) = store.robot_history(c, key)
        assert row["station"] == "cart-9" and row["operator"] == "A. Operator" and row["has_report"]
        assert store.report_html(c, row["run_uuid"]) == "<html><body>report of run 1</body></html>"


@pytest.mark.parametrize("kind", ["symlink", "linked_folder", "oversized", "fifo", "other_name"])
def test_a_queued_report_is_read_only_as_the_station_wrote_it(fleet_db, tmp_path, kind):
    cfg = example_config()
    path = tmp_path / "runs.sqlite"
    run_id = finished_run(path, cfg)
    enqueue_run(path, run_id, cfg)
    folder = tmp_path / "report"
    folder.mkdir()
    report = folder / "report.html"
    secret = tmp_path / "secret.txt"
    secret.write_text("root:x:0:0", encoding="utf-8")
    if kind == "symlink":
        report.symlink_to(secret)
    elif kind == "linked_folder":
        (tmp_path / "real").mkdir()
        (tmp_path / "real" / "report.html").write_text("<html></html>", encoding="utf-8")
        folder.rmdir()
        folder.symlink_to(tmp_path / "real")
    elif kind == "oversized":
        with open(report, "wb") as f:
            f.truncate(MAX_REPORT_BYTES + 1)
    elif kind == "fifo":
        os.mkfifo(report)
    else:
        report = secret
    attach_report(path, run_id, report)
    result = sync(path, fleet_db.station_url)
    assert result.sent == 1 and result.reports == 0 and result.failed == 1 and "report" in result.error
    assert fleet_db.count("reports") == 0 and any(not e.report_sent for e in pending(path))


def test_adding_fleet_to_a_cell_file_keeps_its_calibrations_as_baselines(tmp_path, cell_with_fleet):
    before = load_config(EXAMPLE)
    from station.cell.records.fingerprint import fingerprint

    with RunDB(tmp_path / "runs.sqlite") as db:
        run_id = db.create_run(before.source_text, [], None)
        db.save_result(run_id, "fingerprint", fingerprint(before))
        after = load_config(cell_with_fleet)
        check_baseline_cell(db, run_id, after)  # refused before: "[fleet] changed since", exit 2
        stored = db.load_result(run_id, "fingerprint")
    assert check_same_cell(stored, current_like(stored, after), run_id) == ()
    old_style = {**stored, "[fleet]": "0123456789abcdef"}  # a fingerprint stored before issue 39
    assert check_same_cell(old_style, current_like(stored, after), run_id) == ()
    changed = parse_text(after.source_text.replace('station = "cart-9"', 'station = "cart-8"'), str(cell_with_fleet))
    assert fingerprint(changed) == fingerprint(after)
