"""``station tui --recheck`` (issue 13): a recheck through the operator UI — the same events,
device panel and result panel, with the recheck's outcome and drift figures."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from textual.widgets import DataTable

from station.cell.recheck.measure import RecheckOptions
from station.cell.session.calibrate import CellRequest
from station.errors import Outcome
from station.ui.cli.main import main
from station.ui.tui import launch as tui_launch
from station.ui.tui.app import StationApp
from station.ui.tui.widgets import DevicePanel


def panel(app: StationApp) -> str:
    """The result panel's rows (unwrapped: the panel wraps long values within their column)."""
    return app.result_text


async def wait_until(pilot, cond, what: str, rounds: int = 12000) -> None:
    for _ in range(rounds):
        if cond():
            return
        await pilot.pause(0.01)
    raise AssertionError(f"timed out waiting for: {what}")


@pytest.fixture(scope="module")
def calibrated_db(tmp_path_factory, seed1_run) -> str:
    """A run database holding a calibration of the simulated cell (seed 1): the baseline (a copy of
    the suite's seed-1 run, since the recheck writes into it)."""
    return str(seed1_run.copy_to(tmp_path_factory.mktemp("recheck")).db)


async def test_simulated_recheck_through_the_ui(calibrated_db):
    request = CellRequest(simulated=True, seed=1, db=calibrated_db)
    app = tui_launch.make_app(request, recheck=RecheckOptions())
    assert "Recheck" in str(app.title)
    async with app.run_test(size=(160, 45)) as pilot:
        await pilot.press("s")
        await wait_until(pilot, lambda: app.worker is not None and app.worker.is_finished, "recheck ended")
        await pilot.pause()
        summary = app.summary
        assert summary is not None, panel(app)
        assert summary.failure is None, summary.failure
        assert summary.outcome is Outcome.SUCCESS and app.exit_code == 0 and app.state == "finished"
        assert summary.db == calibrated_db  # the worker's converted summary, not the event's copy
        text = panel(app)
        assert re.search(r"^outcome\s+SUCCESS", text, re.MULTILINE), text
        assert "against run 1" in text and "drift over" in text and "µm" in text
        assert re.search(r"^exit code\s+0$", text, re.MULTILINE), text
        assert app.query_one("#measurements", DataTable).row_count > 0
        assert app.query_one("#devices", DevicePanel).snapshot is not None
        assert app.report_path is None  # a recheck writes no calibration report
        await pilot.press("q")
        await wait_until(pilot, lambda: not app.is_running, "app exit")
    assert app.return_code == 0


def test_recheck_options_need_recheck(tmp_path: Path):
    db = str(tmp_path / "runs.sqlite")
    assert main(["tui", "--simulated", "--poses", "5", "--db", db]) == Outcome.CONFIG_ERROR
    assert main(["tui", "--simulated", "--recheck", "--poses", "2", "--db", db]) == Outcome.CONFIG_ERROR
