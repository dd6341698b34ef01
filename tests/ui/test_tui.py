"""Operator UI driven headless with Textual's Pilot against a scripted fake runner.

The fake plays the session's contract: typed events through ``emit``, ``RunFinished`` /
``RunFailed`` carrying the frozen :class:`RunSummary`, and that summary returned.  The exit code
the UI shows and returns is ``summary.exit_code`` and nothing else.
"""

from __future__ import annotations

import ast
import re
import threading
import time
from pathlib import Path

import pytest
from textual.content import Content
from textual.widgets import DataTable, ProgressBar, Static

from station.cell.pipeline.outcomes import hint_for
from station.cell.records.summary import (
    ErrorStats,
    Failure,
    IdentificationSummary,
    RunSummary,
    UploadSummary,
)
from station.cell.run.facts.events import (
    MeasurementRecorded,
    Notice,
    PhaseChanged,
    Progress,
    RunFailed,
    RunFinished,
    RunStarted,
    StepStarted,
)
from station.cell.run.runcontrol import RunAborted, RunControl
from station.errors import ConfigError, Outcome
from station.ui.tui.app import ConfirmScreen, StationApp
from station.ui.tui.result_panel import HEADLINE_FIGURES

N = 5
LABELS = [f"point C{i}.a, elbow +1" for i in range(N)]
RESIDUALS = [1.25, 2.5, 0.75, 3.0, 1.5]


def stats(rms: float, ap: float = 0.0, rp: float = 0.0) -> ErrorStats:
    return ErrorStats(n=12, rms_um=rms, max_um=rms * 1.5, ap_max_um=ap, rp_max_um=rp)


SUMMARY = RunSummary(
    outcome=Outcome.SUCCESS, run_id=42, cell="sim", robot="SR 800",
    identification=IdentificationSummary(objective="pose", n_measurements=60, n_parameters=20,
                                         rms_normalized=1.02, rms_residual_um=9.87, outliers=(),
                                         parameters=()),
    before=stats(812.4, 1400.0, 31.0), after=stats(23.6, 35.5, 30.2), oracle=stats(21.9),
    upload=UploadSummary(crc32="deadbeef", seconds=1.23),
)


class FakeRunner:
    """Scripted stand-in for ``run_calibration_session``.

    With ``gated`` it waits on a gate before each step so a test can place key presses between
    steps deterministically; it calls ``control.checkpoint()`` at each safe point and records
    what happened.  An abort either escapes as ``RunAborted`` (``on_abort="raise"``) or ends
    like the session ends it (``"session"``: ``RunFailed`` with an ABORTED summary, returned).
    """

    def __init__(self, *, summary: RunSummary = SUMMARY, gated: bool = False,
                 raise_exc: BaseException | None = None, returns: object = None, on_abort: str = "raise"):
        self.summary = summary
        self.returns = summary if returns is None else returns
        self.raise_exc = raise_exc
        self.on_abort = on_abort
        self.gate = threading.Semaphore(0) if gated else None
        self.checkpoints_passed = 0
        self.in_checkpoint = threading.Event()
        self.aborted = False
        self.finished = False
        self.thread_name: str | None = None

    def __call__(self, emit, control: RunControl):
        self.thread_name = threading.current_thread().name
        try:
            emit(RunStarted(run_id=42, n_steps=N))
            emit(PhaseChanged("connect", "simulated cell"))
            emit(PhaseChanged("measure", f"{N} poses"))
            for i in range(N):
                if self.gate is not None:
                    assert self.gate.acquire(timeout=10), "test never opened the gate"
                self.in_checkpoint.set()
                control.checkpoint(timeout=10)
                self.in_checkpoint.clear()
                self.checkpoints_passed += 1
                emit(StepStarted(index=i, total=N, label=LABELS[i]))
                emit(Progress(i + 1, N, LABELS[i]))
                emit(MeasurementRecorded(index=i, total=N, label=LABELS[i], ok=(i != 3),
                                         residual_um=RESIDUALS[i],
                                         message="" if i != 3 else "probe 4 out of range"))
            if self.raise_exc is not None:
                raise self.raise_exc
            if self.summary.failure is not None:
                emit(RunFailed(self.summary))
                return self.returns
            emit(Notice("warning", "backlash 0.1 mm dominates the attainable accuracy"))
            emit(PhaseChanged("identify", "20 parameters"))
            emit(PhaseChanged("verify"))
            emit(RunFinished(self.summary))
            self.finished = True
            return self.returns
        except RunAborted as exc:
            self.aborted = True
            self.in_checkpoint.clear()
            if self.on_abort == "raise":
                raise
            summary = RunSummary(outcome=Outcome.ABORTED, run_id=42,
                                 failure=Failure("RunAborted", str(exc), hint_for(exc, 42)))
            emit(RunFailed(summary))
            return summary


def plain(widget: Static) -> str:
    content = widget.content
    if isinstance(content, str):
        return Content.from_markup(content).plain
    return str(content)


def panel(app: StationApp) -> str:
    """The result panel's rows (unwrapped: the panel wraps long values within their column)."""
    return app.result_text


def row(text: str, label: str) -> str:
    """Value of an aligned ``label  value`` row of the result panel."""
    m = re.search(rf"^{re.escape(label)}\s+(.*)$", text, re.MULTILINE)
    assert m, (label, text)
    return m.group(1).strip()


async def wait_until(pilot, cond, what: str, rounds: int = 400) -> None:
    """Let the app process messages until ``cond()`` holds (bounded, no long sleeps)."""
    for _ in range(rounds):
        if cond():
            return
        await pilot.pause(0.01)
    raise AssertionError(f"timed out waiting for: {what}")


def open_gate(runner: FakeRunner, n: int = 1) -> None:
    assert runner.gate is not None
    for _ in range(n):
        runner.gate.release()


async def test_full_run_progress_table_and_summary():
    runner = FakeRunner()
    app = StationApp(runner, title="SR 800 test")
    async with app.run_test(size=(120, 45)) as pilot:
        assert app.state == "idle" and app.summary is None and app.exit_code is None
        await pilot.press("s")
        await wait_until(pilot, lambda: app.state == "finished", "run finished")
        # the runner sets its flags after its RunFinished event, in its thread: wait for that thread's end
        await wait_until(pilot, lambda: app.worker is not None and app.worker.is_finished, "the worker's end")

        # the runner ran in a worker thread, not on the UI thread
        assert runner.thread_name != threading.main_thread().name
        assert runner.finished and runner.checkpoints_passed == N

        bar = app.query_one("#progress", ProgressBar)
        assert bar.total == N and bar.progress == N

        table = app.query_one("#measurements", DataTable)
        assert table.row_count == N
        for i in range(N):
            idx, label, ok, residual, _note = (str(c) for c in table.get_row_at(i))
            assert idx == str(i + 1)
            assert label == LABELS[i]
            assert ("✗" in ok) if i == 3 else ("✓" in ok)
            assert residual == f"{RESIDUALS[i]:.2f}"
        assert "probe 4 out of range" in str(table.get_row_at(3)[4])

        assert app.run_id == 42
        assert "run #42" in plain(app.query_one("#run-id", Static))
        text = panel(app)
        assert app.query_one("#summary").display
        assert row(text, "outcome").startswith("SUCCESS")
        assert row(text, "run") == "#42 (robot SR 800, cell sim)"
        # every headline figure of the summary, formatted as the summary says; the others two to a row
        for label, value, unit, digits in SUMMARY.figures():
            if label in HEADLINE_FIGURES:
                assert row(text, label) == f"{value:.{digits}f}{' ' + unit if unit else ''}"
        assert row(text, "ISO 9283 after") == "AP max 35.5 µm, RP max 30.2 µm"
        assert row(text, "identification") == "20 parameters, residual RMS 9.9 µm"
        assert row(text, "upload") == "read back, active in 1.23 s"
        # what next, and the table the controller is left with, by its CRC
        assert text.startswith("Next: nothing to fix: table CRC-32 deadbeef is active")
        assert row(text, "active table") == "CRC-32 deadbeef (kept)"
        assert row(text, "RMS before") == "812.4 µm" and row(text, "improvement ratio") == "34.4 ×"
        assert row(text, "exit code") == "0"
        assert app.summary is SUMMARY and app.outcome == "SUCCESS" and app.exit_code == 0
        assert "-ok" in app.query_one("#summary").classes
        assert "Done" in plain(app.query_one("#phases", Static))

        await pilot.press("q")  # not running any more: quits at once
        await wait_until(pilot, lambda: not app.is_running, "app exit")
    assert app.return_code == 0
    assert app.return_value is SUMMARY


async def test_start_button_starts_the_run():
    runner = FakeRunner()
    app = StationApp(runner)
    async with app.run_test(size=(120, 40)) as pilot:
        await pilot.click("#start")
        await wait_until(pilot, lambda: app.state == "finished", "run finished")
        # the runner sets its flag after its RunFinished event, in its thread: wait for that thread's end
        await wait_until(pilot, lambda: app.worker is not None and app.worker.is_finished, "the worker's end")
        assert runner.finished


async def test_pause_blocks_runner_at_checkpoint_and_resume_releases():
    runner = FakeRunner(gated=True)
    app = StationApp(runner)
    async with app.run_test(size=(120, 40)) as pilot:
        await pilot.press("s")
        open_gate(runner, 2)
        await wait_until(pilot, lambda: app.query_one("#measurements", DataTable).row_count == 2, "2 rows")

        await pilot.press("p")
        assert app.control is not None and app.control.paused
        assert app.state in ("pausing", "paused")
        open_gate(runner)  # runner reaches its next checkpoint and must block there
        await wait_until(pilot, lambda: app.control.waiting, "runner blocked in checkpoint")
        await wait_until(pilot, lambda: app.state == "paused", "UI shows paused")
        assert runner.checkpoints_passed == 2
        for _ in range(10):  # it stays blocked while paused
            await pilot.pause(0.01)
        assert runner.checkpoints_passed == 2 and runner.in_checkpoint.is_set()
        assert "PAUSED" in plain(app.query_one("#state", Static))

        await pilot.press("p")  # resume
        await wait_until(pilot, lambda: runner.checkpoints_passed == 3, "runner released")
        assert app.state == "running" and not app.control.paused
        open_gate(runner, N)
        await wait_until(pilot, lambda: app.state == "finished", "run finished")
        assert app.query_one("#progress", ProgressBar).progress == N


@pytest.mark.parametrize("on_abort", ["raise", "session"])
async def test_abort_with_confirmation_is_outcome_aborted(on_abort):
    # "raise": RunAborted escapes start_run and is classified by type; "session": the run ends
    # as run_calibration_session ends it, with an ABORTED summary.  Both are exit code 6.
    runner = FakeRunner(gated=True, on_abort=on_abort)
    app = StationApp(runner)
    async with app.run_test(size=(120, 40)) as pilot:
        await pilot.press("s")
        open_gate(runner, 1)
        await wait_until(pilot, lambda: app.query_one("#measurements", DataTable).row_count == 1, "1 row")

        # declining keeps the run going
        await pilot.press("a")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen), "confirm dialog")
        await pilot.press("n")
        await wait_until(pilot, lambda: not isinstance(app.screen, ConfirmScreen), "dialog closed")
        assert app.control is not None and not app.control.aborted and app.state == "running"

        await pilot.press("a")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen), "confirm dialog")
        await pilot.press("y")
        await wait_until(pilot, lambda: app.control.aborted, "abort flag")
        open_gate(runner, 1)  # next safe point
        await wait_until(pilot, lambda: app.state == "aborted", "UI shows aborted")
        await wait_until(pilot, lambda: app.worker is not None and app.worker.is_finished, "worker done")
        await pilot.pause()
        assert runner.aborted and not runner.finished
        assert runner.checkpoints_passed == 1
        assert app.summary is not None and app.summary.outcome is Outcome.ABORTED
        assert app.exit_code == Outcome.ABORTED == 6
        text = panel(app)
        assert "ABORTED" in text and row(text, "exit code") == "6"
        # Next names the run and the one key that continues it (no CLI line: the UI was not
        # told the command line it runs for, and a command with a placeholder is not shown)
        assert row(text, "Next:").startswith("press c: run #42 goes on at its next step") and "CONFIG" not in text
        assert "What to do" not in text and "then press" not in text  # no advice that starts with "then"
        await pilot.press("q")
        await wait_until(pilot, lambda: not app.is_running, "app exit")
    assert app.return_code == 6


async def test_abort_while_paused_releases_the_runner():
    runner = FakeRunner(gated=True)
    app = StationApp(runner)
    async with app.run_test(size=(120, 40)) as pilot:
        await pilot.press("s")
        await pilot.press("p")
        open_gate(runner, 1)
        await wait_until(pilot, lambda: app.state == "paused", "paused")
        await pilot.press("a")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen), "confirm dialog")
        await pilot.press("y")
        await wait_until(pilot, lambda: app.state == "aborted", "aborted")
        assert runner.aborted and runner.checkpoints_passed == 0
        assert app.exit_code == 6


async def test_run_failed_shows_message_and_hint():
    failure = Failure("IdentificationError", "rank 17 < 20: the poses do not excite axis 2",
                      "plan poses over the whole workspace (station plan --spread 3d)")
    runner = FakeRunner(summary=RunSummary(Outcome.IDENTIFICATION_FAILED, run_id=42, failure=failure))
    app = StationApp(runner)
    async with app.run_test(size=(120, 40)) as pilot:
        await pilot.press("s")
        await wait_until(pilot, lambda: app.state == "failed", "failed")
        text = panel(app)
        # the panel names the outcome, never the Python type (issue 33: messages for people)
        assert "IDENTIFICATION_FAILED" in text and "IdentificationError" not in text
        assert failure.message in text and failure.hint in text
        assert row(text, "outcome").startswith("IDENTIFICATION_FAILED")
        assert app.exit_code == 3 and app.failure == failure
        assert "-failed" in app.query_one("#summary").classes
        await pilot.press("q")
        await wait_until(pilot, lambda: not app.is_running, "app exit")
    assert app.return_code == 3


async def test_exit_code_comes_from_the_outcome_not_the_error_name():
    # An error type *named* like the abort must not make the run "aborted": only the outcome counts.
    failure = Failure("RunAborted", "controller heartbeat lost", "check the fieldbus cable")
    runner = FakeRunner(summary=RunSummary(Outcome.DEVICE_FAULT, run_id=42, failure=failure))
    app = StationApp(runner)
    async with app.run_test(size=(120, 40)) as pilot:
        await pilot.press("s")
        await wait_until(pilot, lambda: app.summary is not None, "run ended")
        assert app.state == "failed" and app.exit_code == 7
        text = panel(app)
        assert "check the fieldbus cable" in text and row(text, "exit code") == "7"


async def test_station_error_escaping_start_run_is_classified_by_type(tmp_path):
    runner = FakeRunner(raise_exc=ConfigError("cell.toml: probe 7 has no direction"))
    app = StationApp(runner, log_dir=tmp_path)
    async with app.run_test(size=(120, 40)) as pilot:
        await pilot.press("s")
        await wait_until(pilot, lambda: app.state == "failed", "failed")
        text = panel(app)
        assert "CONFIG_ERROR" in text and "probe 7 has no direction" in text and "ConfigError" not in text
        assert app.exit_code == Outcome.CONFIG_ERROR == 2
    assert not list(tmp_path.iterdir())  # not a bug: no traceback file


def _buggy_helper():
    return {}["missing key"]


async def test_exception_in_start_run_writes_its_traceback_and_is_internal_error(tmp_path):
    def start_run(emit, control):
        emit(RunStarted(run_id=9, n_steps=3))
        _buggy_helper()

    app = StationApp(start_run, log_dir=tmp_path)
    async with app.run_test(size=(160, 40)) as pilot:
        await pilot.press("s")
        await wait_until(pilot, lambda: app.state == "failed", "failed")
        assert app.summary is not None and app.summary.outcome is Outcome.INTERNAL_ERROR
        assert app.exit_code == 1
        logs = list(tmp_path.glob("station-error-*.log"))
        assert len(logs) == 1
        trace = logs[0].read_text(encoding="utf-8")
        assert "Traceback" in trace and "_buggy_helper" in trace and "KeyError" in trace
        assert app.failure is not None and app.failure.log_file == str(logs[0])
        text = panel(app)
        assert str(logs[0]) in text and "KeyError" in text
        assert row(text, "exit code") == "1"
        await pilot.press("q")
        await wait_until(pilot, lambda: not app.is_running, "app exit")
    assert app.return_code == 1


async def test_start_run_that_returns_no_summary_is_internal_error(tmp_path):
    app = StationApp(lambda emit, control: {"outcome": "SUCCESS", "exit_code": 0}, log_dir=tmp_path)
    async with app.run_test(size=(160, 40)) as pilot:
        await pilot.press("s")
        await wait_until(pilot, lambda: app.state == "failed", "failed")
        assert app.exit_code == 1
        assert "not a RunSummary" in panel(app)


async def test_quit_while_running_asks_then_aborts_and_exits():
    runner = FakeRunner(gated=True)
    app = StationApp(runner)
    async with app.run_test(size=(120, 40)) as pilot:
        await pilot.press("s")
        open_gate(runner, 1)
        await wait_until(pilot, lambda: app.query_one("#measurements", DataTable).row_count == 1, "1 row")
        await pilot.press("q")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen), "confirm dialog")
        await pilot.press("n")
        await wait_until(pilot, lambda: not isinstance(app.screen, ConfirmScreen), "dialog closed")
        assert app.is_running and app.state == "running"
        await pilot.press("q")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen), "confirm dialog")
        await pilot.press("y")
        open_gate(runner, 1)
        await wait_until(pilot, lambda: not app.is_running, "app exit after abort")
    assert runner.aborted
    assert app.return_code == 6
    assert app.return_value is not None and app.return_value.outcome is Outcome.ABORTED


async def test_start_is_refused_while_running():
    runner = FakeRunner(gated=True)
    calls = []

    def start_run(emit, control):
        calls.append(1)
        return runner(emit, control)

    app = StationApp(start_run)
    async with app.run_test(size=(120, 40)) as pilot:
        await pilot.press("s")
        await wait_until(pilot, lambda: app.run_id == 42, "run started")
        await pilot.press("s")
        await pilot.pause()
        assert len(calls) == 1
        open_gate(runner, N)
        await wait_until(pilot, lambda: app.state == "finished", "finished")


async def test_target_missed_is_finished_with_exit_code_10_and_a_red_frame():
    summary = SUMMARY.replace(outcome=Outcome.TARGET_MISSED, after=stats(400.0, 410.0, 30.2))
    app = StationApp(FakeRunner(summary=summary))
    async with app.run_test(size=(120, 45)) as pilot:
        await pilot.press("s")
        await wait_until(pilot, lambda: app.summary is not None and app.worker.is_finished, "ended")
        await pilot.pause()
        assert app.state == "finished" and app.exit_code == 10
        text = panel(app)
        assert row(text, "outcome").startswith("TARGET_MISSED")
        assert row(text, "RMS after") == "400.0 µm" and row(text, "improvement ratio") == "2.0 ×"
        assert row(text, "exit code") == "10"
        assert "-failed" in app.query_one("#summary").classes
        await pilot.press("q")
        await wait_until(pilot, lambda: not app.is_running, "exit")
    assert app.return_code == 10


async def test_returned_summary_completes_the_events_one():
    # The session returns the event's summary completed (database path, report); that one is shown.
    returned = SUMMARY.replace(db="runs.sqlite", report="run-42.html")
    app = StationApp(FakeRunner(summary=SUMMARY, returns=returned))
    async with app.run_test(size=(120, 45)) as pilot:
        await pilot.press("s")
        await wait_until(pilot, lambda: app.summary == returned, "returned summary shown")
        assert row(panel(app), "report") == "run-42.html"
        assert app.exit_code == 0


def test_runcontrol_checkpoint_semantics():
    c = RunControl()
    assert c.checkpoint() is True
    c.pause()
    assert c.paused
    t0 = time.monotonic()
    assert c.checkpoint(timeout=0.05) is False
    assert time.monotonic() - t0 >= 0.04
    events = []
    done = threading.Event()

    def runner():
        c.checkpoint(timeout=5, emit=events.append, index=3)
        done.set()

    th = threading.Thread(target=runner)
    th.start()
    for _ in range(500):
        if c.waiting:
            break
        time.sleep(0.002)
    assert c.waiting and not done.is_set()
    c.resume()
    th.join(5)
    assert done.is_set()
    assert [type(e).__name__ for e in events] == ["Paused", "Resumed"]
    assert events[0].index == 3

    c.abort()
    with pytest.raises(RunAborted) as info:
        c.checkpoint()
    c.pause()  # no effect after abort
    assert not c.paused and c.aborted
    assert info.value.outcome is Outcome.ABORTED and info.value.exit_code == 6


UI = Path(__file__).resolve().parents[2] / "station" / "ui" / "tui"
FORBIDDEN = ("drivers", "pymodbus", "serial", "sqlite3", "station.cell.pipeline.calibration")


@pytest.mark.parametrize("name", ["app.py", "widgets.py", "launch.py"])
def test_the_tui_reaches_devices_only_through_the_session(name):
    tree = ast.parse((UI / name).read_text(encoding="utf-8"))
    imported = [a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names]
    imported += [n.module or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)]
    bad = [m for m in imported if any(m == f or m.startswith(f + ".") for f in FORBIDDEN)]
    assert not bad, bad
