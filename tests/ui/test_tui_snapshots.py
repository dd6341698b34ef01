"""Snapshots of the operator UI's main screens at 80×24 (pytest-textual-snapshot).

Deterministic: scripted fake runs (test_tui_features), a frozen clock for the time left, fixed
device snapshots.  Update after an intended change with ``pytest --snapshot-update`` and look at
the SVGs in ``__snapshots__/`` before committing them.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from test_tui_features import RUNS, FakeSession, frozen, paused_after, report_data, wait_until

from station.ui.tui.app import StationApp
from station.ui.tui.result_panel import CellContext
from station.ui.tui.results import ResultsScreen
from station.ui.tui.screens import QuestionScreen, ResumeScreen
from station.ui.tui.widgets import ConfirmScreen

SIZE = (80, 24)
pytest.importorskip("pytest_textual_snapshot")


def app_for(session: FakeSession) -> StationApp:
    return StationApp(session, title="SR 800 — snapshot", clock=frozen, list_runs=lambda: RUNS,
                      load_results=lambda run_id: report_data(), db_label="runs.sqlite")


def test_idle(snap_compare):
    assert snap_compare(app_for(FakeSession()), terminal_size=SIZE)


def test_paused_with_a_rejected_reading(snap_compare):
    session = FakeSession()

    async def before(pilot):
        await paused_after(pilot, session, 4)
        await at_rest(pilot)

    app = released_at_exit(app_for(session))
    assert snap_compare(app, terminal_size=SIZE, run_before=before)


def test_upload_question(snap_compare):
    session = FakeSession(gated=False)

    async def before(pilot):
        await pilot.press("s")
        await wait_until(pilot, lambda: isinstance(pilot.app.screen, QuestionScreen), "question")

    app = app_for(session)
    assert snap_compare(app, terminal_size=SIZE, run_before=before)
    app.control.abort()


CELL = CellContext(name="example SCARA 600 cell", config="examples/scara600/cell.toml", simulated=True,
                   db="runs.sqlite", probe="simulator", controller="simulator")


def cell_app(session: FakeSession) -> StationApp:
    """The example cell's UI: its title, the exact command lines, its head's probe ids."""
    return StationApp(session, clock=frozen, list_runs=lambda: RUNS, load_results=lambda run_id: report_data(),
                      write_report=lambda run_id: Path(f"/srv/station/runs/report-runs-run-{run_id}/report.html"),
                      db_label="runs.sqlite", cell=CELL)


def released_at_exit(app: StationApp) -> StationApp:
    """``app`` whose exit (after the screenshot) first aborts its paused run: ``app.run`` waits for
    the worker's thread at its end, and a paused fake would hold it there through its two 10 s
    timeouts (issue 42: 20 s of each paused snapshot's time was that wait)."""
    leave = app.exit

    def exit_released(*args, **kwargs) -> None:
        if app.control is not None:
            app.control.abort()  # wakes the paused checkpoint at once: the fake's run ends ABORTED
        leave(*args, **kwargs)

    app.exit = exit_released  # type: ignore[method-assign]
    return app


async def at_rest(pilot) -> None:
    """The notices scrolled to their end (after a refresh) and the screen drawn again."""
    notices = pilot.app.query_one("#notices")
    await wait_until(pilot, lambda: notices.scroll_y == notices.max_scroll_y, "notices at their end")
    for _ in range(2):
        await pilot.pause()


async def settled(pilot) -> None:
    """Everything the end of a run changes has happened: the worker's own end (it re-renders the
    result with its return value), the report, the notices scrolled to their end."""
    app = pilot.app
    await wait_until(pilot, lambda: app.worker is not None and app.worker.is_finished and app.summary is not None,
                     "worker")
    notices = app.query_one("#notices")
    await wait_until(pilot, lambda: notices.scroll_y == notices.max_scroll_y, "notices at their end")
    for _ in range(3):
        await pilot.pause()


def test_finished_with_report(snap_compare):
    """The last screen at 80×24: outcome, exit code, RMS before / after, gain, after / oracle and
    the report's path in view without scrolling (issue 20)."""
    async def before(pilot):
        await pilot.press("s")
        await wait_until(pilot, lambda: pilot.app.report_path is not None, "report")
        await settled(pilot)

    assert snap_compare(cell_app(FakeSession(gated=False, ask=False)), terminal_size=SIZE, run_before=before)


def test_aborted_continue_with_one_key(snap_compare):
    """After an abort: c continues the run; the command line shown is the exact one."""
    session = FakeSession(ask=False)

    async def before(pilot):
        await pilot.press("s")
        session.open(3)
        await wait_until(pilot, lambda: pilot.app.query_one("#measurements").row_count == 3, "3 rows")
        await pilot.press("a")
        await wait_until(pilot, lambda: isinstance(pilot.app.screen, ConfirmScreen), "abort?")
        await pilot.press("y")
        session.open()
        await wait_until(pilot, lambda: pilot.app.report_path is not None, "report")  # an aborted run's too
        await settled(pilot)

    assert snap_compare(cell_app(session), terminal_size=SIZE, run_before=before)


def test_running_with_the_heads_probes(snap_compare):
    """The device panel shows the head file's seven probes by id, no unwired channel."""
    session = FakeSession(head=True)

    async def before(pilot):
        await pilot.press("s")
        session.open(4)
        await wait_until(pilot, lambda: pilot.app.query_one("#measurements").row_count == 4, "4 rows")
        await pilot.press("p")
        session.open()
        await wait_until(pilot, lambda: pilot.app.state == "paused", "paused")
        await at_rest(pilot)

    app = released_at_exit(cell_app(session))
    assert snap_compare(app, terminal_size=SIZE, run_before=before)


def test_resume_list(snap_compare):
    async def before(pilot):
        await pilot.press("r")
        await wait_until(pilot, lambda: isinstance(pilot.app.screen, ResumeScreen), "list")

    assert snap_compare(app_for(FakeSession()), terminal_size=SIZE, run_before=before)


def test_results_parameters(snap_compare):
    async def before(pilot):
        await pilot.press("s")
        await wait_until(pilot, lambda: pilot.app.state == "finished", "finished")
        # the worker's own end re-renders the result with its return value: wait for it too
        await wait_until(pilot, lambda: pilot.app.worker is not None and pilot.app.worker.is_finished, "worker")
        await pilot.pause()
        await pilot.press("v")
        await wait_until(pilot, lambda: isinstance(pilot.app.screen, ResultsScreen), "results")
        await pilot.pause()

    assert snap_compare(app_for(FakeSession(gated=False, ask=False)), terminal_size=SIZE, run_before=before)


def test_failed_correction_with_its_next_line(snap_compare):
    """A failure while the correction table is built: what to change and how to resume, no "press c"
    (issue 29); the whole panel in view at 80×24."""
    from test_tui_next import failed_in_correction

    async def before(pilot):
        await pilot.press("s")
        await wait_until(pilot, lambda: pilot.app.report_path is not None, "report")
        await settled(pilot)

    assert snap_compare(cell_app(failed_in_correction), terminal_size=SIZE, run_before=before)


def test_results_of_a_stored_run_in_a_new_session(snap_compare):
    """v with no run in this session: a run picked from the database's list (issue 29)."""
    async def before(pilot):
        await pilot.press("v")
        await wait_until(pilot, lambda: isinstance(pilot.app.screen, ResumeScreen), "list")
        await pilot.press("enter")
        await wait_until(pilot, lambda: isinstance(pilot.app.screen, ResultsScreen), "results")
        pilot.app.clear_notifications()  # "Loading the results …" would cover the figures
        for _ in range(2):
            await pilot.pause()

    assert snap_compare(cell_app(FakeSession()), terminal_size=SIZE, run_before=before)


def test_help(snap_compare):
    assert snap_compare(app_for(FakeSession()), terminal_size=SIZE, press=["question_mark"])
