"""A finished run keeps its exit code (issue 33): SIGTERM or SIGINT right after the JSON with the
outcome is on stdout changes nothing — the process exits with the outcome's code, not 143 or 130,
however many signals arrive while it shuts down (README, "Signals and pipes"). Without the fix the
first of them ended the process with -15 (a shell's 143)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from station.cell.records.rundb import RunDB
from station.ui.cli.process.stop_signals import StopSignals

ROOT = Path(__file__).resolve().parents[2]
ENV = dict(os.environ, PYTHONPATH=str(ROOT))


def test_sigterm_and_sigint_right_after_the_json_keep_exit_0(tmp_path, short_cell):
    """A simulated calibration; from the moment its JSON line is read, SIGTERM and SIGINT in turn,
    again and again, until the process has exited: its exit code is still the outcome's, 0."""
    cell = short_cell  # the built-in cell, one visit and one cycle: what follows the outcome is tested, not accuracy
    proc = subprocess.Popen([sys.executable, "-m", "station.ui.cli.main", "calibrate", "--simulated", str(cell),
                             "--seed", "1", "--json", "--db", str(tmp_path / "runs.sqlite")],
                            cwd=tmp_path, env=ENV, text=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert proc.stdout is not None and proc.stderr is not None
    summary = json.loads(proc.stdout.readline())  # the outcome is decided and written: from here on, signals
    sent = 0
    while proc.poll() is None:  # not exited (poll reaps it once it has): a signal lands on a live process
        try:
            proc.send_signal((signal.SIGTERM, signal.SIGINT)[sent % 2])
        except ProcessLookupError:
            break
        sent += 1
    err = proc.stderr.read()
    proc.wait()
    assert summary["outcome"] == "SUCCESS", summary
    assert sent >= 2, "the process had exited before the signals: nothing was tested"
    assert proc.returncode == 0, (proc.returncode, sent, err[-2000:])
    assert "Traceback" not in err and "KeyboardInterrupt" not in err
    with RunDB(tmp_path / "runs.sqlite") as db:
        assert db.run(1).status == "verified"


def test_a_signal_after_the_session_only_says_so_once(capsys):
    class Control:
        aborted = 0

        def abort(self) -> None:
            self.aborted += 1

    stops, control = StopSignals(), Control()
    stops.control = control
    stops.control, stops.decided = None, True  # what safe_stop_on_signals leaves behind
    for _ in range(3):
        stops.handle(signal.SIGTERM, None)  # never raises, never aborts: the outcome stands
    assert control.aborted == 0 and len(stops.received) == 3


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_main_of_the_process_holds_the_signals_until_exit():
    """``catch_stop_signals(hold=True)`` leaves SIGTERM and SIGINT ignored when it ends."""
    from station.ui.cli.process.stop_signals import catch_stop_signals

    before = {s: signal.getsignal(s) for s in (signal.SIGTERM, signal.SIGINT)}
    try:
        with catch_stop_signals(hold=True):
            pass
        assert signal.getsignal(signal.SIGTERM) == signal.SIG_IGN
        assert signal.getsignal(signal.SIGINT) == signal.SIG_IGN
    finally:
        for s, h in before.items():
            signal.signal(s, h)
