"""One stream of run facts (issue 42): the run's figure events carry the figures the run stores
in its summary and prints as its JSON, and the stream hands them to every subscriber."""

from __future__ import annotations

import numpy as np
import pytest

from station.cell.pipeline.calibration import Options, run_calibration
from station.cell.run.facts.events import (
    Event,
    Identified,
    MeasurementRecorded,
    Notice,
    RunEnded,
    RunFinished,
    RunStarted,
    TableDesigned,
    Uploaded,
    Verified,
)
from station.cell.run.facts.stream import RunStream
from station.errors import Outcome

# --- the stream itself -----------------------------------------------------------------------------


def test_each_subscriber_gets_the_events_of_its_kind_in_order_until_it_unsubscribes():
    got: list[tuple[str, Event]] = []
    stream = RunStream(lambda e: got.append(("all", e)))
    token = stream.subscribe(lambda e: got.append(("ended", e)), RunEnded)
    stream.subscribe(lambda e: got.append(("notice", e)), Notice)
    started, note = RunStarted(1, 3), Notice("info", "n")
    stream(started)
    stream(note)
    assert got == [("all", started), ("all", note), ("notice", note)]
    got.clear()
    from station.cell.records.summary import RunSummary

    finished = RunFinished(RunSummary(outcome=Outcome.SUCCESS, run_id=1))
    stream(finished)  # a RunFinished is a RunEnded: the subscriber of the base kind gets it
    assert got == [("all", finished), ("ended", finished)]
    assert finished.outcome == "SUCCESS" and finished.exit_code == 0
    stream.unsubscribe(token)
    stream.unsubscribe(token)  # twice: nothing
    got.clear()
    stream(finished)
    assert got == [("all", finished)] and len(stream) == 2


def test_a_subscriber_that_fails_stops_the_emit_and_a_kind_must_be_an_event():
    stream = RunStream()

    def broken(event: Event) -> None:
        raise RuntimeError("view gone")

    stream.subscribe(broken)
    with pytest.raises(RuntimeError, match="view gone"):
        stream(Notice("info", "x"))
    with pytest.raises(TypeError):
        stream.subscribe(print, int)  # type: ignore[type-var]


# --- one run's facts --------------------------------------------------------------------------------



def test_one_runs_events_carry_the_figures_of_its_stored_summary_and_json(cell):
    events: list[Event] = []
    tables: list[TableDesigned] = []
    stream = RunStream(events.append)
    stream.subscribe(tables.append, TableDesigned)
    summary = run_calibration(cell.cfg, cell.probe, cell.ctrl, cell.db, stream, options=Options())
    assert summary.outcome is Outcome.SUCCESS
    stored = cell.db.load_result(summary.run_id, "summary")
    assert stored == summary.to_json()

    def one(kind):
        found = [e for e in events if isinstance(e, kind)]
        assert len(found) == 1, (kind, found)
        return found[0]

    # in the order the run reached them, after every identification measurement and before the end
    order = [type(e) for e in events if isinstance(e, (Identified, TableDesigned, Uploaded, Verified, RunEnded))]
    assert order == [Identified, TableDesigned, Uploaded, Verified, RunFinished]
    last_measured = max(i for i, e in enumerate(events) if isinstance(e, MeasurementRecorded))
    assert events.index(one(RunFinished)) > last_measured and events[-1] is one(RunFinished)

    ident = one(Identified)
    assert ident.identification == summary.identification
    assert stored["identification"]["rms_residual_um"] == ident.identification.rms_residual_um
    assert [p["sigma"] for p in stored["identification"]["parameters"]] == [
        p.sigma for p in ident.identification.parameters]
    np.testing.assert_array_equal(ident.params, cell.db.load_result(summary.run_id, "identification")["params"])

    designed = one(TableDesigned)
    assert tables == [designed]  # the subscriber of one kind got that one event
    assert designed.correction == summary.correction
    bound = stored["correction"]["interpolation_bound_um"]
    assert designed.correction.interpolation_bound_um == bound
    assert cell.db.load_result(summary.run_id, "correction_grid")["bound_um"] == bound
    assert list(designed.correction.grid_shape) == stored["correction"]["grid_shape"]

    up = one(Uploaded)
    assert up.upload == summary.upload and up.upload.crc32 == stored["upload"]["crc32"]
    assert up.active_crc32 == stored["correction"]["crc32"] == f"{cell.srv.controller_server.active_table.crc32():08x}"

    ver = one(Verified)
    assert (ver.before, ver.after) == (summary.before, summary.after)
    assert ver.before is not None
    assert (ver.before.rms_um, ver.after.rms_um, ver.gain) == (
        stored["before"]["rms_um"], stored["after"]["rms_um"], stored["gain"])

    end = one(RunFinished)
    assert (end.outcome, end.exit_code) == (stored["outcome"], stored["exit_code"]) == ("SUCCESS", 0)
    assert end.summary.to_json() == stored

