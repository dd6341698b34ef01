"""Probe-head driver against the simulated unit over a real pseudo-terminal (and TCP)."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from drivers.probe_head import ProbeHead
from drivers.probe_protocol import (
    ChannelStatus,
    ProbeDeviceError,
    ProbeDisconnected,
    ProbeFrameError,
    ProbeOutOfRange,
    ProbeSpreadError,
    ProbeTimeout,
)
from simulators.probe_head_sim import (
    FaultKind,
    ProbeHeadPhysics,
    ProbeHeadServer,
    ProbeHeadTcpServer,
)
from station.core.kinematics.transforms import pose_to_matrix
from station.core.probe.geometry import readings_from_pose, solve_pose

# Long enough that a loaded CI machine does not time out a healthy 17 ms transaction, short
# enough that the tests which provoke timeouts stay quick.
TIMEOUT = 0.3


def wait_for(cond, timeout=2.0):
    deadline = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > deadline:
            raise AssertionError("condition not reached in time")
        time.sleep(0.002)


class Counter:
    """Source whose every call returns all channels equal to the call count (µm)."""

    def __init__(self, n=6):
        self.n, self.calls = n, 0
        self.lock = threading.Lock()

    def __call__(self):
        with self.lock:
            self.calls += 1
            return np.full(self.n, self.calls * 0.001)


@pytest.fixture
def counter_unit():
    src = Counter()
    with ProbeHeadServer(src, n_channels=6) as srv:
        yield srv, src


def test_snapshot_through_physics_solves_to_true_pose():
    physics = ProbeHeadPhysics(noise_mm=0.0005, seed=3)
    geom = physics.geometry
    M_true = geom.nominal_contact_pose() @ pose_to_matrix(
        np.array([0.3, -0.2, 0.4, 0.002, -0.001, 0.003]))
    with ProbeHeadServer(lambda: physics.readings(M_true)) as srv, ProbeHead(srv.port) as ph:
        info = ph.identify()
        assert info.channels == 6
        snap = ph.read_averaged(4, max_spread_mm=0.005)
    assert snap.all_ok
    exact = readings_from_pose(geom, M_true)
    assert np.max(np.abs(snap.values_mm - exact)) < 0.002  # 4σ of the mean of 4, plus 0.1 µm
    sol = solve_pose(geom, snap.values_mm, noise_mm=0.0005)
    assert np.max(np.abs(sol.M[:3, 3] - M_true[:3, 3])) < 0.01
    assert snap.raw.count(b"\r\n") == 4 and snap.raw.startswith(b"M0,")


def test_m0_is_one_consistent_snapshot(counter_unit):
    srv, src = counter_unit
    with ProbeHead(srv.port) as ph:
        a, b = ph.read_all(), ph.read_all()
    assert len(set(a.values_mm)) == 1 and len(set(b.values_mm)) == 1  # one source call each
    assert b.values_mm[0] == pytest.approx(a.values_mm[0] + 0.001)
    assert a.timestamp <= b.timestamp


def test_spread_bound_against_a_drifting_source(counter_unit):
    srv, _ = counter_unit
    with ProbeHead(srv.port) as ph:
        snap = ph.read_averaged(3, max_spread_mm=0.0025)  # drifts 1 µm per snapshot: 2 µm p-p
        assert snap.all_ok
        with pytest.raises(ProbeSpreadError) as info:
            ph.read_averaged(3, max_spread_mm=0.0015)
    assert info.value.spread_mm == pytest.approx(0.002)


def test_zero_preset_clear_on_the_unit():
    values = np.array([1.0, 2.0, 3.0, np.nan, 5.0, 6.0])
    with ProbeHeadServer(lambda: values) as srv, ProbeHead(srv.port) as ph:
        with pytest.raises(ProbeDeviceError) as info:
            ph.read_channel(9)  # driver does not know the count yet: the unit refuses
        assert info.value.code == 3
        ph.zero(1)
        ph.preset(2, -0.25)
        snap = ph.read_all()
        np.testing.assert_allclose(snap.values_mm[[0, 1, 2]], [1.0, 0.0, -0.25])
        assert ph.read_channel(1) == (0.0, ChannelStatus.OK)
        ph.clear_zero(1)
        assert ph.read_channel(1) == (2.0, ChannelStatus.OK)
        with pytest.raises(ProbeDeviceError) as info:
            ph.zero(3)  # invalid reading: nothing to zero on
        assert info.value.code == 4
        assert ph.read_all().values_mm[0] == 1.0  # the link is fine afterwards


@pytest.mark.parametrize(
    "fault, error",
    [(FaultKind.GARBLE, ProbeFrameError), (FaultKind.TRUNCATE, ProbeTimeout),
     (FaultKind.DROP, ProbeTimeout), (FaultKind.BUSY, ProbeDeviceError)],
)
def test_one_shot_fault_raises_typed_error_then_recovers(counter_unit, fault, error):
    srv, _ = counter_unit
    with ProbeHead(srv.port, timeout=TIMEOUT, retries=0) as ph:
        srv.faults.inject(fault)
        with pytest.raises(error):
            ph.read_all()
        assert ph.read_all().all_ok


@pytest.mark.parametrize("fault", list(FaultKind))
def test_retries_hide_a_single_fault_on_reads(counter_unit, fault):
    srv, _ = counter_unit
    with ProbeHead(srv.port, timeout=TIMEOUT, retries=1) as ph:
        srv.faults.inject(fault)
        assert ph.read_all().all_ok
        assert srv.faults.pending == 0


def test_zero_is_not_retried_after_a_lost_reply(counter_unit):
    srv, _ = counter_unit
    with ProbeHead(srv.port, timeout=TIMEOUT, retries=2) as ph:
        srv.faults.inject(FaultKind.DROP)
        done = srv.requests_done
        with pytest.raises(ProbeTimeout, match="not repeated"):
            ph.zero(0)
        assert srv.requests_done == done + 1  # the unit saw exactly one ZS
        # the zero did take effect on the unit: reading it back is how to find out
        value, status = ph.read_channel(0)
        assert status is ChannelStatus.OK and abs(value) < 0.01


def test_late_reply_is_flushed_not_taken_for_the_next(counter_unit):
    srv, src = counter_unit
    with ProbeHead(srv.port, timeout=TIMEOUT, retries=0) as ph:
        srv.faults.latency_s = TIMEOUT + 0.15
        with pytest.raises(ProbeTimeout):
            ph.read_all()
        srv.faults.latency_s = 0.0
        wait_for(lambda: srv.requests_done >= 1)  # the late reply is now in the driver's input
        snap = ph.read_all()
    # the late reply carried call 1; the fresh one carries call 2
    assert snap.values_mm[0] == pytest.approx(0.002)
    assert src.calls == 2


def test_forced_marker_reports_status(counter_unit):
    srv, _ = counter_unit
    with ProbeHead(srv.port) as ph:
        srv.faults.force_status(4, ChannelStatus.OVER_RANGE)
        snap = ph.read_all()
        assert snap.status[4] is ChannelStatus.OVER_RANGE and np.isnan(snap.values_mm[4])
        with pytest.raises(ProbeOutOfRange, match="04: OVER_RANGE"):
            snap.require_ok()
        srv.faults.force_status(4, None)
        assert ph.read_all().all_ok


def test_disconnect_gives_probe_disconnected(counter_unit):
    srv, _ = counter_unit
    ph = ProbeHead(srv.port, timeout=TIMEOUT)
    assert ph.read_all().all_ok
    srv.disconnect()
    with pytest.raises(ProbeDisconnected, match="reconnect"):
        ph.read_all()
    with pytest.raises(ProbeDisconnected):
        ProbeHead(srv.port)


def test_tcp_variant_over_socket_url():
    src = Counter()
    with ProbeHeadTcpServer(src, n_channels=6) as srv:
        assert srv.url.startswith("socket://127.0.0.1:")
        # one client only: pyserial's socket:// close() sleeps 0.3 s by design
        with ProbeHead(srv.url, timeout=0.5) as ph:
            assert ph.identify().channels == 6
            assert ph.read_all().values_mm[0] == pytest.approx(0.001)
            srv.faults.inject(FaultKind.GARBLE)
            assert ph.read_all().values_mm[0] == pytest.approx(0.003)  # retried: calls 2 and 3


def test_physics_markers_noise_and_quantisation():
    physics = ProbeHeadPhysics(noise_mm=0.0005, seed=1)
    geom = physics.geometry
    assert (physics.readings(None) == np.inf).all()  # nothing touched: over range at the extended stop
    M = geom.nominal_contact_pose()
    r = np.array([physics.readings(M) for _ in range(400)])
    np.testing.assert_allclose(r * 1e4, np.round(r * 1e4), atol=1e-6)  # 0.1 µm steps
    assert 0.0004 < r.std() < 0.0006
    # cube 30 mm farther away: top probes fully extended, side probes above the cube
    far = M @ pose_to_matrix(np.array([0, 0, -30.0, 0, 0, 0]))
    assert np.isposinf(physics.readings(far)[:3]).all()
    assert np.isnan(physics.readings(far)[3:]).all()
    near = M @ pose_to_matrix(np.array([0, 0, 6.0, 0, 0, 0]))  # 6 mm closer: pushed past -5
    assert np.isneginf(physics.readings(near)[:3]).all()
    again = ProbeHeadPhysics(noise_mm=0.0005, seed=1).readings(M)
    np.testing.assert_array_equal(again, r[0])


def test_server_source_failure_is_reported_not_swallowed():
    def broken():
        raise RuntimeError("pose source died")

    srv = ProbeHeadServer(broken, n_channels=6).start()
    with ProbeHead(srv.port, timeout=TIMEOUT, retries=0) as ph:
        with pytest.raises(ProbeTimeout):
            ph.read_all()
    wait_for(lambda: srv.failure is not None)
    with pytest.raises(RuntimeError, match="failed while serving"):
        srv.stop()
