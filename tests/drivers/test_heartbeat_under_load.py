"""The PC heartbeat keeps the controller's watchdog fed on a busy PC (issue 19).

The simulated controller runs in its own process (``python -m simulators``), as a real robot
controller does, with its watchdog as configured (1 s). The station's process meanwhile holds
the GIL in pure-Python numerics and two CPU hogs load both cores. The driver's heartbeat writer
is a dedicated thread: the interpreter hands it the GIL at every switch interval, so neither
the numerics nor the load can starve it, and a real-time move completes instead of being
aborted by the watchdog. (The same move without a heartbeat is aborted:
``test_controller_sim.py::test_controller_watchdog_stops_move_without_pc_heartbeat``.)
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from drivers.controller import ModbusController

ROOT = Path(__file__).resolve().parents[2]


class _CountingController(ModbusController):
    """Records when each heartbeat exchange happened (monotonic seconds)."""

    def __init__(self, *a, **kw) -> None:
        super().__init__(*a, **kw)
        self.beats: list[float] = []

    def _heartbeat_once(self) -> int:
        self.beats.append(time.monotonic())
        return super()._heartbeat_once()


def _gil_bound_numerics(stop: threading.Event) -> int:
    """Pure-Python arithmetic that holds the GIL between switch intervals (no numpy release)."""
    n = 0
    acc = 0.0
    while not stop.is_set():
        for i in range(20_000):
            acc += (i * 1.000001) ** 0.5
        n += 1
    return n


@pytest.fixture
def controller_process():
    p = subprocess.Popen([sys.executable, "-m", "simulators", "--time-scale", "1"], cwd=ROOT,
                         stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                         env={**os.environ, "PYTHONUNBUFFERED": "1"})
    line = p.stdout.readline()  # readiness: printed once both endpoints accept traffic
    if not line:
        p.kill()
        raise AssertionError("simulator process did not start")
    host, port = json.loads(line)["controller"].rsplit(":", 1)
    yield host, int(port)
    p.send_signal(signal.SIGTERM)
    try:
        p.wait(timeout=20)
    except subprocess.TimeoutExpired:
        p.kill()


@pytest.fixture
def cpu_hogs():
    hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"], stdin=subprocess.DEVNULL)
            for _ in range(2)]
    yield
    for h in hogs:
        h.kill()
        h.wait()


def test_heartbeat_feeds_the_watchdog_through_numerics_and_cpu_load(controller_process, cpu_hogs):
    host, port = controller_process
    # The driver's defaults for a real controller: 0.2 s period, 1 s link timeout; the reply
    # deadline is widened only so that the loaded machine's connect handshake does not flake.
    with _CountingController(host, port, timeout=5.0) as c:
        limits = c.status()  # a ready controller before the load starts
        assert limits.ready
        q0 = c.read_joints()
        target = q0.copy()
        target[0] += 0.6  # a slow joint-1 move: seconds of real time under the watchdog
        stop = threading.Event()
        worker_result: list[int] = []
        worker = threading.Thread(target=lambda: worker_result.append(_gil_bound_numerics(stop)))
        worker.start()
        try:
            t0 = time.monotonic()
            status = c.move_joints(target, speed=0.15)
            status.wait(60.0)  # raises MotionAborted (WATCHDOG_TIMEOUT) if the heartbeat starved
            elapsed = time.monotonic() - t0
        finally:
            stop.set()
            worker.join()
        assert worker_result and worker_result[0] > 0  # the numerics really ran beside the move
        assert c.link_lost is None
        st = c.status()
        assert not st.error, f"controller error {st.error_code} after the move"
        np.testing.assert_allclose(c.read_joints()[0], target[0], atol=1e-5)
        beats = [b for b in c.beats if t0 <= b <= t0 + elapsed]
        # The watchdog was fed throughout: beats kept coming during the whole move (the move
        # completing is the proof; this says the test measured a move that needed them).
        assert elapsed > 1.0 and len(beats) >= 3
