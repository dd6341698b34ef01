"""One full simulated calibration through the operator UI, at 80×24 and 160×48: pause,
resume, abort, resume from the list of unfinished runs, upload confirmation and roll back.

The simulated robot at time scale 0 may outrun the UI: the abort must land on a run that is still
measuring, so the runner is held at a safe point (``RunControl.checkpoint``) once it is past the row
the test waits for, and let go when the abort is confirmed. The run then ends at that safe point as
the operator's abort says, on any plan length and any load (issue 42: on a short plan the resumed
run reached the upload question before the test's abort)."""

from __future__ import annotations

import threading

import pytest
from textual.widgets import DataTable

from station.cell.run.runcontrol import RunControl
from station.cell.session.calibrate import CellRequest
from station.errors import Outcome
from station.ui.report.paths import report_dir
from station.ui.tui.launch import make_app
from station.ui.tui.screens import QuestionScreen, ResumeScreen
from station.ui.tui.widgets import ConfirmScreen


async def wait_until(pilot, cond, what: str, rounds: int = 4000) -> None:
    for _ in range(rounds):
        if cond():
            return
        await pilot.pause(0.01)
    app = pilot.app
    summary = app.summary
    how = (f"state {app.state}, screen {type(app.screen).__name__}, outcome "
           f"{summary.outcome.name if summary else None}, failure {summary.failure if summary else None}")
    notices = "\n".join(line.plain for line in app.query_one("#notices")._lines[-12:])
    raise AssertionError(f"timed out waiting for: {what} ({how})\nlast notices:\n{notices}")


class Hold:
    """Holds the runner at its first safe point of a step at or past ``from_step`` until
    :meth:`release` (a held runner stands still, as at a pause the UI did not ask for)."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.from_step: int | None = None
        self.held, self.released = threading.Event(), threading.Event()
        checkpoint = RunControl.checkpoint

        def held_checkpoint(control: RunControl, timeout: float | None = None, **kw) -> bool:
            if self.from_step is not None and kw.get("index", 0) >= self.from_step and not self.released.is_set():
                self.held.set()
                self.released.wait(HOLD_S)
            return checkpoint(control, timeout, **kw)

        monkeypatch.setattr(RunControl, "checkpoint", held_checkpoint)

    def release(self) -> None:
        self.released.set()


HOLD_S = 280  # a hang guard: a failing test lets the runner go before pytest's timeout ends it


@pytest.mark.slow
@pytest.mark.timeout(300)  # two whole simulated runs through the UI: minutes on a loaded 2-core machine
@pytest.mark.parametrize("size", [(80, 24), (160, 48)])
async def test_full_simulated_run_with_pause_abort_resume_upload_and_roll_back(tmp_path, size, short_cell,
                                                                                 monkeypatch):
    # the built-in cell with one visit per identification pose and one verification cycle: the
    # operator's keys and screens are the same on a shorter run (issue 42: the suite's time)
    hold = Hold(monkeypatch)
    app = make_app(CellRequest(config=str(short_cell), simulated=True, db=str(tmp_path / "runs.sqlite")))
    try:
        await _pause_abort_resume_upload_roll_back(app, size, tmp_path, short_cell, hold)
    finally:
        hold.release()


async def _pause_abort_resume_upload_roll_back(app, size, tmp_path, short_cell, hold: Hold) -> None:
    async with app.run_test(size=size) as pilot:
        table = app.query_one("#measurements", DataTable)
        await pilot.press("s")
        await wait_until(pilot, lambda: table.row_count >= 3, "3 rows")
        await pilot.press("p")
        await wait_until(pilot, lambda: app.state == "paused", "paused")
        n = table.row_count
        await pilot.pause(0.2)
        assert table.row_count == n and not app.eta.running
        hold.from_step = n + 1  # past the next row: the resumed run shows it, then stands still
        await pilot.press("p")
        await wait_until(pilot, lambda: table.row_count > n and hold.held.is_set(), "running again")
        # the abort key acts on the main screen of a running run (a modal screen takes the keys,
        # and the app's bindings are not reached under it): wait for that, not for a clock
        await wait_until(pilot, lambda: app.state == "running" and not app.screen.is_modal, "running, main screen")
        await pilot.press("a")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen), "abort?")
        await pilot.press("y")
        await wait_until(pilot, lambda: app.state == "aborting", "aborting")
        hold.release()  # the runner goes on to its next safe point, where the abort ends it
        await wait_until(pilot, lambda: app.state == "aborted" and app.worker.is_finished, "aborted")
        run_id = app.summary.run_id
        text = app.result_text
        assert app.exit_code == 6 and f"run #{run_id} goes on" in text
        assert (f"station calibrate --simulated {short_cell} --db {tmp_path / 'runs.sqlite'} --resume {run_id}"
                in " ".join(text.split()))

        await pilot.press("r")
        await wait_until(pilot, lambda: isinstance(app.screen, ResumeScreen), "resume list")
        await pilot.press("enter")
        await wait_until(pilot, lambda: isinstance(app.screen, QuestionScreen), "upload?", 20000)
        assert app.run_id == run_id
        await pilot.press("y")
        await wait_until(pilot, lambda: isinstance(app.screen, QuestionScreen)
                         and type(app.screen.question).__name__ == "KeepCorrection", "keep?", 20000)
        await pilot.press("n")  # roll back
        await wait_until(pilot, lambda: app.worker.is_finished and app.summary is not None, "ended", 20000)
        await wait_until(pilot, lambda: app.report_path is not None, "report", 6000)
        assert app.summary.outcome is Outcome.NOT_UPLOADED and app.exit_code == 11
        assert app.report_path.parent == report_dir(tmp_path / "runs.sqlite", run_id) and app.report_path.exists()
