"""The fleet outbox is a subscriber of the run's stream (issue 42): a run's end on the stream
(finished, or failed once its failure is stored) is queued and sent to the fleet store exactly once;
a session subscribes it, so a simulated run that is stopped reaches the store with its failure."""

from __future__ import annotations

import pytest
from fleet_runs import example_config, finished_run

from station.cell.publication.outbox import queue_state
from station.cell.publication.subscriber import FleetOutbox
from station.cell.records.summary import RunSummary
from station.cell.run.facts import events as ev
from station.cell.run.facts.stream import RunStream
from station.cell.run.runcontrol import RunControl
from station.cell.session.calibrate import CellRequest, run_calibration_session
from station.errors import Outcome
from station.fleet import store
from station.ui.simulated_cell import load_cell


def test_each_run_that_ends_on_the_stream_reaches_the_store_exactly_once(fleet_db, tmp_path):
    cfg = example_config()
    path = tmp_path / "runs.sqlite"
    run_id = finished_run(path, cfg)
    events: list[ev.Event] = []
    stream = RunStream(events.append)
    FleetOutbox.subscribe(stream, path, cfg, url=fleet_db.station_url)
    stream(ev.RunStarted(run_id, 3))
    stream(ev.Notice("info", "not an end"))
    assert fleet_db.count() == 0 and queue_state(path) == []  # nothing but an end is published
    finished = ev.RunFinished(RunSummary(outcome=Outcome.SUCCESS, run_id=run_id))
    stream(finished)
    stream(finished)  # told twice, and then that closing the devices failed: the run is published once
    stream(ev.RunFailed(RunSummary(outcome=Outcome.INTERNAL_ERROR, run_id=run_id)))
    assert fleet_db.count() == 1 and len(queue_state(path)) == 1
    said = [e for e in events if isinstance(e, ev.Notice) and e.message.startswith("fleet:")]
    assert len(said) == 1 and "published" in said[0].message and said[0].level == "info"
    assert events.index(said[0]) == events.index(finished) + 1  # the views hear the end, then the publication
    with store.connect(fleet_db.dashboard_url, read_only=True) as c:
        (row,) = store.robot_history(c, "SR-0001")
    assert row["outcome"] == "SUCCESS" and row["local_run_id"] == run_id


def test_a_store_that_cannot_be_reached_never_stops_the_run_and_the_run_stays_queued(tmp_path):
    cfg = example_config()
    path = tmp_path / "runs.sqlite"
    run_id = finished_run(path, cfg)
    events: list[ev.Event] = []
    stream = RunStream(events.append)
    FleetOutbox.subscribe(stream, path, cfg, url="postgresql://station@127.0.0.1:9/fleet?connect_timeout=2")
    stream(ev.RunFinished(RunSummary(outcome=Outcome.SUCCESS, run_id=run_id)))  # no exception reaches the run
    (said,) = [e for e in events if isinstance(e, ev.Notice)]
    assert said.level == "warning" and "queued, not yet published" in said.message
    (entry,) = queue_state(path)
    assert entry.run_id == run_id and not entry.sent and entry.attempts == 1


@pytest.mark.timeout(300)
def test_a_stopped_simulated_run_is_published_with_its_stored_failure(fleet_db, tmp_path, monkeypatch):
    monkeypatch.setenv("STATION_FLEET_URL", fleet_db.station_url)
    control = RunControl()
    control.abort()  # stopped at the first safe point: RunFailed comes from the session
    events: list[ev.Event] = []
    db = tmp_path / "runs.sqlite"
    summary = run_calibration_session(CellRequest(simulated=True, db=str(db)), events.append, control,
                                      load=load_cell)
    assert summary.outcome is Outcome.ABORTED and summary.run_id == 1
    assert fleet_db.count() == 1
    (entry,) = queue_state(db)
    assert entry.sent and entry.publication["outcome"] == "ABORTED"  # the failure as stored, not before
    ended = [i for i, e in enumerate(events) if isinstance(e, ev.RunEnded)]
    said = [i for i, e in enumerate(events) if isinstance(e, ev.Notice) and e.message.startswith("fleet:")]
    assert len(ended) == 1 and len(said) == 1 and said[0] > ended[0]
