"""Issue 29, the operator's screen says what next: one "Next: …" line for every outcome, advice by
the kind of failure (a correction failure is not a rank deficiency; "press c" only where continuing
can succeed), no stale activity line under a dialog, the phase strip's ticks after a continue, a
stable title, "p Resume" while paused, a report for every run with a number, the kept table's
CRC, and the results of a run picked from the database in a new session."""

from __future__ import annotations

import pytest
from test_tui_features import KEEP, PROPOSAL, RUNS, SUMMARY, FakeSession, paused_after, wait_until
from test_tui_signoff import CTX, REPORT, app_for, screen_lines, settled
from textual.content import Content

from drivers.controller_errors import ControllerLinkLost, EmergencyStop
from drivers.correction_table import TableVerifyError
from drivers.probe_protocol import ProbeTimeout
from station.cell.pipeline.outcomes import failure_summary
from station.cell.records.run_records import RunDatabaseError
from station.cell.records.summary import Failure, RunSummary, TableSummary, UploadSummary
from station.cell.run.facts.events import Notice, PhaseChanged, RunFailed, RunFinished, RunStarted
from station.errors import ConfigError, IdentificationError, Outcome, RunAborted, UnreachableError
from station.ui.tui.app import StationApp
from station.ui.tui.result_panel import can_continue, failure_kind, next_step, summary_markup
from station.ui.tui.results import ResultsScreen
from station.ui.tui.screens import QuestionScreen, ResumeScreen
from station.ui.tui.widgets import ConfirmScreen, passed_phases

SIZE = (80, 24)
CORRECTION_FAILURE = Failure(
    "IdentificationError", "the correction table cannot be built for the identified robot: the inverse kinematics "
    "does not converge at 12 of 31680 nodes",
    "no correction was made; fix what the message names (measurements, robot file, [identification] or "
    "[correction]), then resume or run again")


def failed_in_correction(emit, control):
    """The session's events up to a failure while the correction table is built."""
    emit(PhaseChanged("connect", "simulated cell"))
    emit(RunStarted(run_id=7, n_steps=6))
    for phase in ("plan", "measure", "identify", "correct"):
        emit(PhaseChanged(phase))
    summary = RunSummary(Outcome.IDENTIFICATION_FAILED, run_id=7, db="runs.sqlite", failure=CORRECTION_FAILURE)
    emit(RunFailed(summary))
    return summary


def next_lines(text: str) -> list[str]:
    return [line for line in text.splitlines() if line.startswith("Next: ")]


def panel(*args) -> str:
    """The result panel's text (``summary_markup``'s arguments), as the screen shows it."""
    return Content.from_markup(summary_markup(*args)).plain


# -- Next, for every outcome ------------------------------------------------------------------
#: (exception the run stopped with, the phase it was in, whether pressing c can succeed)
STOPS = [
    (RunAborted("run aborted by the operator at a safe point"), "measure", True),
    (ProbeTimeout("no reply within 2 s"), "measure", True),
    (ControllerLinkLost("controller heartbeat did not advance for 3.1 s"), "verify", True),
    (EmergencyStop("emergency stop pressed"), "measure", True),
    (TableVerifyError("read back differs at value 17"), "upload", True),
    (IdentificationError("only 20 of 40 identification poses are valid, 32 are needed (80%); no correction was "
                         "identified. Fix what the warnings name, then resume: the invalid poses are measured again"),
     "identify", True),
    (IdentificationError("rank 17 < 20: the poses do not excite axis 2"), "identify", False),
    (IdentificationError("the inverse kinematics does not converge at 12 nodes"), "correct", False),
    (ConfigError("cell.toml: [correction] region is empty"), "connect", False),
    (UnreachableError("pose 12 leaves the soft limit of J2"), "measure", False),
    (RunDatabaseError("runs.sqlite: not a station run database"), "connect", False),
    (KeyError("missing key"), "identify", False),
]


@pytest.mark.parametrize(("exc", "phase", "continues"), STOPS, ids=lambda v: type(v).__name__ if
                         isinstance(v, BaseException) else str(v))
def test_every_stop_has_one_next_line_and_c_only_where_continuing_can_succeed(tmp_path, exc, phase, continues):
    summary = failure_summary(exc, run_id=7, log_dir=tmp_path)
    text = panel(summary, 3, CTX, 60, phase)
    lines = next_lines(text)
    assert len(lines) == 1 and len(lines[0]) > len("Next: ") + 20, text
    assert can_continue(summary, phase) is continues
    assert ("press c" in text) is continues, text
    assert "What to do" not in text and "Next: then" not in text


def test_a_correction_failure_is_advised_as_one_whatever_its_exit_code():
    summary = failed_in_correction(lambda e: None, None)
    assert failure_kind(summary, "correct") == "correction" and failure_kind(summary, "identify") == "identification"
    advice = next_step(summary, CTX, "correct")
    assert "[correction] in examples/scara600/cell.toml" in advice and "resume run #7" in advice
    assert "rank" not in advice and "press" not in advice


@pytest.mark.parametrize("summary", [
    SUMMARY,
    SUMMARY.replace(outcome=Outcome.TARGET_MISSED),
    SUMMARY.replace(outcome=Outcome.NOT_UPLOADED, upload=None, upload_skipped=True),
    SUMMARY.replace(outcome=Outcome.NOT_UPLOADED, notes=("the new table was rolled back by the operator",)),
    SUMMARY.replace(outcome=Outcome.NOT_UPLOADED, upload=None, upload_skipped=True,
                    not_uploaded_reason="correction_bound"),
    RunSummary(Outcome.DRIFTED, run_id=8), RunSummary(Outcome.RECHECK_UNTRUSTED, run_id=8),
], ids=["success", "target-missed", "declined", "rolled-back", "bound", "drifted", "untrusted"])
def test_every_run_that_reached_its_end_has_a_next_line_too(summary):
    text = panel(summary, None, CTX, 60)
    assert len(next_lines(text)) == 1 and "press c" not in text and not can_continue(summary)
    if summary.outcome is Outcome.SUCCESS:
        assert next_lines(text)[0].startswith("Next: nothing to fix: table CRC-32 7ff902ab is active")


# -- the screen -------------------------------------------------------------------------------
async def test_a_correction_failure_through_the_ui_says_what_to_change_and_offers_no_c():
    calls = []

    def start_run(emit, control):
        calls.append(1)
        return failed_in_correction(emit, control)

    app = app_for(start_run)
    async with app.run_test(size=SIZE) as pilot:
        await pilot.press("s")
        await settled(pilot, app)
        text = app.result_text
        assert app.exit_code == 3 and app.state == "failed"
        assert "while building the correction table" in text.splitlines()[0]
        assert "change [correction] in examples/scara600/cell.toml" in " ".join(text.split())
        assert "press c" not in text and "rank" not in text  # no advice that fails again, none for another cause
        assert "--resume 7" in " ".join(text.split())  # the command that resumes once the file is changed
        shown = screen_lines(app)
        assert "Continue" not in shown[-1] and "continue" not in shown[1]
        box = app.query_one("#summary-box")
        assert box.scroll_y == 0 and box.max_scroll_y == 0  # all of it in view at 80×24
        await pilot.press("c")  # nothing to continue that could succeed
        await pilot.pause()
        assert calls == [1]


async def test_the_activity_line_is_never_stale_under_a_dialog_or_after_the_end():
    session = FakeSession(gated=False)
    app = app_for(session)
    async with app.run_test(size=SIZE) as pilot:
        detail = app.query_one("#phase-detail")
        await pilot.press("s")
        await wait_until(pilot, lambda: isinstance(app.screen, QuestionScreen), "upload question")
        assert str(detail.render()) == "Waiting for you: Upload the correction table? (y / n)"
        await pilot.press("a")  # the abort's own question, over the upload's
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen), "abort?")
        assert str(detail.render()).startswith("Waiting for you: Abort run #7?")
        said = " ".join(app.screen.question.split())  # the key it names is the docs' (issue 37 §5)
        assert "c continues it" in said and "resumed (r)" not in said
        await pilot.press("n")
        await wait_until(pilot, lambda: isinstance(app.screen, QuestionScreen), "back to the upload question")
        assert str(detail.render()) == "Waiting for you: Upload the correction table? (y / n)"
        await pilot.press("y")
        await wait_until(pilot, lambda: isinstance(app.screen, QuestionScreen) and app.screen.question is KEEP,
                         "keep question")
        assert str(detail.render()) == "Waiting for you: Keep the new correction? (y / n)"
        await pilot.press("y")
        await settled(pilot, app)
        assert str(detail.render()) == "Done — table CRC-32 7ff902ab active · v shows the results"
        assert session.answers == [True, True] and PROPOSAL.crc32 == "7ff902ab"


def test_the_phase_strip_ticks_what_a_run_passed():
    assert passed_phases("measure", set()) == {"connect", "plan", "measure"}  # a resumed run starts here
    assert "upload" not in passed_phases("verify", {"correct"})  # verifying before the upload
    assert "upload" in passed_phases("verify", {"upload"})


async def test_after_a_continue_the_phase_strip_keeps_its_ticks_and_the_title_stays():
    session = FakeSession(ask=False)
    app = app_for(session)
    async with app.run_test(size=SIZE) as pilot:
        title = app.title
        await paused_after(pilot, session, 3)
        await wait_until(pilot, lambda: "p Resume" in screen_lines(app)[-1], "the footer's p Resume")
        assert "p Pause" not in screen_lines(app)[-1]
        await pilot.press("a")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen), "abort?")
        await pilot.press("y")
        await settled(pilot, app)
        await pilot.press("c")
        await wait_until(pilot, lambda: app.running and app.phase == "measure", "continued")
        strip = str(app.query_one("#phases").render())
        assert "✓Connect" in strip and "✓Plan" in strip
        await wait_until(pilot, lambda: "p Pause" in screen_lines(app)[-1], "the footer's p Pause")
        session.open(10)
        await settled(pilot, app)
        assert app.summary.cell == "sim" and app.title == title == CTX.title()  # not the run's cell name


async def test_a_failed_run_gets_its_report_and_the_kept_tables_crc_is_named():
    written = []

    def write_report(run_id):
        written.append(run_id)
        return REPORT

    app = StationApp(failed_in_correction, cell=CTX, write_report=write_report)
    async with app.run_test(size=SIZE) as pilot:
        await pilot.press("s")
        await wait_until(pilot, lambda: app.report_path is not None, "report")
        assert written == [7] and f"Report written: {REPORT}" in app.query_one("#notices").text
        assert REPORT in app.result_text

    def oracle_last(emit, control):  # the oracle's table was the last one uploaded, then rolled back
        emit(RunStarted(run_id=7, n_steps=1))
        emit(Notice("info", "correction table active, CRC-32 0x0badcafe (0.30 s)"))
        emit(Notice("info", "rolled back to the station's table after the oracle check"))
        summary = SUMMARY.replace(upload=UploadSummary("7ff902ab", 0.31),
                                  tables=TableSummary(active_at_start="none", active_at_end="7ff902ab"))
        emit(RunFinished(summary))
        return summary

    app = StationApp(oracle_last, cell=CTX)
    async with app.run_test(size=SIZE) as pilot:
        await pilot.press("s")
        await settled(pilot, app)
        assert "active table       CRC-32 7ff902ab (kept)" in app.result_text
        assert app.query_one("#notices").text.splitlines()[-1] == "Active table: CRC-32 7ff902ab (kept)"


async def test_the_results_of_a_run_picked_from_the_database_in_a_new_session():
    loaded = []

    def load_results(run_id):
        from test_tui_features import report_data

        loaded.append(run_id)
        return report_data()

    app = StationApp(FakeSession(), cell=CTX, list_runs=lambda: RUNS, load_results=load_results,
                     db_label="runs.sqlite")
    async with app.run_test(size=SIZE) as pilot:
        await pilot.press("v")  # no run in this session: the database's ended runs to pick from
        await wait_until(pilot, lambda: isinstance(app.screen, ResumeScreen), "run list")
        assert [r.id for r in app.screen.runs] == [9, 7]  # not #5, which never ended
        await pilot.press("enter")
        await wait_until(pilot, lambda: isinstance(app.screen, ResultsScreen), "results")
        assert loaded == [9]
        await pilot.press("escape")
        await pilot.press("r")  # the resume list: v shows the highlighted run's results instead
        await wait_until(pilot, lambda: isinstance(app.screen, ResumeScreen), "resume list")
        await pilot.press("v")
        await wait_until(pilot, lambda: isinstance(app.screen, ResultsScreen), "results of #7")
        assert loaded == [9, 7] and app.summary is None  # nothing was started


async def test_a_report_that_cannot_be_written_is_a_notice_in_words_for_people():
    def write_report(run_id):
        raise IdentificationError(f"run {run_id} stopped before the identification with 2 valid measurements")

    app = StationApp(failed_in_correction, cell=CTX, write_report=write_report)
    async with app.run_test(size=SIZE) as pilot:
        await pilot.press("s")
        notices = app.query_one("#notices")
        await wait_until(pilot, lambda: "report not written" in notices.text, "the report's notice")
        last = notices.text.splitlines()[-1]
        assert last == "report not written: run 7 stopped before the identification with 2 valid measurements"
        assert app.summary.exit_code == 3 and app.report_path is None  # the run's result stands without it


async def test_a_long_result_scrolls_with_pgdn_without_tab_first():
    notes = tuple(f"note {i}: what the run says about itself, long enough to wrap in the panel" for i in range(8))

    def start_run(emit, control):
        emit(RunStarted(run_id=7, n_steps=1))
        summary = SUMMARY.replace(notes=notes)
        emit(RunFinished(summary))
        return summary

    app = StationApp(start_run, cell=CTX)
    async with app.run_test(size=SIZE) as pilot:
        await pilot.press("s")
        await settled(pilot, app)
        box = app.query_one("#summary-box")
        # the frame's mark follows the laid-out text (after the panel's width is known), a refresh later
        await wait_until(pilot, lambda: box.border_subtitle == "more: PgDn ↓", "the frame says more")
        assert box.max_scroll_y > 0
        assert box.scroll_y == 0 and app.result_text.startswith("Next: ")  # what matters first, in view
        await pilot.press("pagedown")
        await wait_until(pilot, lambda: box.scroll_y > 0, "scrolled down")
        await pilot.press("pageup")
        await wait_until(pilot, lambda: box.scroll_y == 0, "back at the top")


@pytest.mark.slow
async def test_a_real_session_that_fails_building_its_table_is_advised_as_a_correction_failure(tmp_path, monkeypatch,
                                                                                               short_cell):
    """The simulated cell through the session, its correction step made to fail as the issue saw it
    (an IdentificationError, exit code 3, after the identification held): the phase the session
    reported is what tells it from a rank deficiency."""
    from station.cell.pipeline import calibration as pipeline
    from station.cell.session.calibrate import CellRequest
    from station.ui.tui.launch import make_app

    def no_table(cfg, params, design):
        raise IdentificationError("the correction table cannot be built for the identified robot")

    monkeypatch.setattr(pipeline, "identified_table", no_table)
    db = tmp_path / "runs.sqlite"
    # the built-in cell with one visit per identification pose and one verification cycle (issue 42)
    app = make_app(CellRequest(config=str(short_cell), simulated=True, db=str(db)))
    async with app.run_test(size=SIZE) as pilot:
        await pilot.press("s")
        await wait_until(pilot, lambda: app.worker is not None and app.worker.is_finished and app.summary is not None,
                         "run ended", 12000)
        await pilot.pause()
        assert app.exit_code == 3 and app.phase == "correct" and app.summary.run_id is not None
        text = " ".join(app.result_text.split())
        run = app.summary.run_id
        assert "Next: change [correction]" in text and f"resume run #{run}" in text
        assert f"--db {db} --resume {run}" in text and "press c" not in text
        assert not app.check_action("continue_run", ())  # c would fail the same way at once
