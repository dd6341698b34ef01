"""The operator UI over the real session (``run_calibration_session``): outcomes and exit
codes as the CLI has them, a device fault included."""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

import pytest
from textual.widgets import DataTable

from station.cell.config.template import TEMPLATE
from station.cell.session.calibrate import CellRequest, run_calibration_session
from station.errors import Outcome
from station.ui.simulated_cell import load_cell
from station.ui.tui import launch as tui_launch
from station.ui.tui.app import ConfirmScreen, StationApp
from station.ui.tui.result_panel import HEADLINE_FIGURES


def panel(app: StationApp) -> str:
    """The result panel's rows (unwrapped: the panel wraps long values within their column)."""
    return app.result_text


def exit_code_row(text: str) -> str:
    m = re.search(r"^exit code\s+(\d+)$", text, re.MULTILINE)
    assert m, text
    return m.group(1)


async def wait_until(pilot, cond, what: str, rounds: int = 3000) -> None:
    for _ in range(rounds):
        if cond():
            return
        await pilot.pause(0.01)
    raise AssertionError(f"timed out waiting for: {what}")


@pytest.fixture
def missing_probe_request(tmp_path: Path) -> Iterator[CellRequest]:
    """A valid cell configuration whose probe head is a serial device that does not exist; its
    controller is the simulated one, which answers (the session connects the controller first)."""
    from simulators import start_simulated_cell

    tty = tmp_path / "no-such-tty"
    with start_simulated_cell() as servers:
        controller = f'"{servers.controller_host}:{servers.controller_port}"'
        text = TEMPLATE.replace('"192.168.0.10:502"', controller).replace(
            'probe_head = "/dev/ttyUSB0"', f'probe_head = "{tty.as_posix()}"')
        assert str(tty) in text and controller in text
        config = tmp_path / "cell.toml"
        config.write_text(text, encoding="utf-8")
        yield CellRequest(config=str(config), db=str(tmp_path / "runs.sqlite"))


async def test_probe_head_fault_is_a_device_fault_not_an_internal_error(missing_probe_request, tmp_path):
    request = missing_probe_request
    app = StationApp(lambda emit, control: run_calibration_session(request, emit, control), log_dir=tmp_path)
    async with app.run_test(size=(160, 45)) as pilot:
        await pilot.press("s")
        await wait_until(pilot, lambda: app.worker is not None and app.worker.is_finished, "run ended")
        await pilot.pause()
        assert app.state == "failed"
        assert app.summary is not None and app.summary.outcome is Outcome.DEVICE_FAULT
        assert app.exit_code == 7
        failure = app.failure
        assert failure is not None and failure.error_type == "ProbeDisconnected" and failure.log_file is None
        text = panel(app)
        assert "no-such-tty" in text  # the message names the device
        assert failure.hint and f"Next: {failure.hint}" in text
        assert exit_code_row(text) == "7"
        await pilot.press("q")
        await wait_until(pilot, lambda: not app.is_running, "app exit")
    assert app.return_code == 7
    assert not list(tmp_path.glob("station-error-*.log"))


class _HeadlessApp(StationApp):
    """StationApp whose run() presses Start, waits for the end and quits, without a terminal."""

    def run(self, *args, **kwargs):  # type: ignore[override]
        async def operator(pilot) -> None:
            await pilot.press("s")
            await wait_until(pilot, lambda: self.worker is not None and self.worker.is_finished, "run ended")
            await pilot.pause()
            await pilot.press("q")

        return super().run(headless=True, size=(160, 45), auto_pilot=operator)


def test_launch_returns_the_sessions_exit_code(missing_probe_request, monkeypatch):
    monkeypatch.setattr(tui_launch, "StationApp", _HeadlessApp)
    assert tui_launch.launch(missing_probe_request) == Outcome.DEVICE_FAULT == 7


# -- a full calibration of the simulated cell (needs the pipeline's RunSummary) ----------------

@pytest.mark.slow  # an end-to-end session: the slow tier (README), run by CI
async def test_simulated_calibration_through_the_ui(tmp_path, short_cell):
    # the built-in cell with one visit per identification pose and one verification cycle: the
    # panel's rows and the exit code are the same on the shorter run (issue 42: the suite's time)
    request = CellRequest(config=str(short_cell), simulated=True, db=str(tmp_path / "runs.sqlite"))
    app = StationApp(lambda emit, control: run_calibration_session(request, emit, control, load=load_cell),
                     log_dir=tmp_path)
    async with app.run_test(size=(120, 32)) as pilot:
        await pilot.press("s")
        await wait_until(pilot, lambda: app.worker is not None and app.worker.is_finished, "run ended", 12000)
        await pilot.pause()
        summary = app.summary
        assert summary is not None, panel(app)
        assert summary.failure is None, summary.failure
        assert summary.outcome in (Outcome.SUCCESS, Outcome.TARGET_MISSED)
        assert app.exit_code == summary.exit_code and app.state == "finished"
        assert summary.db == request.db  # the returned summary, not only the event's
        text = panel(app)
        for label, *_ in summary.figures():
            if label in HEADLINE_FIGURES:
                assert label in text
        assert "ISO 9283 after" in text and "identification" in text and "Next: " in text
        assert exit_code_row(text) == str(summary.exit_code)
        assert app.query_one("#measurements", DataTable).row_count > 0
        await pilot.press("q")
        await wait_until(pilot, lambda: not app.is_running, "app exit")
    assert app.return_code == summary.exit_code


async def test_operator_abort_of_the_simulated_cell_is_exit_code_6(tmp_path):
    request = CellRequest(simulated=True, db=str(tmp_path / "runs.sqlite"))
    app = StationApp(lambda emit, control: run_calibration_session(request, emit, control, load=load_cell),
                     log_dir=tmp_path)
    async with app.run_test(size=(120, 32)) as pilot:
        await pilot.press("s")
        await wait_until(pilot, lambda: app.query_one("#measurements", DataTable).row_count >= 2, "2 rows")
        await pilot.press("a")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen), "confirm dialog")
        await pilot.press("y")
        await wait_until(pilot, lambda: app.worker is not None and app.worker.is_finished, "run ended")
        await pilot.pause()
        assert app.summary is not None and app.summary.outcome is Outcome.ABORTED, panel(app)
        assert app.state == "aborted" and app.exit_code == 6
        assert app.summary.run_id is not None
        assert f"Next: press c: run #{app.summary.run_id} goes on at its next step" in panel(app)
