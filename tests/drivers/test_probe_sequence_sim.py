"""The probe driver's sequence rule against the simulated unit over a real pseudo-terminal.

Issue 12, item 7 (stale replies) and item 9 (determinism): a reply that arrives after the
timeout must never be taken for the answer to a later request, unsolicited frames are dropped,
and a run with one stalled reply gives the same readings as a run without it, except for the
one request that stalled. No test here asserts a wall-clock time; waits are on events.
"""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from drivers.probe_head import ProbeHead
from drivers.probe_protocol import ProbeTimeout
from simulators.probe_head_sim import ProbeHeadServer, ProbeHeadTcpServer

TIMEOUT = 0.3
LATE = TIMEOUT + 0.25  # the stalled reply arrives well after the driver gave up on it


def wait_for(cond, timeout=3.0):
    deadline = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > deadline:
            raise AssertionError("condition not reached in time")
        time.sleep(0.002)


class Counter:
    """Every call returns all channels equal to the call count (µm)."""

    def __init__(self, n=6):
        self.n, self.calls = n, 0
        self.lock = threading.Lock()

    def __call__(self):
        with self.lock:
            self.calls += 1
            return np.full(self.n, self.calls * 0.001)


class Cell:
    """Like the simulated cell: the reading depends on where the robot stands (``state``, set
    by the test as a move would) plus a 'noise' keyed to the number of reads since the move."""

    def __init__(self, n=6):
        self.n = n
        self.state = 0
        self.reads = 0
        self.lock = threading.Lock()

    def move(self, state: int) -> None:
        with self.lock:
            self.state, self.reads = state, 0

    def __call__(self):
        with self.lock:
            self.reads += 1
            return np.full(self.n, self.state + self.reads * 0.0001)


def test_late_reply_is_discarded_and_the_next_request_gets_its_own():
    src = Counter()
    with ProbeHeadServer(src, n_channels=6) as srv, \
            ProbeHead(srv.port, timeout=TIMEOUT, retries=0) as ph:
        srv.faults.inject_delay(LATE)
        with pytest.raises(ProbeTimeout):
            ph.read_all()            # call 1 is late
        snap = ph.read_all()         # at once: the late reply has not even arrived yet
        assert snap.values_mm[0] == pytest.approx(0.002)  # its own reply (call 2), not call 1
        assert src.calls == 2
        assert ph.stats.resyncs == 1 and ph.stats.discarded_frames == 1
        assert ph.read_all().values_mm[0] == pytest.approx(0.003)  # and it stays in step
    assert b"M0,+000.0010" not in snap.raw


def test_late_reply_is_not_taken_for_the_retry():
    cell = Cell()
    with ProbeHeadServer(cell, n_channels=6) as srv, \
            ProbeHead(srv.port, timeout=TIMEOUT, retries=2) as ph:
        cell.move(5)
        srv.faults.inject_delay(LATE)
        first = ph.read_all()        # attempt 1 is late; the retry answers
        cell.move(7)
        second = ph.read_all()
    # the retry is the second read at state 5; the reading after the move is from state 7
    assert first.values_mm[0] == pytest.approx(5.0002)
    assert second.values_mm[0] == pytest.approx(7.0001)
    assert ph.stats.retries == 1 and ph.stats.discarded_frames == 1


@pytest.mark.parametrize("frame", [
    b"M0,+999.0000,+999.0000,+999.0000,+999.0000,+999.0000,+999.0000\r\n",
    b"ID,BABBLE,9.9,06\r\n",
])
def test_unsolicited_frame_between_requests_is_discarded(frame):
    src = Counter()
    with ProbeHeadServer(src, n_channels=6) as srv, \
            ProbeHead(srv.port, timeout=TIMEOUT, retries=0) as ph:
        assert ph.read_all().values_mm[0] == pytest.approx(0.001)
        srv.send_unsolicited(frame)
        wait_for(lambda: ph._port.in_waiting >= len(frame))  # it is in the driver's input
        snap = ph.read_all()
    assert snap.values_mm[0] == pytest.approx(0.002)
    assert ph.stats.discarded_frames == 1 and ph.stats.discarded_bytes == len(frame)


def test_unsolicited_frame_while_waiting_for_the_reply_is_discarded():
    src = Counter()
    with ProbeHeadServer(src, n_channels=6) as srv, \
            ProbeHead(srv.port, timeout=TIMEOUT, retries=0) as ph:
        srv.faults.inject_unsolicited(b"ID,BABBLE,9.9,06\r\n")
        srv.faults.inject_unsolicited(b"M0,+123.4567,+123.4567\r\n")
        assert ph.read_all().values_mm[0] == pytest.approx(0.001)
        assert ph.read_channel(2) == (pytest.approx(0.002), ph.read_all().status[2])
        assert srv.unsolicited_sent == 2
    assert ph.stats.discarded_frames == 2 and ph.stats.retries == 0


def test_late_reply_over_tcp_is_discarded():
    src = Counter()
    with ProbeHeadTcpServer(src, n_channels=6) as srv, \
            ProbeHead(srv.url, timeout=TIMEOUT, retries=0) as ph:
        srv.faults.inject_delay(LATE)
        with pytest.raises(ProbeTimeout):
            ph.read_all()
        assert ph.read_all().values_mm[0] == pytest.approx(0.002)


def _steps(delay_on: int | None, retries: int) -> list:
    """Eight 'steps' of a run: move, then an averaged reading of three snapshots. The reply of
    request number ``delay_on`` (0-based over the whole run) is held back past the timeout."""
    cell = Cell()
    out: list = []
    with ProbeHeadServer(cell, n_channels=6) as srv, \
            ProbeHead(srv.port, timeout=TIMEOUT, retries=retries) as ph:
        request = 0
        for step in range(8):
            cell.move(step + 1)
            snaps = []
            for _ in range(3):
                if request == delay_on:
                    srv.faults.inject_delay(LATE)
                request += 1
                try:
                    snaps.append(ph.read_all().values_mm.copy())
                except ProbeTimeout:
                    snaps.append(None)
            out.append(snaps)
    return out


@pytest.mark.parametrize("retries", [0, 2])
def test_one_stalled_reply_changes_only_its_own_request(retries):
    clean = _steps(None, retries)
    stalled = _steps(10, retries)  # step 3, second snapshot
    for step, (a, b) in enumerate(zip(clean, stalled)):
        for k, (x, y) in enumerate(zip(a, b)):
            if step == 3 and k == 1 and not retries:
                assert y is None  # ProbeTimeout for that request, and nothing else changes
            elif step == 3 and k >= 1 and retries:
                # the retry is a fresh reading (the next one at that pose), and so are the
                # readings after it in the same step; the late reply itself is never used
                np.testing.assert_allclose(y, x + 0.0001)
            else:
                np.testing.assert_array_equal(x, y, err_msg=f"step {step} snapshot {k}")
