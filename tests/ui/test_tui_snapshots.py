"""Snapshots of the operator UI's main screens at 80×24 (pytest-textual-snapshot).

Deterministic: scripted fake runs (test_tui_features), a frozen clock for the time left, fixed
device snapshots.  Update after an intended change with ``pytest --snapshot-update`` and look at
the SVGs in ``__snapshots__/`` before committing them.
"""

from __future__ import annotations

import pytest
from test_tui_features import RUNS, FakeSession, frozen, report_data, wait_until

from station.ui.tui import StationApp
from station.ui.tui_results import ResultsScreen
from station.ui.tui_screens import QuestionScreen, ResumeScreen

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
        app = pilot.app
        await pilot.press("s")
        session.open(4)
        await wait_until(pilot, lambda: app.query_one("#measurements").row_count == 4, "4 rows")
        await pilot.press("p")
        session.open()
        await wait_until(pilot, lambda: app.state == "paused", "paused")
        await pilot.pause()

    app = app_for(session)
    assert snap_compare(app, terminal_size=SIZE, run_before=before)
    app.control.abort()  # release the fake's worker


def test_upload_question(snap_compare):
    session = FakeSession(gated=False)

    async def before(pilot):
        await pilot.press("s")
        await wait_until(pilot, lambda: isinstance(pilot.app.screen, QuestionScreen), "question")

    app = app_for(session)
    assert snap_compare(app, terminal_size=SIZE, run_before=before)
    app.control.abort()


# The finished screen is pinned by the Pilot tests (test_tui_features.py) rather than a snapshot:
# its rendering raced the worker's end in about one run in ten (styling only, the text was equal).


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


def test_help(snap_compare):
    assert snap_compare(app_for(FakeSession()), terminal_size=SIZE, press=["question_mark"])
