"""Probe dialects against exact wire transcripts, with the frames of the vendors' own manuals.

Keyence: DL-RS1A User's Manual (GT2 Edition): p. 7 (line, delimiters), pp. 8-10 (frames; the
error example ``SR,06,101`` -> ``ER,SR,65``), p. 14 (error numbers). Mitutoyo: ID-H0530/0560
User's Manual 99MAH016B, section 4.2.4 (``GA**`` -> ``GN**,+0016.2345``).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from drivers.probe_dialects import DIALECTS, check_line_settings, get_dialect
from drivers.probe_dialects import keyence_dl_rs1a as kd
from drivers.probe_dialects import mitutoyo_ga as md
from drivers.probe_head import ProbeHead
from drivers.probe_protocol import (
    ChannelStatus,
    ErrorAction,
    ProbeConfigError,
    ProbeDeviceError,
    ProbeDialectMismatch,
    ProbeFrameError,
    ProbeLineSettingsError,
    ProbeUnsettled,
)
from tests.drivers.test_probe_driver_transcript import ScriptedPort

DOCS = Path(__file__).resolve().parents[2] / "docs" / "protocols.md"


def keyence(steps, **kw) -> tuple[ProbeHead, ScriptedPort]:
    port = ScriptedPort(steps)
    kw.setdefault("timeout", 0.1)
    head = ProbeHead.from_port(port, name="fake", dialect="keyence-dl-rs1a", **kw)
    # the transcript has no clock: no refresh wait, no start-up wait (the pty tests keep them)
    head.dialect = dataclasses.replace(DIALECTS["keyence-dl-rs1a"], refresh_s=0.0, retry_wait_s=0.0)
    return head, port


# ---------------------------------------------------------------- line settings (p. 7)

def test_dl_rs1a_line_settings_are_the_manuals():
    assert check_line_settings("keyence-dl-rs1a").describe() == "9600 8N1"  # factory default
    for baud in (2400, 4800, 9600, 19200, 38400):
        assert check_line_settings("keyence-dl-rs1a", baud).baudrate == baud
    # the manual lists 7 or 8 data bits and none/even/odd parity and forbids no combination
    assert check_line_settings("keyence-dl-rs1a", 9600, 7, "none").describe() == "9600 7N1"
    assert check_line_settings("keyence-dl-rs1a", 9600, 7, "even").describe() == "9600 7E1"


@pytest.mark.parametrize("kw, named", [
    ({"baudrate": 57600}, "baudrate 57600"),
    ({"baudrate": 115200}, "baudrate 115200"),
    ({"bytesize": 6}, "probe_bytesize 6"),
    ({"parity": "mark"}, "probe_parity 'mark'"),
    ({"stopbits": 2}, "2 stop bits"),
])
def test_dl_rs1a_refuses_what_it_does_not_offer(kw, named):
    with pytest.raises(ProbeLineSettingsError) as err:
        check_line_settings("keyence-dl-rs1a", **kw)
    msg = str(err.value)
    assert named in msg and "2400/4800/9600/19200/38400 baud" in msg and "factory default 9600 8N1" in msg
    assert "probe_bytesize" in msg and "probe_parity" in msg


def test_driver_refuses_bad_line_settings_before_opening_the_port():
    with pytest.raises(ProbeLineSettingsError, match="57600"):
        ProbeHead("/dev/does-not-exist-probe", 57600, dialect="keyence-dl-rs1a")


def test_unknown_dialect_names_the_known_ones():
    with pytest.raises(ProbeConfigError, match="probe_protocol.*'station-ascii', 'keyence-dl-rs1a', 'mitutoyo-ga'"):
        get_dialect("keyence")


def test_station_ascii_defaults_are_unchanged():
    assert check_line_settings("station-ascii").describe() == "38400 8N1"


# ---------------------------------------------------------------- DL-RS1A frames (pp. 8-10, 14)

def test_m0_is_the_channel_count_and_identify_is_synthesised():
    head, port = keyence([(b"M0\r\n", b"M0,+000.1234,-000.0021,+001.5000\r\n")])
    info = head.identify()
    assert (info.model, info.firmware, info.channels) == ("DL-RS1A", "n/a", 3)
    assert head.channels == 3
    port.assert_done()


def test_read_all_needs_two_agreeing_m0_replies():
    head, port = keyence([
        (b"M0\r\n", b"M0,+000.1234,-000.0021\r\n"),
        (b"M0\r\n", b"M0,+000.1300,-000.0021\r\n"),   # still moving: 6.6 µm apart
        (b"M0\r\n", b"M0,+000.1302,-000.0022\r\n"),   # agrees with the previous one within 5 µm
    ])
    snap = head.read_all()
    np.testing.assert_allclose(snap.values_mm, [0.1302, -0.0022])
    assert head.stats.unsettled == 1
    assert snap.raw == b"M0,+000.1300,-000.0021\r\nM0,+000.1302,-000.0022\r\n"
    port.assert_done()


def test_read_all_gives_up_when_the_data_never_settles():
    frames = [(b"M0\r\n", b"M0,+000.%04d\r\n" % (100 * k)) for k in range(4)]
    head, port = keyence(frames, settle_attempts=3)
    with pytest.raises(ProbeUnsettled, match="channel 00: 3 pairs"):
        head.read_all()
    port.assert_done()


def test_ms_frame_of_the_manual_decodes_outputs_and_values():
    assert kd.parse_ms(b"MS,0,+000.1234,4,-001.0000\r\n") == [(0, 0.1234, ChannelStatus.OK),
                                                           (4, -1.0, ChannelStatus.OK)]
    with pytest.raises(ProbeFrameError):
        kd.parse_ms(b"MS,0,+000.1234,4\r\n")


def test_sr_example_of_the_manual_and_its_id_error():
    # p. 8: "SR,06,101" CR LF answered "ER,SR,65" CR LF (ID No. error)
    with pytest.raises(ProbeDeviceError) as err:
        kd.parse_sr(b"ER,SR,65\r\n", 6, 101)
    assert err.value.code == 65 and err.value.action is ErrorAction.CONFIG_ERROR
    assert "ID number error" in str(err.value)
    assert kd.parse_sr(b"SR,06,101,+000.5000\r\n", 6, 101) == b"+000.5000"


@pytest.mark.parametrize("code, action", [
    (0, ErrorAction.DRIVER_ERROR), (2, ErrorAction.RETRY_AFTER_WAIT), (20, ErrorAction.CONFIG_ERROR),
    (21, ErrorAction.DRIVER_ERROR), (22, ErrorAction.RETRY_AFTER_WAIT), (29, ErrorAction.CONFIG_ERROR),
    (65, ErrorAction.CONFIG_ERROR), (66, ErrorAction.DEVICE_FAULT), (67, ErrorAction.CONFIG_ERROR),
])
def test_every_error_number_of_the_manual_has_a_meaning_and_an_action(code, action):
    assert kd.ERRORS[code].effective_action is action
    with pytest.raises(ProbeDeviceError) as err:
        kd.parse_m0(b"ER,M0,%02d\r\n" % code)
    assert err.value.code == code and err.value.meaning == kd.ERRORS[code].meaning


def test_er_22_during_start_up_is_sent_again_after_a_wait():
    head, port = keyence([
        (b"M0\r\n", b"ER,M0,22\r\n"),
        (b"M0\r\n", b"M0,+000.1000\r\n"),
        (b"M0\r\n", b"M0,+000.1001\r\n"),
    ], retries=2)
    assert head.read_all().values_mm[0] == pytest.approx(0.1001)
    assert head.stats.retries == 1
    port.assert_done()


def test_an_unknown_error_code_is_not_retried():
    head, port = keyence([(b"M0\r\n", b"ER,M0,42\r\n")], retries=2)
    with pytest.raises(ProbeDeviceError, match="unknown error code") as err:
        head.read_all()
    assert err.value.code == 42 and not err.value.retryable
    port.assert_done()


@pytest.mark.parametrize("field, status", [
    (b"+000.1234", ChannelStatus.OK), (b"-199.9999", ChannelStatus.OK),
    (b"+999.9999", ChannelStatus.OVER_RANGE), (b"-999.9998", ChannelStatus.UNDER_RANGE),
    (b"+200.0000", ChannelStatus.OVER_RANGE), (b"+EEE.EEEE", ChannelStatus.INVALID),
    (b"-----", ChannelStatus.INVALID),
])
def test_values_beyond_the_gt2_range_and_special_values_are_not_measurements(field, status):
    value, st = kd.parse_value(field)
    assert st is status
    assert math.isnan(value) == (status is not ChannelStatus.OK)


@pytest.mark.parametrize("field", [b"+0.1234", b"+000.12345", b"+FFFFFFF", b"0001.0000", b"+00\xb0.1234"])
def test_malformed_values_are_garbled_frames(field):
    with pytest.raises(ProbeFrameError):
        kd.parse_value(field)


def test_a_reading_outside_the_probe_stroke_is_never_a_measurement():
    head, port = keyence([(b"M0\r\n", b"M0,+004.9000,+005.2000\r\n")] * 2, valid_range_mm=5.0)
    snap = head.read_all()
    assert snap.status == (ChannelStatus.OK, ChannelStatus.OVER_RANGE)
    assert math.isnan(snap.values_mm[1])
    port.assert_done()


def test_resync_after_a_timeout_is_m0_not_id():
    head, port = keyence([
        (b"M0\r\n", b""),                                 # lost
        (b"M0\r\n", b"M0,+000.1000\r\n"),                 # the fence, answered
        (b"M0\r\n", b"M0,+000.1000\r\n"),
        (b"M0\r\n", b"M0,+000.1000\r\n"),
    ], retries=1)
    head.read_all()
    assert head.stats.resyncs == 1 and head.stats.timeouts == 1
    assert all(entry[1] != b"ID\r" for entry in port.log if entry[0] == "write")
    port.assert_done()


def test_zero_and_preset_are_refused_outside_station_ascii():
    head, _ = keyence([])
    with pytest.raises(ProbeConfigError, match="absolute values"):
        head.zero(0)


def test_station_ascii_driver_names_the_dl_rs1a_when_it_answers_er_id_00():
    port = ScriptedPort([(b"ID\r", b"ER,ID,00\r\n")])
    head = ProbeHead.from_port(port, timeout=0.1, name="fake")
    with pytest.raises(ProbeDialectMismatch) as err:
        head.identify()
    msg = str(err.value)
    assert "does not speak 'station-ascii'" in msg and "probe_protocol = 'keyence-dl-rs1a'" in msg


# ---------------------------------------------------------------- Mitutoyo frames (4.2.4)

def test_mitutoyo_manual_example_frames():
    assert md.request("GA", 1) == b"GA01\r\n"
    assert md.parse_ga(b"GN01,+0016.2345\r\n", 1) == [(16.2345, ChannelStatus.OK)]
    assert md.parse_ga(b"GN07,-0016.2345\r\n", 7) == [(-16.2345, ChannelStatus.OK)]
    assert md.format_value(16.2345) == b"+0016.2345"


def test_mitutoyo_other_modes_are_refused_as_not_a_position():
    with pytest.raises(ProbeDeviceError, match="indicator 01 is in max mode.*CN01"):
        md.parse_ga(b"GX01,+0016.2345\r\n", 1)


def test_mitutoyo_snapshot_is_one_request_per_indicator():
    port = ScriptedPort([(b"GA01\r\n", b"GN01,+0001.0000\r\n"), (b"GA02\r\n", b"GN02,-0000.5000\r\n")])
    head = ProbeHead.from_port(port, timeout=0.1, name="fake", dialect="mitutoyo-ga", channels=2)
    np.testing.assert_allclose(head.read_all().values_mm, [1.0, -0.5])
    port.assert_done()


def test_mitutoyo_driver_names_the_keyence_unit_answering_er():
    port = ScriptedPort([(b"GA01\r\n", b"ER,GA,00\r\n")])
    head = ProbeHead.from_port(port, timeout=0.1, name="fake", dialect="mitutoyo-ga", channels=1)
    with pytest.raises(ProbeDialectMismatch, match="'keyence-dl-rs1a'"):
        head.read_all()


# ---------------------------------------------------------------- docs are true to the tables

def test_docs_describe_every_dialect_command_and_error():
    text = DOCS.read_text(encoding="utf-8")
    for d in DIALECTS.values():
        assert f"### {d.name}" in text, d.name
        for name in d.commands:
            assert f"`{name}" in text, (d.name, name)
    for code in kd.ERRORS:
        assert f"| `{code:02d}` |" in text, code
