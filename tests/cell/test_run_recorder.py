"""The run database's writer is a subscriber of the runner's stream (issue 42), the first one: a view
hears of a measurement once it is committed (read through another connection), and a writer that
fails stops the run at that step, before its next motion and before any view counts it."""

from __future__ import annotations

import pytest

from station.cell.pipeline.calibration import run_calibration
from station.cell.records.rundb import RunDB
from station.cell.run.facts import events as ev
from station.cell.run.facts.stream import RunStream
from tests.cell.test_pipeline import Cell


@pytest.fixture
def cell(tmp_path):
    c = Cell(tmp_path)
    yield c
    c.close()


def test_views_hear_of_a_committed_measurement_and_a_failed_write_stops_the_run(cell, tmp_path):
    events: list[ev.Event] = []
    on_disk_when_heard: list[tuple[int, bool]] = []
    reader = RunDB(tmp_path / "runs.sqlite")  # another connection: sees what is committed only

    def view(e: ev.Event) -> None:
        events.append(e)
        if isinstance(e, (ev.StepMeasured, ev.MeasurementRecorded)):
            on_disk_when_heard.append((e.index, e.index in reader.completed_steps(1)))

    moves: list[int] = []
    move = cell.ctrl.move_joints

    def counted_move(*a, **kw):
        moves.append(len(calls))  # the writes tried before this motion
        return move(*a, **kw)

    cell.ctrl.move_joints = counted_move
    write = cell.db.record_measurement
    calls = []

    def disk_full_at_the_fourth(*a, **kw):
        calls.append(a[1])
        if len(calls) == 4:
            raise OSError(28, "No space left on device")
        return write(*a, **kw)

    cell.db.record_measurement = disk_full_at_the_fourth
    with pytest.raises(OSError, match="No space left"):
        run_calibration(cell.cfg, cell.probe, cell.ctrl, cell.db, RunStream(view))
    try:
        stored = reader.completed_steps(1)
    finally:
        reader.close()
    assert len(calls) == 4 and stored == set(calls[:3])
    heard = [i for i, _ in on_disk_when_heard]
    assert all(ok for _, ok in on_disk_when_heard), on_disk_when_heard  # on disk before any view hears
    assert set(heard) == set(calls[:3]) and calls[3] not in heard  # the failed step: never heard of
    last = max(i for i, e in enumerate(events) if isinstance(e, ev.StepStarted))
    assert events[last].index == calls[3]  # no step started after it
    assert not any(isinstance(e, ev.Progress) and e.done > 3 for e in events)  # nor counted
    assert moves and max(moves) == 3  # and nothing moved after the failed write (the 4th step's motions: before it)


def test_a_subscriber_that_comes_first_is_called_before_those_there_and_unsubscribes_alike():
    got: list[str] = []
    stream = RunStream(lambda e: got.append("view"))
    token = stream.subscribe(lambda e: got.append("writer"), ev.Notice, first=True)
    stream(ev.Notice("info", "x"))
    stream(ev.Paused(1))  # not a Notice: the writer is not called
    assert got == ["writer", "view", "view"]
    stream.unsubscribe(token)
    got.clear()
    stream(ev.Notice("info", "x"))
    assert got == ["view"]
