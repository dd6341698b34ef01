"""One full simulated calibration through the operator UI, at 80×24 and 160×48: pause,
resume, abort, resume from the list of unfinished runs, upload confirmation and roll back."""

from __future__ import annotations

import pytest
from textual.widgets import DataTable

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


@pytest.mark.slow
@pytest.mark.timeout(300)  # two whole simulated runs through the UI: minutes on a loaded 2-core machine
@pytest.mark.parametrize("size", [(80, 24), (160, 48)])
async def test_full_simulated_run_with_pause_abort_resume_upload_and_roll_back(tmp_path, size):
    app = make_app(CellRequest(simulated=True, db=str(tmp_path / "runs.sqlite")))
    async with app.run_test(size=size) as pilot:
        table = app.query_one("#measurements", DataTable)
        await pilot.press("s")
        await wait_until(pilot, lambda: table.row_count >= 3, "3 rows")
        await pilot.press("p")
        await wait_until(pilot, lambda: app.state == "paused", "paused")
        n = table.row_count
        await pilot.pause(0.2)
        assert table.row_count == n and not app.eta.running
        await pilot.press("p")
        await wait_until(pilot, lambda: table.row_count > n, "running again")
        # the abort key acts on the main screen of a running run (a modal screen takes the keys,
        # and the app's bindings are not reached under it): wait for that, not for a clock
        await wait_until(pilot, lambda: app.state == "running" and not app.screen.is_modal, "running, main screen")
        await pilot.press("a")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen), "abort?")
        await pilot.press("y")
        await wait_until(pilot, lambda: app.state == "aborted" and app.worker.is_finished, "aborted")
        run_id = app.summary.run_id
        text = app.result_text
        assert app.exit_code == 6 and f"run #{run_id} goes on" in text
        assert f"station calibrate --simulated --db {tmp_path / 'runs.sqlite'} --resume {run_id}" in " ".join(text.split())

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
