"""Probe-head driver against exact wire transcripts (pymeasure ``expected_protocol`` style).

The fake port asserts every byte the driver writes, in order, and answers with scripted bytes;
an empty answer plays a timeout (``read_until`` then returns what it has, as pyserial does).
"""

from __future__ import annotations

import numpy as np
import pytest
import serial

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


class ScriptedPort:
    """Serial-like fake: ``steps`` is a list of ``(expected_write, reply)`` pairs."""

    def __init__(self, steps: list[tuple[bytes, bytes]], stale: bytes = b"") -> None:
        self.steps = list(steps)
        self.buffer = bytearray(stale)
        self.log: list[tuple[str, bytes]] = []
        self.closed = False

    def reset_input_buffer(self) -> None:
        self.log.append(("flush", bytes(self.buffer)))
        self.buffer.clear()

    def write(self, data: bytes) -> int:
        assert self.steps, f"driver wrote {data!r} after the transcript ended"
        expected, reply = self.steps.pop(0)
        assert data == expected, f"driver wrote {data!r}, transcript expects {expected!r}"
        self.log.append(("write", data))
        self.buffer += reply
        return len(data)

    def read_until(self, expected: bytes = b"\n", size: int | None = None) -> bytes:
        idx = self.buffer.find(expected)
        end = len(self.buffer) if idx < 0 else idx + len(expected)
        if size is not None:
            end = min(end, size)
        out = bytes(self.buffer[:end])
        del self.buffer[:end]
        self.log.append(("read", out))
        return out

    def close(self) -> None:
        self.closed = True

    def assert_done(self) -> None:
        assert not self.steps, f"transcript not finished: {self.steps}"


def head(steps, stale=b"", retries=2):
    port = ScriptedPort(steps, stale)
    return ProbeHead.from_port(port, timeout=0.1, retries=retries, name="fake"), port


M0_OK = b"M0,+000.1000,-000.2000,+000.0000,+001.5000,-002.2500,+000.0001\r\n"
ID_REPLY = b"ID,DL-SIM,2.10,06\r\n"


def test_identify_exact_bytes_and_channel_count():
    ph, port = head([(b"ID\r", b"ID,DL-SIM,2.10,06\r\n")])
    info = ph.identify()
    assert (info.model, info.firmware, info.channels) == ("DL-SIM", "2.10", 6)
    assert ph.channels == 6
    port.assert_done()


def test_read_all_flushes_stale_input_first():
    stale = b"M0,+111.1111,+111.1111,+111.1111,+111.1111,+111.1111,+111.1111\r\nM0,+2"
    ph, port = head([(b"M0\r", M0_OK)], stale=stale)
    snap = ph.read_all()
    np.testing.assert_array_equal(snap.values_mm, [0.1, -0.2, 0.0, 1.5, -2.25, 0.0001])
    assert snap.all_ok and snap.raw == M0_OK
    assert port.log == [("flush", stale), ("write", b"M0\r"), ("read", M0_OK)]
    assert not snap.values_mm.flags.writeable


def test_markers_become_status_and_nan():
    line = b"M0,+000.1000,+FFFFFFF,-FFFFFFF,XXXXXXXX,+000.0000,+000.0000\r\n"
    ph, _ = head([(b"M0\r", line)])
    snap = ph.read_all()
    assert snap.status[:4] == (ChannelStatus.OK, ChannelStatus.OVER_RANGE,
                               ChannelStatus.UNDER_RANGE, ChannelStatus.INVALID)
    assert np.isnan(snap.values_mm[1:4]).all() and snap.values_mm[0] == 0.1
    with pytest.raises(ProbeOutOfRange) as info:
        snap.require_ok()
    assert set(info.value.statuses) == {1, 2, 3}


@pytest.mark.parametrize(
    "bad_reply",
    [b"", b"M0,+000.10", b"M0,+000.1\xb000,-000.2000,+000.0000,+001.5000,-002.2500,+000.0001\r\n",
     b"ER,M0,05\r\n"],
    ids=["timeout", "truncated", "garbled", "busy"],
)
def test_reads_are_retried_after_transient_faults(bad_reply):
    timed_out = not bad_reply.endswith(b"\r\n")
    # after a timeout the line is out of step: the retry is preceded by the ID fence
    fence = [(b"ID\r", ID_REPLY)] if timed_out else []
    ph, port = head([(b"M0\r", bad_reply), *fence, (b"M0\r", M0_OK)])
    assert ph.read_all().values_mm[0] == 0.1
    port.assert_done()
    # each attempt starts with a flush: the partial line of the first one is discarded
    kinds = ["flush", "write", "read"] * (3 if timed_out else 2)
    assert [k for k, _ in port.log] == kinds
    assert ph.stats.retries == 1 and ph.stats.timeouts == int(timed_out)
    assert ph.stats.resyncs == int(timed_out)


def test_reads_give_up_after_bounded_retries():
    # the first attempt times out; the next two are fences that get no answer: the M0 is
    # never sent into a line that is out of step
    ph, port = head([(b"M0\r", b""), (b"ID\r", b""), (b"ID\r", b"")], retries=2)
    with pytest.raises(ProbeTimeout, match="gave up after 3 attempts"):
        ph.read_all()
    port.assert_done()  # exactly three requests, no fourth


def test_partial_reply_is_a_timeout_naming_the_data():
    ph, _ = head([(b"MS,02\r", b"MS,02,+00")], retries=0)
    with pytest.raises(ProbeTimeout, match="incomplete reply"):
        ph.read_channel(2)


@pytest.mark.parametrize(
    "call, frame",
    [
        (lambda ph: ph.zero(1), b"ZS,01\r"),
        (lambda ph: ph.clear_zero(1), b"ZC,01\r"),
        (lambda ph: ph.preset(1, 2.5), b"PS,01,+002.5000\r"),
    ],
    ids=["zero", "clear", "preset"],
)
def test_state_changing_commands_are_never_retried(call, frame):
    ph, port = head([(frame, b"")], retries=2)
    with pytest.raises(ProbeTimeout, match="was not repeated"):
        call(ph)
    port.assert_done()  # the ScriptedPort would fail on a second write


def test_busy_on_zero_is_not_retried_either():
    ph, port = head([(b"ZS,00\r", b"ER,ZS,05\r\n")])
    with pytest.raises(ProbeDeviceError) as info:
        ph.zero(0)
    assert info.value.code == 5
    port.assert_done()


def test_zero_preset_clear_transcript():
    ph, port = head([
        (b"ZS,03\r", b"ZS,03\r\n"),
        (b"PS,04,-001.2500\r", b"PS,04,-001.2500\r\n"),
        (b"ZC,03\r", b"ZC,03\r\n"),
    ])
    ph.zero(3)
    ph.preset(4, -1.25)
    ph.clear_zero(3)
    port.assert_done()


def test_error_reply_is_not_retried_and_carries_code():
    ph, port = head([(b"MS,09\r", b"ER,MS,03\r\n")])
    with pytest.raises(ProbeDeviceError) as info:
        ph.read_channel(9)
    assert (info.value.code, info.value.meaning) == (3, "channel not present")
    port.assert_done()


def test_zero_refused_when_not_measuring():
    ph, _ = head([(b"ZS,00\r", b"ER,ZS,04\r\n")])
    with pytest.raises(ProbeDeviceError, match="bring the probe into its range"):
        ph.zero(0)


def test_ack_for_wrong_channel_is_a_frame_error():
    ph, _ = head([(b"ZS,01\r", b"ZS,02\r\n")])
    with pytest.raises(ProbeFrameError):
        ph.zero(1)


def test_channel_count_from_id_is_enforced():
    short = b"M0,+000.1000,+000.1000\r\n"
    ph, port = head([(b"ID\r", b"ID,DL-SIM,2.10,06\r\n")] + [(b"M0\r", short)] * 3)
    ph.identify()
    with pytest.raises(ProbeFrameError, match="reported 6"):
        ph.read_all()
    port.assert_done()
    with pytest.raises(ValueError):
        ph.read_channel(6)  # checked locally: never sent


def _m0(*vals: bytes) -> bytes:
    return b"M0," + b",".join(vals) + b"\r\n"


def test_read_averaged_mean_status_and_raw():
    frames = [
        _m0(b"+001.0000", b"+002.0000", b"+000.5000"),
        _m0(b"+001.0002", b"+FFFFFFF", b"+000.5000"),
        _m0(b"+001.0004", b"+002.0000", b"XXXXXXXX"),
    ]
    ph, port = head([(b"M0\r", f) for f in frames])
    snap = ph.read_averaged(3, max_spread_mm=0.001)
    assert snap.values_mm[0] == pytest.approx(1.0002, abs=1e-12)
    assert np.isnan(snap.values_mm[1:]).all()
    assert snap.status == (ChannelStatus.OK, ChannelStatus.OVER_RANGE, ChannelStatus.INVALID)
    assert snap.raw == b"".join(frames)
    port.assert_done()


def test_read_averaged_spread_bound():
    frames = [_m0(b"+001.0000", b"+002.0000"), _m0(b"+001.0000", b"+002.0030")]
    ph, _ = head([(b"M0\r", f) for f in frames])
    with pytest.raises(ProbeSpreadError) as info:
        ph.read_averaged(2, max_spread_mm=0.002)
    assert info.value.channel == 1
    assert info.value.spread_mm == pytest.approx(0.003)


class BrokenPort(ScriptedPort):
    def write(self, data: bytes) -> int:
        raise serial.SerialException("write failed: [Errno 5] Input/output error")


def test_serial_exception_becomes_disconnected():
    ph = ProbeHead.from_port(BrokenPort([]), name="fake")
    with pytest.raises(ProbeDisconnected, match="reconnect") as info:
        ph.read_all()
    assert isinstance(info.value.__cause__, serial.SerialException)


def test_context_manager_closes_port():
    port = ScriptedPort([])
    with ProbeHead.from_port(port):
        pass
    assert port.closed


def test_open_failure_is_disconnected():
    with pytest.raises(ProbeDisconnected, match="device path"):
        ProbeHead("/dev/does-not-exist-probe")


# ---------------------------------------------------------------- sequence rule (docs/protocols.md)

LATE_M0 = b"M0,+111.1111,+111.1111,+111.1111,+111.1111,+111.1111,+111.1111\r\n"


def test_after_a_timeout_the_next_request_is_fenced_and_the_late_reply_discarded():
    ph, port = head([
        (b"M0\r", b""),                      # times out: the reply is late
        (b"ID\r", LATE_M0 + ID_REPLY),       # the fence: the late reply arrives before its answer
        (b"M0\r", M0_OK),
    ], retries=0)
    with pytest.raises(ProbeTimeout, match="no reply"):
        ph.read_all()
    snap = ph.read_all()
    assert snap.values_mm[0] == 0.1 and snap.raw == M0_OK  # never the late 111.1111
    port.assert_done()
    assert port.log == [
        ("flush", b""), ("write", b"M0\r"), ("read", b""),
        ("flush", b""), ("write", b"ID\r"), ("read", LATE_M0), ("read", ID_REPLY),
        ("flush", b""), ("write", b"M0\r"), ("read", M0_OK),
    ]
    assert (ph.stats.timeouts, ph.stats.resyncs, ph.stats.discarded_frames) == (1, 1, 1)


def test_an_unanswered_fence_keeps_the_request_unsent():
    ph, port = head([(b"M0\r", b""), (b"ID\r", b""), (b"ID\r", ID_REPLY), (b"M0\r", M0_OK)],
                    retries=0)
    with pytest.raises(ProbeTimeout):
        ph.read_all()
    with pytest.raises(ProbeTimeout, match="resynchronisation request ID"):
        ph.read_all()  # the M0 is not written into a line that is out of step
    assert ph.read_all().raw == M0_OK  # the next call fences again, then asks
    port.assert_done()


@pytest.mark.parametrize("foreign", [
    b"ID,DL-SIM,2.10,06\r\n",        # a reply to another command
    b"MS,03,+000.5000\r\n",
    b"ER,ZS,04\r\n",                  # an error reply for another command
    b"\x00\x7fLINE NOISE\r\n",        # junk that happens to end in CR LF
])
def test_a_frame_that_does_not_name_the_request_is_discarded(foreign):
    ph, port = head([(b"M0\r", foreign + M0_OK)], retries=0)
    snap = ph.read_all()
    assert snap.raw == M0_OK
    assert port.log[-2:] == [("read", foreign), ("read", M0_OK)]
    assert ph.stats.discarded_frames == 1 and ph.stats.retries == 0


def test_endless_foreign_frames_end_in_a_timeout_not_a_hang():
    ph, port = head([(b"M0\r", b"ID,X,1,06\r\n" * 40)], retries=0)
    with pytest.raises(ProbeTimeout):
        ph.read_all()
    assert ph.stats.discarded_frames == 16  # bounded


def test_error_reply_for_an_unreadable_request_names_it():
    ph, _ = head([(b"MS,02\r", b"ER,??,01\r\n")], retries=0)
    with pytest.raises(ProbeFrameError):
        ph.read_channel(2)  # taken as this request's answer (not silently skipped), and refused
