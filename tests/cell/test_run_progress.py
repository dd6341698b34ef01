"""Progress "k of n" (issue 42): the run counts its touches in the order made and streams them as
``Progress``; the CLI's and the terminal UI's bars show that count, never the plan's index, which
jumps back and forth while the body is located (its first, farthest and next-farthest points come
first) and which knows nothing of the search touches and the warm-up's cycles."""

from __future__ import annotations

import io
import shutil
from pathlib import Path

import pytest

from station.cell.records.rundb import RunDB
from station.cell.run.facts import events as ev
from station.cell.run.facts.progress import RunProgress
from station.cell.run.facts.stream import RunStream
from station.cell.run.locate import RESULT_KEY
from station.cell.session.calibrate import CellRequest, run_calibration_session
from station.errors import Outcome
from station.ui.cli.commands_cell import progress_printer
from station.ui.cli.process.progress_clock import ProgressClock
from station.ui.simulated_cell import load_cell

CELL = Path(__file__).resolve().parent / "data" / "integrator_scara"


def _progress(events: list[ev.Event]) -> list[tuple[int, int]]:
    return [(e.done, e.total) for e in events if isinstance(e, ev.Progress)]


def test_the_count_goes_up_by_touch_and_the_total_grows_with_each_touch_the_plan_did_not_hold():
    got: list[ev.Event] = []
    p = RunProgress(got.append)
    p.start(5, 1)  # a resumed run: one step valid on disk
    p.measured(3, "identification: C3")
    p.inserted("locating the body: C0, searched")
    p.measured(0, "identification: C0")
    p.measured(3, "identification: C3")  # measured again in this attempt: a touch beyond the plan
    assert _progress(got) == [(1, 5), (2, 5), (3, 6), (4, 6), (5, 7)]
    assert got[1] == ev.Progress(2, 5, "identification: C3")
    p.finish()  # the run needs no more: two planned steps were not measured (an upload declined)
    assert _progress(got)[-1] == (5, 5)
    with pytest.raises(ValueError):
        p.start(3, 4)


def test_the_cli_counts_k_of_n_from_the_stream_not_from_the_plans_index():
    out = io.StringIO()
    show = progress_printer(out, ProgressClock(now=lambda: 0.0))
    show(ev.RunStarted(1, 40))
    for k, index in enumerate((0, 17, 34, 1), start=1):  # locating first: the plan's index jumps
        show(ev.StepStarted(index, 40, f"C{index}"))
        show(ev.Progress(k, 40, f"identification: C{index}"))
        show(ev.MeasurementRecorded(index, 40, f"C{index}", True, 1.0))
    lines = [ln.split()[0] for ln in out.getvalue().splitlines()[1:]]
    assert lines == ["1/40", "2/40", "3/40", "4/40"]


@pytest.fixture(scope="module")
def located_run(tmp_path_factory):
    """An integrator's SCARA whose base stands 3.2 mm from its file (tests/cell/test_locate_body.py):
    the body is searched for, located, and the run calibrates; with a warm-up of 2 cycles."""
    folder = tmp_path_factory.mktemp("located") / "cell"
    shutil.copytree(CELL, folder)
    cfg = folder / "cell.toml"
    cfg.write_text(cfg.read_text() + "\n[warmup]\nenabled = true\nuntil = \"converged\"\nmax_cycles = 2\n"
                                     "converged_um = 0.001\nprogram_poses = 2\n")
    events: list[ev.Event] = []
    stream = RunStream(events.append)
    db = folder / "runs.sqlite"
    summary = run_calibration_session(CellRequest(config=str(cfg), simulated=True, db=str(db)), stream,
                                      load=load_cell)
    with RunDB(db) as rdb:
        plan = len(rdb.run(summary.run_id).plan)
        located = rdb.load_result(summary.run_id, RESULT_KEY)
        warmup = rdb.load_result(summary.run_id, "warmup")
    return summary, events, plan, located, warmup


def test_a_located_runs_progress_never_goes_back_and_ends_at_n_of_n(located_run):
    summary, events, plan, located, warmup = located_run
    assert summary.outcome is Outcome.SUCCESS, summary.failure
    # the premise: the plan's index jumps (back, too) while the body is located, and it was searched for
    index = [e.index for e in events if isinstance(e, ev.MeasurementRecorded)]
    assert any(b < a for a, b in zip(index, index[1:])) and located["search_touches"] >= 1
    assert warmup["cycles"] == 2
    seen = _progress(events)
    assert seen[0] == (0, plan)  # the start: nothing on disk, the plan's steps to do
    assert all(b[0] >= a[0] and b[1] >= a[1] for a, b in zip(seen, seen[1:])), seen
    assert all(k <= n for k, n in seen)
    # n of n at the end, n the plan's steps and every touch the plan did not hold: the search's and the
    # warm-up's (the built-in figures, not the count's own: from the run database)
    extra = located["search_touches"] + warmup["cycles"]
    assert seen[-1] == (plan + extra, plan + extra)
    assert isinstance(events[-1], ev.RunFinished)
    # every measurement is counted when it is on disk: its Progress comes just before its record
    for i, e in enumerate(events):
        if isinstance(e, ev.MeasurementRecorded):
            assert isinstance(events[i - 1], ev.Progress) and events[i - 1].label.endswith(e.label)


def test_the_cli_bar_of_a_located_run_counts_up_to_n_of_n(located_run):
    _, events, plan, _, _ = located_run
    out = io.StringIO()
    show = progress_printer(out, ProgressClock(now=lambda: 0.0))
    for e in events:
        show(e)
    counts = [ln.split()[0] for ln in out.getvalue().splitlines() if ln.startswith("  ") and "/" in ln.split()[0]]
    k = [int(c.split("/")[0]) for c in counts if c.split("/")[0].isdigit()]
    assert k and all(b > a for a, b in zip(k, k[1:])), k
    n = _progress(events)[-1][1]
    assert counts[-1] == f"{n}/{n}" and n > plan
