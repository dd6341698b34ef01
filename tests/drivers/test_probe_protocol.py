"""Probe-head protocol: formatting, parsing, and fuzzing of every parser."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers import probe_protocol as pp
from drivers.probe_protocol import ChannelStatus


@pytest.mark.parametrize(
    "value, wire",
    [
        (12.3456, b"+012.3456"),
        (-0.0021, b"-000.0021"),
        (0.0, b"+000.0000"),
        (-0.00004, b"+000.0000"),  # rounds to zero: never a negative zero on the wire
        (999.9999, b"+999.9999"),
        (-999.9999, b"-999.9999"),
        (1000.0, b"+FFFFFFF"),
        (-1000.0, b"-FFFFFFF"),
        (math.inf, b"+FFFFFFF"),
        (-math.inf, b"-FFFFFFF"),
        (math.nan, b"XXXXXXXX"),
        (0.00005001, b"+000.0001"),
    ],
)
def test_format_value(value, wire):
    assert pp.format_value(value) == wire


@pytest.mark.parametrize(
    "wire, value, status",
    [
        (b"+012.3456", 12.3456, ChannelStatus.OK),
        (b"-000.0021", -0.0021, ChannelStatus.OK),
        (b"+FFFFFFF", math.nan, ChannelStatus.OVER_RANGE),
        (b"-FFFFFFF", math.nan, ChannelStatus.UNDER_RANGE),
        (b"XXXXXXXX", math.nan, ChannelStatus.INVALID),
    ],
)
def test_parse_value(wire, value, status):
    v, s = pp.parse_value(wire)
    assert s is status
    assert (math.isnan(v) and math.isnan(value)) or v == value


@pytest.mark.parametrize("bad", [b"12.3456", b"+12.3456", b"+012.345", b"+012,3456", b" +012.3456",
                                 "+0\u06612.3456".encode(), b"+FFFFFFFF", b"",
                                 b"xxxxxxxx"])
def test_parse_value_rejects(bad):
    with pytest.raises(pp.ProbeFrameError):
        pp.parse_value(bad)


@given(st.floats(min_value=-999.9999, max_value=999.9999))
def test_value_round_trip_is_0p1_um(v):
    back, status = pp.parse_value(pp.format_value(v))
    assert status is ChannelStatus.OK
    assert abs(back - v) <= 0.00005 + 1e-12


def test_request_frames():
    assert pp.format_request("M0") == b"M0\r"
    assert pp.format_request("MS", 3) == b"MS,03\r"
    assert pp.format_request("ID") == b"ID\r"
    assert pp.format_request("ZS", 14) == b"ZS,14\r"
    assert pp.format_request("ZC", 0) == b"ZC,00\r"
    assert pp.format_request("PS", 2, -1.5) == b"PS,02,-001.5000\r"
    with pytest.raises(ValueError):
        pp.format_request("XX")
    with pytest.raises(ValueError):
        pp.format_request("MS")
    with pytest.raises(ValueError):
        pp.format_request("MS", 15)
    with pytest.raises(ValueError):
        pp.format_request("PS", 1, math.inf)


def test_parse_request_accepts_cr_and_crlf():
    assert pp.parse_request(b"M0") == pp.Request("M0", ())
    assert pp.parse_request(b"MS,07\r") == pp.Request("MS", (7,))
    assert pp.parse_request(b"PS,01,+002.5000\r\n") == pp.Request("PS", (1, 2.5))


@pytest.mark.parametrize(
    "line, cmd, code",
    [
        (b"QQ", "QQ", pp.ERR_UNKNOWN_COMMAND),
        (b"m0", "??", pp.ERR_UNKNOWN_COMMAND),
        (b"", "??", pp.ERR_UNKNOWN_COMMAND),
        (b"MS", "MS", pp.ERR_BAD_PARAMETER),
        (b"MS,1", "MS", pp.ERR_BAD_PARAMETER),
        (b"M0,01", "M0", pp.ERR_BAD_PARAMETER),
        (b"PS,01,+FFFFFFF", "PS", pp.ERR_OUT_OF_RANGE),
        (b"PS,01,1.5", "PS", pp.ERR_BAD_PARAMETER),
        (b"M0" + b"," * 70, "M0", pp.ERR_BAD_PARAMETER),  # longer than the unit's buffer
        (b"\xff" * 70, "??", pp.ERR_BAD_PARAMETER),
    ],
)
def test_parse_request_errors_carry_unit_codes(line, cmd, code):
    with pytest.raises(pp.ProbeDeviceError) as info:
        pp.parse_request(line)
    assert (info.value.command, info.value.code) == (cmd, code)
    assert pp.format_error(info.value.command, info.value.code) == b"ER,%s,%02d\r\n" % (
        cmd.encode(), code)


def test_m0_reply_round_trip():
    line = pp.format_reply("M0", 12.3456, -0.0021, math.inf, -math.inf, math.nan, 0.0)
    assert line == b"M0,+012.3456,-000.0021,+FFFFFFF,-FFFFFFF,XXXXXXXX,+000.0000\r\n"
    values, status = pp.parse_m0(line, channels=6)
    np.testing.assert_array_equal(values[[0, 1, 5]], [12.3456, -0.0021, 0.0])
    assert np.isnan(values[2:5]).all()
    assert status == (ChannelStatus.OK, ChannelStatus.OK, ChannelStatus.OVER_RANGE,
                      ChannelStatus.UNDER_RANGE, ChannelStatus.INVALID, ChannelStatus.OK)
    with pytest.raises(pp.ProbeFrameError, match="reported 5"):
        pp.parse_m0(line, channels=5)


def test_other_replies():
    assert pp.parse_ms(b"MS,03,+000.1234\r\n", 3) == (0.1234, ChannelStatus.OK)
    with pytest.raises(pp.ProbeFrameError, match="stale"):
        pp.parse_ms(b"MS,04,+000.1234\r\n", 3)
    assert pp.parse_id(b"ID,DL-SIM,2.10,06\r\n") == pp.DeviceInfo("DL-SIM", "2.10", 6)
    assert pp.parse_ack(b"ZS,02\r\n", "ZS", 2) == (2,)
    assert pp.format_reply("PS", 1, 2.5) == b"PS,01,+002.5000\r\n"


@pytest.mark.parametrize(
    "line",
    [
        b"M0,+012.3456",  # truncated: no CR LF
        b"M0,+012.3456\r",
        b"M0,+012.3456\n",
        b"M0,+012.3456\r\nM0,+012.3456\r\n",  # two frames run together
        b"MS,+012.3456\r\n",  # wrong command echoed
        b"M0\r\n",  # no channels
        b"M0," + b",".join([b"+000.0000"] * 16) + b"\r\n",  # more than 15 channels
        b"M0,+01\xb2.3456\r\n",  # garbled byte
        b"ER,M0\r\n",
        b"ER,MS,03\r\n",  # error for another command
    ],
)
def test_bad_replies_are_frame_errors(line):
    with pytest.raises(pp.ProbeFrameError):
        pp.parse_m0(line)


def test_error_reply_is_device_error_with_meaning_and_advice():
    with pytest.raises(pp.ProbeDeviceError) as info:
        pp.parse_ms(b"ER,MS,03\r\n", 9)
    err = info.value
    assert (err.command, err.code, err.retryable) == ("MS", 3, False)
    assert err.meaning == "channel not present"
    assert "cabling" in str(err)
    with pytest.raises(pp.ProbeDeviceError) as info:
        pp.parse_m0(b"ER,M0,05\r\n")
    assert info.value.retryable
    with pytest.raises(pp.ProbeDeviceError, match="unknown error code"):
        pp.parse_m0(b"ER,M0,42\r\n")


def test_table_is_consistent():
    assert set(pp.COMMANDS) == {"M0", "MS", "ID", "ZS", "ZC", "PS"}
    # only reads may be retried by a driver
    assert {n for n, s in pp.COMMANDS.items() if s.read_only} == {"M0", "MS", "ID"}
    assert all(len(m) == 8 for m in pp.MARKERS.values())
    assert [e.code for e in pp.ERROR_CODES.values()] == list(range(6))


def test_parsers_reject_non_bytes():
    with pytest.raises(pp.ProbeFrameError):
        pp.parse_m0("M0,+000.0000\r\n")  # type: ignore[arg-type]


_PARSERS = [
    pp.parse_value,
    pp.parse_request,
    lambda b: pp.parse_m0(b),
    lambda b: pp.parse_m0(b, channels=6),
    lambda b: pp.parse_ms(b, 3),
    pp.parse_id,
    lambda b: pp.parse_ack(b, "ZS", 1),
    lambda b: pp.parse_ack(b, "PS", 1),
    lambda b: pp.parse_reply(b, "ZC"),
]

# Bytes biased towards protocol-like material so the fuzz reaches deep into the parsers.
_protocolish = st.lists(
    st.sampled_from([b"M0", b"MS", b"ID", b"ZS", b"PS", b"ER", b",", b"+", b"-", b".", b"0",
                     b"9", b"05", b"+012.3456", b"+FFFFFFF", b"XXXXXXXX", b"\r", b"\n",
                     b"\r\n", b"\xff", b"\x00", b"A"]),
    max_size=40,
).map(b"".join)


@settings(max_examples=300, deadline=None)
@given(data=st.one_of(st.binary(max_size=200), _protocolish), which=st.integers(0, len(_PARSERS) - 1))
def test_fuzz_parsers_raise_only_probe_errors(data, which):
    try:
        _PARSERS[which](data)
    except pp.ProbeError:
        pass  # the only acceptable failure; anything else propagates and fails the test


def test_protocol_document_covers_the_table():
    from pathlib import Path

    doc = (Path(__file__).resolve().parents[2] / "docs" / "protocols.md").read_text()
    for name in pp.COMMANDS:
        assert f"`{name}" in doc, f"command {name} missing from the protocol document"
    for code in pp.ERROR_CODES:
        assert f"| `{code:02d}` |" in doc, f"error code {code:02d} missing"
    for marker in pp.MARKERS.values():
        assert marker.decode() in doc
    # the documented examples are valid frames for the table
    assert pp.parse_m0(
        b"M0,+000.1234,-000.0021,+001.5000,+FFFFFFF,XXXXXXXX,-000.5000\r\n", channels=6)
    assert len(pp.format_reply("M0", *[1.0] * 6)) == 64
    assert len(pp.format_reply("M0", *[1.0] * 15)) == 154
    assert len(pp.format_request("MS", 3)) + len(pp.format_reply("MS", 3, 1.0)) == 23
