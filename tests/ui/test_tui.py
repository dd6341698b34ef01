"""Operator UI driven headless with Textual's Pilot against a scripted fake runner."""

from __future__ import annotations

import threading
import time

import pytest

from station.cell.events import (
    MeasurementRecorded,
    Notice,
    PhaseChanged,
    RunFailed,
    RunFinished,
    RunStarted,
    StepStarted,
)
from station.cell.runcontrol import RunAborted, RunControl
from station.ui.tui import ConfirmScreen, StationApp, exit_code_for

from textual.content import Content
from textual.widgets import DataTable, ProgressBar, Static

N = 5
LABELS = [f"point C{i}.a, elbow +1" for i in range(N)]
RESIDUALS = [1.25, 2.5, 0.75, 3.0, 1.5]
SUMMARY = {
    "rms_before_um": 812.4,
    "rms_after_um": 23.6,
    "ratio": 34.42,
    "oracle_rms_after_um": 21.9,
    "exit_code": 0,
}


class FakeRunner:
    """Scripted stand-in for station.cell.pipeline.run_calibration.

    With ``gate`` set, it waits on the gate before each step so a test can place key presses
    between steps deterministically; it calls ``control.checkpoint()`` at each safe point and
    records what happened.
    """

    def __init__(self, *, fail: RunFailed | None = None, gated: bool = False, raise_exc: Exception | None = None,
                 summary: dict | None = None, returns: dict | None = None, outcome: str = "calibrated"):
        self.fail = fail
        self.summary = dict(SUMMARY) if summary is None else summary
        self.returns = returns
        self.outcome = outcome
        self.raise_exc = raise_exc
        self.gate = threading.Semaphore(0) if gated else None
        self.checkpoints_passed = 0
        self.in_checkpoint = threading.Event()
        self.aborted = False
        self.finished = False
        self.thread_name: str | None = None

    def __call__(self, emit, control: RunControl) -> dict:
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
                emit(
                    MeasurementRecorded(
                        index=i, total=N, label=LABELS[i], ok=(i != 3), residual_um=RESIDUALS[i],
                        message="" if i != 3 else "probe 4 out of range",
                    )
                )
            if self.raise_exc is not None:
                raise self.raise_exc
            if self.fail is not None:
                emit(self.fail)
                return dict(self.returns) if self.returns is not None else {}
            emit(Notice("warning", "backlash 0.1 mm dominates the attainable accuracy"))
            emit(PhaseChanged("identify", "20 parameters"))
            emit(PhaseChanged("verify"))
            emit(RunFinished(outcome=self.outcome, summary=dict(self.summary)))
            self.finished = True
            return dict(self.returns) if self.returns is not None else dict(self.summary)
        except RunAborted:
            self.aborted = True
            self.in_checkpoint.clear()
            raise


def plain(widget: Static) -> str:
    content = widget.content
    if isinstance(content, str):
        return Content.from_markup(content).plain
    return str(content)


async def wait_until(pilot, cond, what: str, rounds: int = 400) -> None:
    """Let the app process messages until ``cond()`` holds (bounded, no long sleeps)."""
    for _ in range(rounds):
        if cond():
            return
        await pilot.pause(0.01)
    raise AssertionError(f"timed out waiting for: {what}")


def open_gate(runner: FakeRunner, n: int = 1) -> None:
    for _ in range(n):
        runner.gate.release()


async def test_full_run_progress_table_and_summary():
    runner = FakeRunner()
    app = StationApp(runner, title="SR 800 test")
    async with app.run_test(size=(120, 40)) as pilot:
        assert app.state == "idle"
        await pilot.press("s")
        await wait_until(pilot, lambda: app.state == "finished", "run finished")

        # the runner ran in a worker thread, not on the UI thread
        assert runner.thread_name != threading.main_thread().name
        assert runner.finished and runner.checkpoints_passed == N

        bar = app.query_one("#progress", ProgressBar)
        assert bar.total == N and bar.progress == N

        table = app.query_one("#measurements", DataTable)
        assert table.row_count == N
        for i in range(N):
            idx, label, ok, residual, note = (str(c) for c in table.get_row_at(i))
            assert idx == str(i + 1)
            assert label == LABELS[i]
            assert ("✗" in ok) if i == 3 else ("✓" in ok)
            assert residual == f"{RESIDUALS[i]:.2f}"
        assert "probe 4 out of range" in str(table.get_row_at(3)[4])

        assert app.run_id == 42
        assert "run #42" in plain(app.query_one("#run-id", Static))
        summary = plain(app.query_one("#summary", Static))
        assert app.query_one("#summary").display
        for needle in ("calibrated", "812.4 µm", "23.6 µm", "34.4 ×", "21.9 µm", "exit code"):
            assert needle in summary, (needle, summary)
        assert app.outcome == "calibrated" and app.exit_code == 0
        assert "done" in plain(app.query_one("#phases", Static))

        await pilot.press("q")  # not running any more: quits at once
        await wait_until(pilot, lambda: not app.is_running, "app exit")
    assert app.return_code == 0
    assert app.return_value["rms_after_um"] == pytest.approx(23.6)


async def test_start_button_starts_the_run():
    runner = FakeRunner()
    app = StationApp(runner)
    async with app.run_test(size=(120, 40)) as pilot:
        await pilot.click("#start")
        await wait_until(pilot, lambda: app.state == "finished", "run finished")
        assert runner.finished


async def test_pause_blocks_runner_at_checkpoint_and_resume_releases():
    runner = FakeRunner(gated=True)
    app = StationApp(runner)
    async with app.run_test(size=(120, 40)) as pilot:
        await pilot.press("s")
        open_gate(runner, 2)
        await wait_until(pilot, lambda: app.query_one("#measurements", DataTable).row_count == 2, "2 rows")

        await pilot.press("p")
        assert app.control.paused
        assert app.state in ("pausing", "paused")
        open_gate(runner)  # runner reaches its next checkpoint and must block there
        await wait_until(pilot, lambda: app.control.waiting, "runner blocked in checkpoint")
        await wait_until(pilot, lambda: app.state == "paused", "UI shows paused")
        assert runner.checkpoints_passed == 2
        # it stays blocked while paused
        for _ in range(10):
            await pilot.pause(0.01)
        assert runner.checkpoints_passed == 2 and runner.in_checkpoint.is_set()
        assert "PAUSED" in plain(app.query_one("#state", Static))

        await pilot.press("p")  # resume
        await wait_until(pilot, lambda: runner.checkpoints_passed == 3, "runner released")
        assert app.state == "running" and not app.control.paused
        open_gate(runner, N)
        await wait_until(pilot, lambda: app.state == "finished", "run finished")
        assert app.query_one("#progress", ProgressBar).progress == N


async def test_abort_with_confirmation_raises_in_runner_and_shows_aborted():
    runner = FakeRunner(gated=True)
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
        assert not app.control.aborted and app.state == "running"

        await pilot.press("a")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen), "confirm dialog")
        await pilot.press("y")
        await wait_until(pilot, lambda: app.control.aborted, "abort flag")
        open_gate(runner, 1)  # next safe point
        await wait_until(pilot, lambda: app.state == "aborted", "UI shows aborted")
        assert runner.aborted and not runner.finished
        assert runner.checkpoints_passed == 1
        assert app.exit_code == RunAborted.exit_code == 6
        summary = plain(app.query_one("#summary", Static))
        assert "ABORTED" in summary and "exit code 6" in summary


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


async def test_run_failed_shows_message_and_hint():
    fail = RunFailed(
        error_type="IdentificationError",
        message="rank 17 < 20: the poses do not excite axis 2",
        hint="plan poses over the whole workspace (station plan --spread 3d)",
    )
    runner = FakeRunner(fail=fail)
    app = StationApp(runner)
    async with app.run_test(size=(120, 40)) as pilot:
        await pilot.press("s")
        await wait_until(pilot, lambda: app.state == "failed", "failed")
        text = plain(app.query_one("#summary", Static))
        assert "IdentificationError" in text
        assert fail.message in text
        assert fail.hint in text
        assert app.exit_code == 3
        await pilot.press("q")
        await wait_until(pilot, lambda: not app.is_running, "app exit")
    assert app.return_code == 3


async def test_runner_exception_without_event_is_shown():
    from station.errors import ConfigError

    runner = FakeRunner(raise_exc=ConfigError("cell.toml: probe 7 has no direction"))
    app = StationApp(runner)
    async with app.run_test(size=(120, 40)) as pilot:
        await pilot.press("s")
        await wait_until(pilot, lambda: app.state == "failed", "failed")
        text = plain(app.query_one("#summary", Static))
        assert "ConfigError" in text and "probe 7 has no direction" in text
        assert app.exit_code == 2


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
    with pytest.raises(RunAborted):
        c.checkpoint()
    c.pause()  # no effect after abort
    assert not c.paused and c.aborted
    assert RunAborted.exit_code == 6


def test_exit_code_mapping():
    assert exit_code_for("IdentificationError") == 3
    assert exit_code_for("UnreachableError") == 4
    assert exit_code_for("RunAborted") == 6
    assert exit_code_for("ZeroDivisionError") == 1


# The pipeline's own summary layout (station.cell.pipeline): nested stats, "gain", exit code only in
# the return value (added by the launcher), outcome names of station.cell.pipeline.Outcome.
PIPELINE_SUMMARY = {
    "run_id": 7, "cell": "sim", "robot": "SR 800",
    "identification": {"n_parameters": 20, "rms_residual_um": 9.87, "parameters": {"A2.x": {"value": 445.0}}},
    "before": {"n": 12, "rms_um": 1012.3, "max_um": 1500.0, "ap_max_um": 1400.0, "rp_max_um": 31.0,
               "errors_um": [1.0, 2.0]},
    "after": {"n": 12, "rms_um": 24.6, "max_um": 40.0, "ap_max_um": 35.5, "rp_max_um": 30.2, "errors_um": []},
    "oracle": {"n": 12, "rms_um": 20.1},
    "gain": 41.15, "after_vs_oracle": 1.224, "upload": {"crc32": "deadbeef", "verified": True},
    "outcome": "TARGET_MISSED",
}


async def test_pipeline_summary_layout_and_exit_code_from_return_value():
    runner = FakeRunner(summary=PIPELINE_SUMMARY, outcome="TARGET_MISSED",
                        returns={**PIPELINE_SUMMARY, "exit_code": 10})
    app = StationApp(runner)
    async with app.run_test(size=(120, 45)) as pilot:
        await pilot.press("s")
        await wait_until(pilot, lambda: app.state == "finished" and app.exit_code == 10, "finished, code 10")
        text = plain(app.query_one("#summary", Static))
        for needle in ("TARGET_MISSED", "SR 800", "RMS before         1012.3 µm", "24.6 µm", "41.1 ×",
                       "20.1 µm", "1.22 ×", "35.5 µm", "30.2 µm", "identified parameters", "exit code          10"):
            assert needle.split("  ")[-1].strip() in text, (needle, text)
        assert "-failed" in app.query_one("#summary").classes  # non-zero code: red frame
        await pilot.press("q")
        await wait_until(pilot, lambda: not app.is_running, "exit")
    assert app.return_code == 10


async def test_outcome_name_gives_exit_code_without_explicit_one():
    summary = {k: v for k, v in PIPELINE_SUMMARY.items()}
    runner = FakeRunner(summary=summary, outcome="SUCCESS", returns={})
    app = StationApp(runner)
    async with app.run_test(size=(120, 45)) as pilot:
        await pilot.press("s")
        await wait_until(pilot, lambda: app.state == "finished", "finished")
        assert app.exit_code == 0
        assert "-ok" in app.query_one("#summary").classes


async def test_run_failed_then_returned_exit_code_wins():
    # The launcher emits RunFailed for a driver's own error type and returns its exit code.
    fail = RunFailed("DeviceFault", "controller heartbeat lost", "check the fieldbus cable")
    runner = FakeRunner(fail=fail, returns={"outcome": "DeviceFault", "exit_code": 7})
    app = StationApp(runner)
    async with app.run_test(size=(120, 40)) as pilot:
        await pilot.press("s")
        await wait_until(pilot, lambda: app.exit_code == 7, "exit code 7")
        text = plain(app.query_one("#summary", Static))
        assert "DeviceFault" in text and "check the fieldbus cable" in text and "exit code 7" in text
        assert app.state == "failed"


def test_outcome_mirror_matches_pipeline():
    calibrate = pytest.importorskip("station.cell.pipeline")
    from station.ui.tui import OUTCOME_EXIT_CODES

    assert OUTCOME_EXIT_CODES == {o.name: int(o) for o in calibrate.Outcome}
