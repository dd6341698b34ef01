"""The DL-RS1A and Mitutoyo dialects against their simulated units over a real pseudo-terminal."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from drivers.probe_head import ProbeHead
from drivers.probe_protocol import ChannelStatus, ProbeDialectMismatch, ProbeLineGarbled, ProbeTimeout
from simulators.probe_head_sim import FaultKind, ProbeHeadServer

VALUES = np.array([0.1234, -0.0021, 1.5, 2.25, -3.0, 0.5])
TIMEOUT = 0.3


def keyence_server(values=VALUES, **kw) -> ProbeHeadServer:
    kw.setdefault("pace", False)
    return ProbeHeadServer(lambda: values, protocol="keyence-dl-rs1a", **kw)


def test_dl_rs1a_check_at_its_factory_settings():
    with keyence_server() as srv, ProbeHead(srv.port, 9600, dialect="keyence-dl-rs1a", timeout=TIMEOUT) as ph:
        info = ph.identify()
        assert (info.model, info.channels) == ("DL-RS1A", 6)
        np.testing.assert_allclose(ph.read_averaged(3, 0.001).values_mm, VALUES)
        assert srv.garbled_replies == 0


def test_dl_rs1a_answers_only_its_manuals_commands():
    with keyence_server() as srv:
        unit = srv.unit
        assert unit.handle(b"ID") == b"ER,ID,00\r\n"
        assert unit.handle(b"MS,03") == b"ER,MS,21\r\n"
        assert unit.handle(b"SR,06,101") == b"ER,SR,65\r\n"   # the manual's example: no amplifier 06
        assert unit.handle(b"SR,00,121") == b"SR,00,121,0\r\n"  # preset memory: YES (initial)
        assert unit.handle(b"SW,00,103,2") == b"ER,SW,67\r\n"  # read/write switch on R
        assert unit.handle(b"MS").startswith(b"MS,0,+000.1234,0,-000.0021,")


def test_wrong_baud_rate_garbles_and_names_the_line_settings():
    with keyence_server() as srv, ProbeHead(srv.port, 38400, dialect="keyence-dl-rs1a", timeout=TIMEOUT,
                                            retries=0) as ph:
        with pytest.raises(ProbeLineGarbled) as err:
            ph.identify()
        msg = str(err.value)
        assert "38400 8N1" in msg and "factory default 9600 8N1" in msg and "[devices] baudrate" in msg
        assert srv.garbled_replies >= 1


def test_station_ascii_against_a_dl_rs1a_names_probe_protocol():
    with keyence_server() as srv, ProbeHead(srv.port, 9600, timeout=TIMEOUT) as ph:
        with pytest.raises(ProbeDialectMismatch, match=r"probe_protocol = 'keyence-dl-rs1a'"):
            ph.identify()


def test_er_22_at_start_up_is_retried_after_a_wait():
    with keyence_server() as srv, ProbeHead(srv.port, 9600, dialect="keyence-dl-rs1a", timeout=TIMEOUT,
                                            retries=2) as ph:
        srv.faults.inject(FaultKind.BUSY, 2)  # amplifiers starting up: ER,M0,22 twice
        t0 = time.monotonic()
        snap = ph.read_all()
        waited = time.monotonic() - t0
        np.testing.assert_allclose(snap.values_mm, VALUES)
        assert ph.stats.retries == 2
        assert waited >= 2 * ph.dialect.retry_wait_s


def test_over_range_and_invalid_amplifiers_are_not_measurements():
    values = VALUES.copy()
    values[1], values[4] = np.inf, np.nan
    with keyence_server(values) as srv, ProbeHead(srv.port, 9600, dialect="keyence-dl-rs1a", timeout=TIMEOUT,
                                                  valid_range_mm=2.0) as ph:
        snap = ph.read_all()
        assert snap.status[1] is ChannelStatus.OVER_RANGE and snap.status[4] is ChannelStatus.INVALID
        # within the GT2 range but outside the probe's stroke (±2 mm here): never a measurement
        assert snap.status[3] is ChannelStatus.OVER_RANGE and snap.status[5] is ChannelStatus.OK
        assert all(math.isnan(snap.values_mm[k]) for k in (1, 3, 4))


def test_m0_returns_buffered_data_until_the_unit_refreshes():
    calls = []

    def source():
        calls.append(1)
        return VALUES + 0.0001 * len(calls)

    with ProbeHeadServer(source, n_channels=6, protocol="keyence-dl-rs1a", pace=False, refresh_s=10.0) as srv:
        assert srv.unit.handle(b"M0") == srv.unit.handle(b"M0")  # one buffer between two polls
        assert len(calls) == 1


def test_dl_rs1a_at_7e1_with_the_unit_set_so():
    with keyence_server(bytesize=7, parity="even") as srv, \
            ProbeHead(srv.port, 9600, dialect="keyence-dl-rs1a", bytesize=7, parity="even", timeout=TIMEOUT) as ph:
        assert ph.identify().channels == 6


# ---------------------------------------------------------------- Mitutoyo

def test_mitutoyo_line_scans_its_indicators_and_reads_each():
    with ProbeHeadServer(lambda: VALUES, protocol="mitutoyo-ga", pace=False) as srv, \
            ProbeHead(srv.port, 9600, dialect="mitutoyo-ga", timeout=TIMEOUT) as ph:
        assert ph.identify().channels == 6
        np.testing.assert_allclose(ph.read_averaged(2, 0.001).values_mm, VALUES)
        assert srv.unit.handle(b"GA07") is None       # no such indicator: silence
        assert srv.unit.handle(b"CX02") == b"CH02\r\n"
        assert srv.unit.handle(b"GA02").startswith(b"GX02,")
        srv.unit.handle(b"CN02")


def test_mitutoyo_driver_against_a_dl_rs1a_names_probe_protocol():
    with keyence_server() as srv, ProbeHead(srv.port, 9600, dialect="mitutoyo-ga", channels=6,
                                            timeout=TIMEOUT) as ph:
        with pytest.raises(ProbeDialectMismatch, match="keyence-dl-rs1a"):
            ph.read_all()


def test_dl_rs1a_driver_against_mitutoyo_times_out_naming_probe_protocol():
    with ProbeHeadServer(lambda: VALUES, protocol="mitutoyo-ga", pace=False) as srv, \
            ProbeHead(srv.port, 9600, dialect="keyence-dl-rs1a", timeout=0.2, retries=0) as ph:
        with pytest.raises(ProbeTimeout, match="probe_protocol"):
            ph.identify()
