"""The run database's writer of a calibration's facts subscribes to the run's stream (issue 42): the
pipeline emits its start, plan, identification, table, upload, status and end, and
:class:`~station.cell.run.facts.writer.RunWriter`, the first subscriber, stores each before any view hears
of it. A run's events, its stored records and its JSON summary agree figure for figure; a write that
fails, or a view that raises, stops the run where it stands, every measurement on disk."""

from __future__ import annotations

import numpy as np
import pytest

from station.cell.pipeline.calibration import Options, run_calibration
from station.cell.records.rundb import RunDB
from station.cell.records.summary import RunSummary
from station.cell.run.facts import events as ev
from station.cell.run.facts.stream import RunStream
from station.cell.run.facts.writer import RunWriter
from station.errors import Outcome


def _one(events: list[ev.Event], kind: type) -> ev.Event:
    found = [e for e in events if isinstance(e, kind)]
    assert len(found) == 1, (kind, found)
    return found[0]


def test_a_runs_events_its_stored_records_and_its_json_agree_figure_for_figure(cell, tmp_path):
    events: list[ev.Event] = []
    seen: dict[str, object] = {}  # what another connection read from disk when a view heard of each fact
    reader = RunDB(tmp_path / "runs.sqlite")

    def view(e: ev.Event) -> None:
        events.append(e)
        if isinstance(e, ev.Identified):
            seen["identification"] = reader.load_result(1, "identification", default=None)
            seen["status at identified"] = reader.run(1).status
        elif isinstance(e, ev.TableDesigned):
            seen["correction_grid"] = reader.load_result(1, "correction_grid", default=None)
        elif isinstance(e, ev.Uploaded):
            seen["status at uploaded"] = reader.run(1).status
        elif isinstance(e, ev.RunFinished):
            seen["summary"] = reader.load_result(1, "summary", default=None)

    try:
        summary = run_calibration(cell.cfg, cell.probe, cell.ctrl, cell.db, RunStream(view), options=Options(),
                                  seed=1, devices_info={"probe": "simulated probe head"})
    finally:
        reader.close()
    assert summary.outcome is Outcome.SUCCESS and summary.run_id == 1
    db, run_id = cell.db, summary.run_id
    json = summary.to_json()  # the --json object

    planned, started = _one(events, ev.RunPlanned), _one(events, ev.RunStarted)
    run = db.run(run_id)
    assert (run.config_toml, run.seed, [dict(s) for s in planned.plan]) == (planned.config_toml, 1, list(run.plan))
    assert started.run_id == run_id and started.n_steps == len(run.plan) and not started.resume
    assert db.load_result(run_id, "devices") == {"probe": "simulated probe head"} == dict(started.devices)
    assert db.load_result(run_id, "fingerprint") == planned.fingerprint
    assert db.load_result(run_id, "config_source") == planned.config_source
    assert any(r.message == f"run started: {len(run.plan)} steps, 0 on disk" for r in db.events(run_id))

    ident = _one(events, ev.Identified)
    stored = db.load_result(run_id, "identification")
    assert seen["identification"] == stored and seen["status at identified"] == "identified"  # on disk first
    assert stored["params"] == list(ident.params)
    estimates = ident.identification.parameters
    assert stored["chosen"] == [p.name for p in estimates] == [p["name"] for p in json["identification"]["parameters"]]
    assert stored["sigma"] == [p.sigma for p in estimates] == [p["sigma"] for p in json["identification"]["parameters"]]
    assert [stored["params"][cell.cfg.model.param_index(p.name)] for p in estimates] == [
        p["value"] for p in json["identification"]["parameters"]]
    assert stored["rms_normalized"] == ident.identification.rms_normalized == json["identification"]["rms_normalized"]
    assert stored["outliers"] == list(ident.identification.outliers) == json["identification"]["outliers"]
    cov = np.asarray(stored["covariance"])
    assert cov.shape == (len(estimates),) * 2 and np.array_equal(cov, np.asarray(ident.covariance))
    np.testing.assert_array_equal(np.sqrt(np.diag(cov)), stored["sigma"])  # σ is the covariance's
    assert np.asarray(stored["residuals"]).shape[0] == ident.identification.n_measurements
    assert np.array_equal(np.asarray(stored["residuals"]), np.asarray(ident.residuals))

    designed = _one(events, ev.TableDesigned)
    grid = db.load_result(run_id, "correction_grid")
    assert seen["correction_grid"] == grid  # on disk before the views heard of the table
    bound = designed.correction.interpolation_bound_um
    assert grid["bound_um"] == bound == json["correction"]["interpolation_bound_um"]
    assert grid["predicted_bound_um"] == designed.correction.predicted_bound_um == json["correction"]["predicted_bound_um"]
    assert grid["sampled_bounds_um"] == list(designed.sampled_bounds_um) and len(grid["sampled_bounds_um"]) > 0
    assert {k: grid[k] for k in designed.grid} == dict(designed.grid) and grid["error_terms"] is designed.error_terms
    assert designed.correction.crc32 == json["correction"]["crc32"] == json["upload"]["crc32"]

    up = _one(events, ev.Uploaded)
    assert seen["status at uploaded"] == "uploaded" and up.upload.crc32 == json["upload"]["crc32"]
    ver = _one(events, ev.Verified)
    assert (ver.before.rms_um, ver.after.rms_um, ver.gain) == (json["before"]["rms_um"], json["after"]["rms_um"],
                                                               json["gain"])

    end = _one(events, ev.RunFinished)
    assert seen["summary"] == db.load_result(run_id, "summary") == end.summary.to_json() == json
    # the statuses streamed are the statuses stored, in order
    streamed = [e.status for e in events if isinstance(e, ev.StatusChanged)]
    assert streamed == ["measuring", "measured", "verified"]
    changes = [r.message.split(" -> ")[1] for r in db.events(run_id) if r.message.startswith("status ")]
    assert changes == ["measuring", "measured", "identified", "uploaded", "verified"] and run.status == "verified"


def test_a_failed_write_of_a_fact_stops_the_run_before_its_next_motion_with_every_measurement_on_disk(cell):
    events: list[ev.Event] = []
    motions: list[int] = []
    for name in ("move_joints", "move_cartesian"):
        move = getattr(cell.ctrl, name)

        def counted(*a, _move=move, **kw):
            motions.append(1)
            return _move(*a, **kw)

        setattr(cell.ctrl, name, counted)
    save = cell.db.save_result
    failed: list[int] = []

    def disk_full_at_the_table(run_id, key, obj):
        if key == "correction_grid":
            failed.append(len(motions))
            raise OSError(28, "No space left on device")
        return save(run_id, key, obj)

    cell.db.save_result = disk_full_at_the_table
    active = cell.srv.controller_server.active_table
    with pytest.raises(OSError, match="No space left"):
        run_calibration(cell.cfg, cell.probe, cell.ctrl, cell.db, RunStream(events.append))
    assert len(failed) == 1
    assert not any(isinstance(e, ev.TableDesigned) for e in events)  # no view heard of the table not stored
    assert motions and len(motions) == failed[0]  # nothing moved after the failed write
    last = max(i for i, e in enumerate(events) if isinstance(e, ev.StepMeasured))
    assert not any(isinstance(e, ev.StepStarted) for e in events[last:])
    assert cell.srv.controller_server.active_table is active  # nothing uploaded
    measured = {e.index for e in events if isinstance(e, ev.StepMeasured)}
    assert measured and cell.db.completed_steps(1) == measured  # every measurement made is on disk
    assert cell.db.load_result(1, "identification")["chosen"]  # the facts before it too
    run = cell.db.run(1)
    assert run.status == "failed"
    assert any(r.level == "error" and "No space left" in r.message for r in cell.db.events(1))


def test_a_view_that_raises_stops_the_run_after_the_writer_stored_the_fact(cell):
    events: list[ev.Event] = []

    def view(e: ev.Event) -> None:
        events.append(e)
        if isinstance(e, ev.Identified):
            raise RuntimeError("view gone")

    with pytest.raises(RuntimeError, match="view gone"):
        run_calibration(cell.cfg, cell.probe, cell.ctrl, cell.db, RunStream(view))
    ident = next(e for e in events if isinstance(e, ev.Identified))
    assert cell.db.load_result(1, "identification")["params"] == list(ident.params)  # stored before it was heard
    after = events[events.index(ident):]
    assert not any(isinstance(e, (ev.StepStarted, ev.TableDesigned, ev.RunEnded)) for e in after)
    assert [e.status for e in after if isinstance(e, ev.StatusChanged)] == ["failed"]
    assert cell.db.run(1).status == "failed"
    assert cell.db.load_result(1, "summary", default=None) is None  # no end stored for a run that did not end


def test_the_writer_writes_only_its_own_run(tmp_path):
    with RunDB(tmp_path / "runs.sqlite") as db:
        writer = RunWriter(db)
        with pytest.raises(RuntimeError, match="no run yet"):
            writer(ev.StatusChanged("measuring"))
        writer(ev.RunPlanned('[cell]\nname = "c"\n', ({"index": 0},), 3, "<test>", {"robot": "r"}))
        assert writer.run_id == 1 and db.run(1).plan == ({"index": 0},) and db.run(1).seed == 3
        writer(ev.Notice("info", "nothing to store"))
        with pytest.raises(ValueError, match="run 2's start streamed to the writer of run 1"):
            writer(ev.RunStarted(2, 1))
        with pytest.raises(ValueError, match="second run planned"):
            writer(ev.RunPlanned("", (), None, "", {}))
        with pytest.raises(ValueError, match="run 2's end"):
            writer(ev.RunFinished(RunSummary(outcome=Outcome.SUCCESS, run_id=2)))
        writer(ev.RunFinished(RunSummary(outcome=Outcome.SUCCESS, run_id=1)))
        assert db.load_result(1, "summary")["outcome"] == "SUCCESS"
