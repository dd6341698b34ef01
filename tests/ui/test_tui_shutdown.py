"""What reaches the operator UI while it closes (issue 42: the races CI finds under load).

A test that leaves ``app.run_test()`` while the run's worker still runs, and an operator who quits,
both close the app with the worker's messages still on their way: a question of the run, the pause
poll's timer, the worker's own end. The panels are gone then, as here where the main screen's
widgets are removed; nothing may raise, and a question is answered "no" (nothing is uploaded)."""

from __future__ import annotations

from test_tui_features import FakeSession, frozen, wait_until

from station.ui.tui.app import StationApp
from station.ui.tui.screens import QuestionScreen


async def closing(app: StationApp) -> None:
    """The main screen's panels removed, as while the app shuts down."""
    await app.screen.remove_children()
    assert not app.query("#summary") and not app.query("#state")


async def test_a_question_that_arrives_while_the_app_closes_is_answered_no_without_a_dialog():
    session = FakeSession()
    app = StationApp(session, clock=frozen)
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("s")
        await wait_until(pilot, lambda: app.run_id == 7, "run started")
        await closing(app)
        session.open(session.steps)  # the run goes on in its worker; every event finds no panel
        await wait_until(pilot, lambda: app.worker is not None and app.worker.is_finished, "the worker's end")
        await pilot.pause()  # its StateChanged, queued as it ended, handled (the pilot waits for the app's queue)
        assert session.answers == [False]  # "Upload?" answered no: nothing uploaded, no dialog left open
        assert not isinstance(app.screen, QuestionScreen)
        assert app.worker.error is None and app.summary is None  # nothing shown on panels that are gone


async def test_the_pause_poll_after_the_panels_are_gone_is_harmless():
    session = FakeSession()
    app = StationApp(session, clock=frozen)
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("s")
        await wait_until(pilot, lambda: app.run_id == 7, "run started")
        await pilot.press("p")  # the runner waits on the test's gate: the pause is asked, not reached
        assert app.state == "pausing"
        await closing(app)
        session.open()
        await wait_until(pilot, lambda: app.control is not None and app.control.waiting, "runner in its checkpoint")
        app._poll_control()  # its 0.1 s timer, firing now: no panel to show PAUSED on, no error
        assert app.state == "pausing"
        app.control.abort()
        await wait_until(pilot, lambda: app.worker.is_finished, "the aborted run's end")
        await pilot.pause()  # its StateChanged handled
        assert app.worker.error is None and app.summary is None

