"""Scripted stand-ins for the session, the run list and the results (shared by the TUI tests)."""

from __future__ import annotations

import math
import threading

import numpy as np

from station.cell.records.reading.run_list import RunInfo
from station.cell.records.summary import ErrorStats, Failure, IdentificationSummary, RunSummary, UploadSummary
from station.cell.run.facts.events import (
    DeviceSnapshot,
    MeasurementRecorded,
    Notice,
    PhaseChanged,
    Progress,
    RunFailed,
    RunFinished,
    RunStarted,
    StepStarted,
)
from station.cell.run.questions import KeepCorrection, UploadProposal
from station.cell.run.runcontrol import RunAborted
from station.errors import Outcome
from station.ui.report.writer import ReportData

N = 6
LABELS = [f"C{i}.a elbow {'+1' if i % 2 else '-1'} reverse cycle {i + 1}" for i in range(N)]
NOTES = {3: "probe 4 over range (+2.61 mm > +2.50 mm): tip not in contact"}


def stats(rms: float) -> ErrorStats:
    return ErrorStats(n=12, rms_um=rms, max_um=rms * 1.5, ap_max_um=rms * 1.2, rp_max_um=rms * 0.4)


SUMMARY = RunSummary(
    outcome=Outcome.SUCCESS, run_id=7, cell="sim", robot="sr800", db="runs.sqlite",
    identification=IdentificationSummary(objective="pose", n_measurements=60, n_parameters=4,
                                         rms_normalized=1.02, rms_residual_um=9.87, outliers=(), parameters=()),
    before=stats(683.4), after=stats(9.9), oracle=stats(10.0), upload=UploadSummary(crc32="7ff902ab", seconds=0.31))

PROPOSAL = UploadProposal(n_values=31680, grid_shape=(11, 15, 2, 12), interpolation_bound_um=6.2, crc32="7ff902ab",
                          max_correction=(0.00151, 0.00109, 0.7306, 0.00243),
                          joint_types=("revolute", "revolute", "prismatic", "revolute"))
KEEP = KeepCorrection(rms_before_um=683.4, rms_after_um=9.9, gain=69.0, crc32="7ff902ab")


def snapshot(over: bool = False) -> DeviceSnapshot:
    return DeviceSnapshot(probe_mm=(-1.128, 0.0, 0.75, 2.61 if over else 2.2, math.nan, -2.4),
                          probe_status=("ok", "ok", "ok", "over_range" if over else "ok", "invalid", "ok"),
                          stroke_mm=5.0, joints=(math.radians(-45.47), math.radians(75.35), -101.52,
                                                 math.radians(130.12)),
                          joint_types=("revolute", "revolute", "prismatic", "revolute"),
                          controller="ready", heartbeat_age_s=0.25)


#: the example cell's 7-probe head (examples/scara600/head.toml): channel 4 of the interface is not wired
HEAD_IDS = ("T1", "T2", "T3", "X1", "X2", "Y1", "Y2")


def head_snapshot(over: bool = False) -> DeviceSnapshot:
    """What the runner reports for a head with probe ids: one entry per probe, head order."""
    return DeviceSnapshot(probe_mm=(-1.193, -1.104, -1.321, 4.2 if over else -3.066, -2.92, 2.261, 2.134),
                          probe_status=("ok", "ok", "ok", "over_range" if over else "ok", "ok", "ok", "ok"),
                          stroke_mm=8.0, joints=(math.radians(-79.87), math.radians(90.89), -123.0,
                                                 math.radians(18.98)),
                          joint_types=("revolute", "revolute", "prismatic", "revolute"),
                          controller="ready", heartbeat_age_s=0.02, probe_ids=HEAD_IDS)


class FakeSession:
    """Plays ``run_calibration_session(request, emit, control, confirm)`` with ``resume``.

    ``gate``: the worker waits on it before each step, so a test places key presses between
    steps.  ``answers`` records what ``confirm`` returned.
    """

    def __init__(self, gated: bool = True, steps: int = N, ask: bool = True, head: bool = False) -> None:
        self.gate = threading.Semaphore(0) if gated else None
        self.head = head  # report the probes by the head file's ids (head_snapshot)
        self.steps = steps
        self.ask = ask
        self.answers: list[bool] = []
        self.resumed: list[int | None] = []
        self.threads: list[str] = []

    def open(self, n: int = 1) -> None:
        assert self.gate is not None
        for _ in range(n):
            self.gate.release()

    def __call__(self, emit, control, confirm=None, resume=None):
        self.threads.append(threading.current_thread().name)
        self.resumed.append(resume)
        start = 2 if resume is not None else 0
        try:
            emit(PhaseChanged("connect", "simulated cell"))
            emit(RunStarted(run_id=7, n_steps=self.steps, resumed_from=start))
            emit(PhaseChanged("measure", "identification poses"))
            for i in range(start, self.steps):
                if self.gate is not None:
                    assert self.gate.acquire(timeout=10), "test never opened the gate"
                control.checkpoint(timeout=10, emit=emit, index=i)
                emit(StepStarted(i, self.steps, f"identification: {LABELS[i]}"))
                emit(head_snapshot(i == 3) if self.head else DeviceSnapshot(**{**snapshot(i == 3).__dict__}))
                emit(Progress(i + 1, self.steps, LABELS[i]))
                emit(MeasurementRecorded(i, self.steps, LABELS[i], i not in NOTES, 1.25 * (i + 1), NOTES.get(i, "")))
            emit(PhaseChanged("identify"))
            emit(PhaseChanged("correct"))
            emit(PhaseChanged("verify", "before correction"))
            summary = SUMMARY
            if self.ask and confirm is not None:
                self.answers.append(confirm(PROPOSAL))
                if not self.answers[-1]:
                    summary = SUMMARY.replace(outcome=Outcome.NOT_UPLOADED, upload=None, after=None, oracle=None,
                                              upload_skipped=True, notes=("upload declined by the operator",))
                    emit(RunFinished(summary))
                    return summary
                emit(PhaseChanged("upload", "31680 values, CRC-32 0x7ff902ab"))
                emit(Notice("info", "read back 31680 values identical, CRC-32 0x7ff902ab"))
                emit(Notice("info", "correction table active, CRC-32 0x7ff902ab (0.31 s)"))
                emit(PhaseChanged("verify", "after correction"))
                self.answers.append(confirm(KEEP))
                if not self.answers[-1]:
                    emit(Notice("warning", "rolled back by the operator: no correction table is active"))
                    summary = SUMMARY.replace(outcome=Outcome.NOT_UPLOADED,
                                              notes=("the new table was rolled back by the operator",))
            emit(RunFinished(summary))
            return summary
        except RunAborted as exc:
            summary = RunSummary(outcome=Outcome.ABORTED, run_id=7, db="runs.sqlite",
                                 failure=Failure("RunAborted", str(exc), "continue later: --resume 7"))
            emit(RunFailed(summary))
            return summary


RUNS = [
    RunInfo(id=9, created_utc="2026-05-02T10:11:12Z", cell="sim", robot="sr800", status="verified", steps_done=305,
            steps_total=305, outcome="SUCCESS", rms_before_um=683.4, rms_after_um=9.9, gain=69.0),
    RunInfo(id=7, created_utc="2026-05-01T08:00:00Z", cell="sim", robot="sr800", status="aborted", steps_done=2,
            steps_total=N, outcome="ABORTED", rms_before_um=None, rms_after_um=None, gain=None),
    RunInfo(id=5, created_utc="2026-04-30T07:00:00Z", cell="sim", robot="sr800", status="measuring", steps_done=40,
            steps_total=305, outcome=None, rms_before_um=None, rms_after_um=None, gain=None),
]


def report_data() -> ReportData:
    names = ["R.x", "A2.pitch", "A3.roll", "A4.roll"]
    corr = np.eye(4)
    corr[2, 3] = corr[3, 2] = -0.97
    rng = np.random.default_rng(3)
    xs = np.linspace(-200, 200, 30)
    return ReportData(
        robot_name="sr800", run_id=7, param_names=names, param_nominal=np.array([-450.0, 0.0, 0.0, 0.0]),
        param_identified=np.array([-446.834, -1.9e-4, -1.9e-4, -1.98e-3]),
        param_sigma=np.array([2.03e-3, 4.8e-6, 1.1e-5, np.nan]), param_is_angle=np.array([False, True, True, True]),
        residuals=rng.normal(0, 0.01, (40, 6)), accuracy_xy_mm=np.column_stack([xs, xs * 0.5]),
        accuracy_sigma_mm=2.4e-3 + 1e-5 * np.abs(xs), errors_before_um=np.linspace(500, 900, 20),
        errors_after_um=np.linspace(5, 20, 20), oracle_after_um=np.linspace(4, 18, 20), summary=SUMMARY,
        param_correlation=corr)


# ================================================================================== pilot tests
# (the fakes above are shared with test_tui_snapshots.py and test_tui_sim.py)
import ast  # noqa: E402
from pathlib import Path  # noqa: E402

import pytest  # noqa: E402
from textual.content import Content  # noqa: E402
from textual.widgets import DataTable, Static  # noqa: E402

from station.ui.tui.app import StationApp  # noqa: E402
from station.ui.tui.results import ResultsScreen, parameter_rows  # noqa: E402
from station.ui.tui.screens import HelpScreen, QuestionScreen, ResumeScreen  # noqa: E402
from station.ui.tui.widgets import ConfirmScreen, DevicePanel, Eta, activity_text, device_text, phase_markup  # noqa: E402


def plain(widget: Static) -> str:
    content = widget.content
    return Content.from_markup(content).plain if isinstance(content, str) else str(content)


async def wait_until(pilot, cond, what: str, rounds: int = 500) -> None:
    for _ in range(rounds):
        if cond():
            return
        await pilot.pause(0.01)
    raise AssertionError(f"timed out waiting for: {what}")


async def paused_after(pilot, session: FakeSession, rows: int) -> None:
    """Start the run, let ``rows`` steps through, pause it and wait until the UI says paused."""
    app = pilot.app
    await pilot.press("s")
    session.open(rows)
    await wait_until(pilot, lambda: app.query_one("#measurements").row_count == rows, f"{rows} rows")
    await pilot.press("p")
    session.open()
    await wait_until(pilot, lambda: app.state == "paused", "paused")


def frozen() -> float:
    return 0.0


def make_app(session: FakeSession, **kw) -> StationApp:
    kw.setdefault("clock", frozen)
    return StationApp(session, title="SR 800 test", **kw)


def test_device_text_shows_joints_heartbeat_and_out_of_range_probes():
    text = device_text(snapshot(over=True), 76).plain
    assert "controller ready" in text and "heartbeat 0.25 s" in text
    assert "J1 -45.47°" in text and "J3 -101.52 mm" in text  # revolute in degrees, prismatic in mm
    assert "P4" in text and "OVER" in text and "INVAL" in text
    assert "-1.128" in text
    assert max(len(line) for line in device_text(snapshot(), 44).plain.splitlines()) <= 44
    assert "no reading yet" in device_text(None, 40).plain


def test_eta_stands_still_while_paused_and_does_not_jump_on_resume():
    now = [0.0]
    eta = Eta(lambda: now[0])
    eta.start(0, 11)
    assert eta.remaining_s() is None and "--:--:--" in eta.text()
    now[0] = 10.0
    eta.update(1, 11)  # 10 s per step, 10 steps left
    assert eta.remaining_s() == pytest.approx(100.0)
    now[0] = 15.0
    assert eta.remaining_s() == pytest.approx(95.0)  # counts down between steps
    eta.pause()
    now[0] = 500.0
    assert eta.remaining_s() == pytest.approx(95.0) and "⏸" in eta.text()
    eta.resume()
    now[0] = 501.0
    assert eta.remaining_s() == pytest.approx(94.0)  # continues where it stood
    # a resumed run's rate comes from this attempt's steps only
    eta.start(200, 305)
    now[0] = 511.0
    eta.update(201, 305)
    assert eta.remaining_s() == pytest.approx(10.0 * 104)


def test_readable_phase_names():
    strip = Content.from_markup(phase_markup("verify", {"connect", "measure"})).plain
    assert strip == "✓Connect › Plan › ✓Measure › Identify › Correct › Upload ›  Verify  › Done"
    assert len(Content.from_markup(phase_markup("done", set(PHASE_KEYS))).plain) <= 79
    assert activity_text("verify", "before correction") == "Verifying before correction"
    assert activity_text("identify") == "Identifying the parameters"


PHASE_KEYS = ("connect", "plan", "measure", "identify", "correct", "upload", "verify", "done")


async def test_device_panel_pause_eta_and_rejected_reading_at_80x24():
    session = FakeSession()
    now = [0.0]
    app = make_app(session, clock=lambda: now[0])
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("s")
        for _ in range(4):
            now[0] += 5.0
            session.open()
        table = app.query_one("#measurements", DataTable)
        await wait_until(pilot, lambda: table.row_count == 4, "4 rows")
        assert "OVER" in device_text(app.query_one(DevicePanel).snapshot, 40).plain
        # the reason a reading was rejected is in view at 80 columns, with its long label
        assert "probe 4 over range" in str(table.get_row_at(3)[4])
        widths = sum(c.get_render_width(table) for c in table.columns.values())
        assert widths - len(str(table.get_row_at(3)[4])) + 20 <= table.scrollable_content_region.width
        assert not app.query_one("#buttons").display  # the footer's keys stay, the buttons give way
        eta_before = app.eta.remaining_s()
        assert eta_before is not None
        await pilot.press("p")
        session.open()
        await wait_until(pilot, lambda: app.state == "paused", "paused")
        paused_left = app.eta.remaining_s()
        now[0] += 600.0  # a long pause: the estimate stands still
        assert app.eta.remaining_s() == paused_left and not app.eta.running
        assert "⏸" in plain(app.query_one("#eta", Static)) or "⏸" in app.eta.text()
        await pilot.press("p")
        await wait_until(pilot, lambda: app.state == "running", "running")
        now[0] += 1.0
        assert app.eta.running and app.eta.remaining_s() <= paused_left  # no jump on resume
        session.open(10)
        await wait_until(pilot, lambda: isinstance(app.screen, QuestionScreen), "upload question")
        await pilot.press("y")
        await wait_until(pilot, lambda: isinstance(app.screen, QuestionScreen) and len(session.answers) == 1, "keep?")
        await pilot.press("y")
        await wait_until(pilot, lambda: app.state == "finished", "finished")


async def test_upload_confirmation_read_back_and_roll_back():
    session = FakeSession(gated=False)
    app = make_app(session)
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("s")
        await wait_until(pilot, lambda: isinstance(app.screen, QuestionScreen), "upload question")
        body = plain(app.screen.query_one("#question-body", Static))
        assert "31680" in body and "11 × 15 × 2 × 12" in body and "6.2 µm" in body and "7ff902ab" in body
        assert "J3 730.6 µm" in body and "J1 311.5″" in body
        assert app.screen.query_one("#yes").label.plain == "Upload (y)"
        await pilot.press("y")
        await wait_until(pilot, lambda: len(session.answers) == 2 or isinstance(app.screen, QuestionScreen)
                         and app.screen.question is KEEP, "keep question")
        # read-back and activation were shown while the question is up
        notices = " ".join(app.query_one("#notices").text.split())
        assert "read back 31680 values identical" in notices and "correction table active" in notices
        assert "Roll back" in str(app.screen.query_one("#no").label)
        await pilot.press("n")
        await wait_until(pilot, lambda: app.state == "finished", "finished")
        assert session.answers == [True, False]
        assert session.threads[0] != "MainThread"
        assert app.exit_code == 11 and "rolled back" in app.result_text


async def test_declining_the_upload_and_abort_during_a_question():
    session = FakeSession(gated=False)
    app = make_app(session)
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("s")
        await wait_until(pilot, lambda: isinstance(app.screen, QuestionScreen), "upload question")
        await pilot.press("n")
        await wait_until(pilot, lambda: app.state == "finished", "finished")
        assert session.answers == [False] and app.exit_code == 11
        assert "skipped" in app.result_text

        session.answers.clear()
        await pilot.press("s")  # a new run clears the notices of the last one
        await wait_until(pilot, lambda: isinstance(app.screen, QuestionScreen), "upload question")
        assert "upload declined" not in app.query_one("#notices").text
        await pilot.press("a")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen), "abort?")
        assert "run #7" in str(app.screen.question)
        await pilot.press("y")
        await wait_until(pilot, lambda: app.state not in ("running", "aborting"), "ended")
        assert session.answers == [False]  # the abort answered "no": nothing was uploaded


@pytest.mark.parametrize("abort", [False, True])
async def test_a_question_that_arrives_under_the_abort_dialog_waits_for_its_answer(abort):
    # the run reaches "Upload?" while the operator's "Abort?" dialog is open (a fast run on a loaded
    # machine did, in CI): pushed over the dialog, the question would take the "y" meant for the
    # abort and upload the table. It waits; "n" to the abort then asks it, "y" answers it "no".
    session = FakeSession(gated=True)
    app = make_app(session)
    async with app.run_test(size=(80, 24)) as pilot:
        table = app.query_one("#measurements", DataTable)
        await pilot.press("s")
        session.open(2)
        await wait_until(pilot, lambda: table.row_count >= 2, "2 rows")
        await pilot.press("a")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen), "abort?")
        session.open(N - 2)  # the run goes on under the dialog and asks its question
        await wait_until(pilot, lambda: app.deferred_question is not None, "the question, held back")
        assert isinstance(app.screen, ConfirmScreen) and "Asked:" not in app.query_one("#notices").text
        await pilot.press("y" if abort else "n")
        if abort:
            await wait_until(pilot, lambda: app.state not in ("running", "aborting"), "ended")
            assert session.answers == [False] and "Asked:" not in app.query_one("#notices").text
        else:
            await wait_until(pilot, lambda: isinstance(app.screen, QuestionScreen), "upload question")
            assert app.screen.question == PROPOSAL and app.deferred_question is None
            await pilot.press("n")
            await wait_until(pilot, lambda: app.state == "finished", "finished")
            assert session.answers == [False] and app.exit_code == 11


async def test_resume_lists_unfinished_runs_and_resumes_the_picked_one():
    session = FakeSession(gated=False, ask=False)
    calls = []

    def runs():
        import threading as th
        calls.append(th.current_thread().name)
        return RUNS

    app = make_app(session, list_runs=runs, db_label="runs.sqlite")
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("r")
        await wait_until(pilot, lambda: isinstance(app.screen, ResumeScreen), "resume list")
        assert calls and calls[0] != "MainThread"
        table = app.screen.query_one("#runs", DataTable)
        assert [str(table.get_row_at(i)[0]) for i in range(table.row_count)] == ["#7", "#5"]  # not the finished #9
        await pilot.press("down", "up", "enter")
        await wait_until(pilot, lambda: app.state == "finished", "finished")
        assert session.resumed == [7]
        assert app.query_one("#progress").progress == N


async def test_results_view_report_and_help():
    session = FakeSession(gated=False, ask=False)
    written = []

    def write_report(run_id):
        import threading as th
        written.append(th.current_thread().name)
        return Path("/runs/report-run-7/report.html")

    app = make_app(session, load_results=lambda run_id: report_data(), write_report=write_report)
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("question_mark")
        await wait_until(pilot, lambda: isinstance(app.screen, HelpScreen), "help")
        assert "roll" in plain(app.screen.query_one("#help-text", Static))
        await pilot.press("escape")
        await pilot.press("s")
        await wait_until(pilot, lambda: app.report_path is not None, "report written")
        assert written and written[0] != "MainThread"
        assert "/runs/report-run-7/report.html" in app.result_text
        await pilot.press("v")
        await wait_until(pilot, lambda: isinstance(app.screen, ResultsScreen), "results")
        table = app.screen.query_one("#params", DataTable)
        assert table.row_count == 4
        row = [str(c) for c in table.get_row_at(2)]
        assert row[0] == "A3.roll" and row[5] == "A4.roll -0.97"
        assert row[4].endswith("″")
        await pilot.press("2", "3", "4")
        await pilot.press("escape")
        await wait_until(pilot, lambda: not isinstance(app.screen, ResultsScreen), "back")


def test_parameter_rows_units_and_held_parameters():
    rows = parameter_rows(report_data())
    assert rows[0][3] == "+3166.0 µm" and rows[0][4] == "2.03 µm"
    assert rows[3][4] == "held" and rows[1][5] == ""


UI = Path(__file__).resolve().parents[2] / "station" / "ui" / "tui"
FORBIDDEN = ("drivers", "pymodbus", "serial", "sqlite3", "station.cell.pipeline.calibration")


@pytest.mark.parametrize("path", sorted(UI.glob("*.py")), ids=lambda p: p.name)
def test_no_tui_module_reaches_a_device(path):
    tree = ast.parse(path.read_text(encoding="utf-8"))
    imported = [a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names]
    imported += [n.module or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)]
    assert not [m for m in imported if any(m == f or m.startswith(f + ".") for f in FORBIDDEN)]


async def test_the_eta_timer_firing_during_shutdown_is_harmless():
    """The ETA is refreshed by a 1 s timer, which can fire once more while the app shuts down and
    its widgets are already removed (a CI run caught it at the end of a full simulated run): that
    must not raise; while the widget is there, it shows the ETA."""
    from textual.widgets import Static

    app = make_app(FakeSession(gated=False, ask=False))
    async with app.run_test(size=(80, 24)) as pilot:
        app.run_id = 7
        app._show_eta()
        eta = app.query_one("#eta", Static)
        assert str(eta.render()) == app.eta.text()
        await eta.remove()
        await pilot.pause()
        app._show_eta()  # the widget is gone, as during shutdown: nothing to update, no error
