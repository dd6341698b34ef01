"""The measurement table at 120×40 after the run (issue 37, "smaller finds"): once the result panel
opens, the table still shows the latest rows (it showed 39–41 when the run stopped at 56), and a
note too long for its cell is shortened in the middle - its start and its end kept - not cut at
the right edge."""

from __future__ import annotations

from test_tui_features import SUMMARY, wait_until
from test_tui_signoff import app_for, screen_lines, settled

from station.cell.records.summary import Failure, RunSummary
from station.cell.run.facts.events import MeasurementRecorded, PhaseChanged, RunFailed, RunFinished, RunStarted
from station.errors import Outcome
from station.ui.tui.measurement_table import shorten_middle

SIZE = (120, 40)
STEPS = 56
#: a runner's note: what refused the reading (start) and the figure that decides (end)
LONG = ("probe 4 over range (+2.61 mm > +2.50 mm): tip not in contact; re-centred twice along the face normal "
        "by 0.4 mm and still beyond the stroke, left out of the identification: residual 812.40 µm")


def session(failed: bool):
    def start_run(emit, control):
        emit(PhaseChanged("connect", "simulated cell"))
        emit(RunStarted(run_id=7, n_steps=80))
        emit(PhaseChanged("measure", "identification poses"))
        for i in range(STEPS):
            emit(MeasurementRecorded(i, 80, f"P{i // 3 + 1}{'abc'[i % 3]} elbow +1", i % 7 != 6, 0.02 * i,
                                     LONG if i % 7 == 6 else ""))
        if failed:
            summary = RunSummary(Outcome.DEVICE_FAULT, run_id=7, db="runs.sqlite",
                                 failure=Failure("ProbeTimeout", "no reply within 2 s", "check the probe", "", "probe"))
            emit(RunFailed(summary))
        else:
            summary = SUMMARY
            emit(RunFinished(summary))
        return summary
    return start_run


def _table_rows(app) -> list[str]:
    """The rows of the measurement table on the screen (the table's region)."""
    table = app.query_one("#measurements")
    lines = screen_lines(app)
    return [lines[y][table.region.x:table.region.right] for y in range(table.region.y, table.region.bottom)
            if y < len(lines)]


async def _ended(failed: bool):
    app = app_for(session(failed))
    async with app.run_test(size=SIZE) as pilot:
        await pilot.press("s")
        await settled(pilot, app)
        # the result panel laid out: the table has the height it keeps after the end
        await wait_until(pilot, lambda: app.query_one("#summary-box").region.height > 0, "result panel open")
        for _ in range(3):
            await pilot.pause()
        return _table_rows(app), app.query_one("#measurements").region


async def test_after_a_stop_the_table_shows_the_last_rows():
    rows, region = await _ended(failed=True)
    text = "\n".join(rows)
    assert region.height >= 6
    # the last line inside the border is the step it stopped at: no horizontal scrollbar below it (the
    # notes fit their column), no older rows
    assert rows[-2].strip(" │").startswith(f"{STEPS} "), text
    assert not any(r.strip(" │").startswith("39 ") for r in rows), text


async def test_after_a_finished_run_the_table_shows_the_last_rows_too():
    rows, _ = await _ended(failed=False)
    assert rows[-2].strip(" │").startswith(f"{STEPS} "), "\n".join(rows)


async def test_a_long_note_is_shortened_in_the_middle_keeping_start_and_end():
    rows, _ = await _ended(failed=True)
    notes = [r for r in rows if "probe 4 over range" in r]
    assert notes, "\n".join(rows)
    for r in notes:
        assert "…" in r and r.rstrip(" │").endswith("residual 812.40 µm"), r


def test_shorten_middle():
    assert shorten_middle("short", 10) == "short"
    s = shorten_middle(LONG, 40)
    assert len(s) == 40 and s.startswith("probe 4 over range") and s.endswith("812.40 µm") and "…" in s
    assert shorten_middle(LONG, 1) == "…"
