"""Issue 12 on the Modbus link: the reply's function code is checked (exact wire transcript),
the map version and the word order are checked on connect, and the simulated controller
enforces the motion safety invariants for any client (raw pymodbus, property-based). Map 2:
targets travel as scaled 32-bit integers, so no client can send a NaN; the ends of the integer
range are what a broken client can send."""

from __future__ import annotations

import math
import socket
import struct
import threading
import time

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pymodbus.client import ModbusTcpClient

from drivers.controller import ModbusController
from drivers.controller_errors import (
    ClaimIdentity,
    MapVersionError,
    ModbusExceptionError,
    ModbusResponseError,
    MotionRejected,
    WordOrderError,
)
from drivers.controller_map import (
    REG,
    WINDOW_SIZE,
    Command,
    ErrorCode,
    RegisterDecodeError,
    StatusBit,
    WordOrder,
    encode,
    encode_i32_array,
    implausible_limits,
    register_span,
)
from simulators.controller_claim import ClaimRules
from simulators.controller_server import SimulatedController
from simulators.controller_tables import TableSlots, serve_transfer

# --------------------------------------------------------------------------------------------
# function code: a scripted server on a real socket, exact bytes both ways
# --------------------------------------------------------------------------------------------

LIMITS = [-2.0, 2.0, -2.5, 2.5, -200.0, 0.0, -6.0, 6.0]


def _read_reply(payload: bytes) -> bytes:
    return bytes([3, len(payload)]) + payload


class _Program:
    """The robot program behind the scripted server: a window image at base 0 that answers
    reads and writes by the request PDU (transfers as the simulator's program does)."""

    def __init__(self):
        self.regs = [0] * WINDOW_SIZE
        for name, value in (("map_version", 3), ("n_joints", 4), ("order_check", 1)):
            r = REG[name]
            self.regs[r.address:r.end] = encode(r, value)
        self.tables = TableSlots()

    def info(self, number):
        from drivers.controller_map import INFO_PAGES
        return encode(INFO_PAGES["soft_limits"][1], LIMITS + [0.0] * 4) if number == 0 else None

    def __call__(self, pdu: bytes) -> bytes:
        fc, address, count = pdu[0], *struct.unpack(">HH", pdu[1:5])
        if fc == 3:
            return _read_reply(b"".join(struct.pack(">H", w) for w in self.regs[address:address + count]))
        values = list(struct.unpack(f">{count}H", pdu[6:6 + 2 * count]))
        self.regs[address:address + count] = values
        if address == REG["xfer_seq"].address:
            serve_transfer(self.regs, self.tables, WordOrder.BIG, self.info)
        if address == REG["claim_request"].address:
            ClaimRules(WordOrder.BIG).serve(self.regs, heartbeat_live=True)
        return pdu[:5]


class ScriptedServer:
    """One TCP client; answers the n-th request with ``script[n](request_pdu)`` (a PDU)."""

    def __init__(self, script):
        self.script = list(script)
        self.requests: list[bytes] = []
        self.sock = socket.create_server(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _recv(self, conn, n):
        buf = b""
        while len(buf) < n:
            chunk = conn.recv(n - len(buf))
            if not chunk:
                return b""
            buf += chunk
        return buf

    def _serve(self):
        conn, _ = self.sock.accept()
        with conn:
            for answer in self.script:
                head = self._recv(conn, 7)
                if not head:
                    return
                (length,) = struct.unpack(">H", head[4:6])
                adu = head + self._recv(conn, length - 1)
                self.requests.append(adu)
                pdu = answer(adu[7:])
                conn.sendall(head[:4] + struct.pack(">H", len(pdu) + 1) + head[6:7] + pdu)

    def close(self):
        self.sock.close()


CONNECT_REQUESTS = [  # MBAP (tid, protocol 0, length, unit 1) + PDU
    bytes.fromhex("0001 0000 0006 01 03 0000 0040"),      # offsets 0..63: identification
    bytes.fromhex("0002 0000 0006 01 03 0040 0040"),      # 64..127: the whole window is there
    bytes.fromhex("0003 0000 0009 01 10 0000 0001 02 0001"),  # hb_pc: the claim needs a live heartbeat
    bytes.fromhex("0004 0000 0006 01 03 0001 0001"),      # hb_robot
    bytes.fromhex("0005 0000 000b 01 10 001a 0002 04 5ec0 de01"),  # claim_request: the session token
    bytes.fromhex("0006 0000 0006 01 03 001c 0002"),      # claim_owner: granted
    bytes.fromhex("0007 0000 0013 01 10 001e 0006 0c 0a00 0007 0000 1267 6b0f d62a"),  # host, PID, since
    bytes.fromhex("0008 0000 0006 01 03 002b 0001"),      # xfer_ack
    bytes.fromhex("0009 0000 000d 01 10 003f 0003 06 0001 0005 0000"),  # READ_INFO page 0
    bytes.fromhex("000a 0000 0006 01 03 002b 0054"),      # answer + soft limits in one read
    bytes.fromhex("000b 0000 0006 01 03 0009 0001"),      # cmd_seq
]
#: the session the scripted connects claim with (fixed: the bytes above carry it)
SESSION = {"claim_token": 0x5EC0DE01, "claim_identity": ClaimIdentity("10.0.0.7", 4711, 1796199978.0)}


def _connect_script():
    program = _Program()
    return [program] * len(CONNECT_REQUESTS)


@pytest.mark.parametrize("reply, error, got", [
    (bytes.fromhex("04 0e") + bytes(14), ModbusResponseError, 4),   # FC 4 (input registers)
    (bytes.fromhex("10 0028 0007"), ModbusResponseError, 16),        # a write's response
    (bytes.fromhex("84 02"), ModbusResponseError, 0x84),             # exception for FC 4
    (bytes.fromhex("83 02"), ModbusExceptionError, None),            # the right exception
])
def test_a_reply_with_another_function_code_is_refused(reply, error, got):
    srv = ScriptedServer(_connect_script() + [lambda req: reply])
    c = ModbusController("127.0.0.1", srv.port, heartbeat_period=None, timeout=2.0, **SESSION)
    try:
        c.connect()
        with pytest.raises(error) as info:
            c.status()
    finally:
        c.close()
        srv.close()
    status_first, status_count = register_span("ack_seq", "error_bound")
    assert srv.requests == CONNECT_REQUESTS + [
        bytes.fromhex("000c 0000 0006 01 03") + struct.pack(">HH", status_first, status_count)]
    if got is not None:
        assert (info.value.expected_fc, info.value.got_fc) == (3, got)
        assert "was not used" in str(info.value)
    else:
        assert info.value.code == 2


def test_a_write_answered_with_a_read_response_is_refused():
    srv = ScriptedServer(_connect_script() + [lambda req: _read_reply(b"\x00\x01")])
    c = ModbusController("127.0.0.1", srv.port, heartbeat_period=None, timeout=2.0, **SESSION)
    try:
        c.connect()
        with pytest.raises(ModbusResponseError) as info:
            c._write(REG["hb_pc"].address, [7])
    finally:
        c.close()
        srv.close()
    assert srv.requests[-1] == bytes.fromhex("000c 0000 0009 01 10 0000 0001 02 0007")
    assert (info.value.expected_fc, info.value.got_fc) == (16, 3)


# --------------------------------------------------------------------------------------------
# map version and word order on connect
# --------------------------------------------------------------------------------------------


def test_unknown_map_version_is_refused_naming_both_versions():
    with SimulatedController(map_version=1) as sim:
        c = ModbusController("127.0.0.1", sim.port, heartbeat_period=None)
        with pytest.raises(MapVersionError) as info:
            c.connect()
        c.close()
        assert sim.command_writes == []
    assert (info.value.found, info.value.supported) == (1, (3,))
    assert "version 1" in str(info.value) and "version 3" in str(info.value)


@pytest.mark.parametrize("sim_order, drv_order", [(WordOrder.LITTLE, WordOrder.BIG),
                                                  (WordOrder.BIG, WordOrder.LITTLE)])
def test_wrong_word_order_is_a_word_order_error_not_a_soft_limit(sim_order, drv_order):
    with SimulatedController(word_order=sim_order) as sim:
        c = ModbusController("127.0.0.1", sim.port, word_order=drv_order, heartbeat_period=None)
        with pytest.raises(WordOrderError) as info:
            c.connect()
        c.close()
        assert sim.command_writes == []  # nothing was commanded
    assert info.value.detected is sim_order and info.value.configured is drv_order
    assert f'word_order = "{sim_order.value}"' in str(info.value)


def test_right_word_order_connects():
    with SimulatedController(word_order=WordOrder.LITTLE) as sim:
        c = ModbusController("127.0.0.1", sim.port, word_order=WordOrder.LITTLE,
                             heartbeat_period=None)
        c.connect()
        np.testing.assert_allclose(c.soft_limits(), sim.soft_limits, rtol=1e-6)
        c.close()


def test_implausible_limits():
    assert implausible_limits(LIMITS, 4) is None
    assert "lower_1" in implausible_limits([math.nan] + LIMITS[1:], 4)
    assert "not below" in implausible_limits([2.0, -2.0] + LIMITS[2:], 4)
    assert "not below" in implausible_limits([1.0, 1.0] + LIMITS[2:], 4)
    assert implausible_limits([2.3e-41, 1.0] + LIMITS[2:], 4) is not None  # a swapped 1.0
    assert implausible_limits([-1e9, 1.0] + LIMITS[2:], 4) is not None
    assert implausible_limits(LIMITS[:6], 4) is not None


def test_limits_implausible_in_either_order_are_a_decode_error():
    with SimulatedController() as sim:
        sim.soft_limits = np.array([[1.0, -1.0]] * 4)  # a broken program: lower above upper
        c = ModbusController("127.0.0.1", sim.port, heartbeat_period=None)
        with pytest.raises(RegisterDecodeError, match="either word order"):
            c.connect()
        c.close()
        assert sim.command_writes == []


# --------------------------------------------------------------------------------------------
# safety invariants in the simulated controller (any client) and in the driver
# --------------------------------------------------------------------------------------------

_CMD_FIRST, _ = register_span("cmd_code", "cmd_token")
_ST_FIRST, _ST_COUNT = register_span("ack_seq", "error_bound")


def _i32_words(values) -> list[int]:
    """Scaled i32 words; values beyond the range are clipped to its ends (what a broken client
    can at worst send)."""
    v = np.clip(np.asarray(values, dtype=float), -2147.483648, 2147.483647)
    return encode_i32_array(v, 1e-6)


class RawClient:
    """A bare pymodbus client that writes command blocks the driver would never send."""

    TOKEN = [0x1234, 0x5678]  # its session token, as two words

    def __init__(self, port: int):
        self.client = ModbusTcpClient("127.0.0.1", port=port, timeout=2.0, retries=0)
        assert self.client.connect()
        self.seq = self.read(REG["cmd_seq"].address, 1)[0]
        # it holds the controller (map 3): a heartbeat, then its token in claim_request
        assert not self.client.write_registers(REG["hb_pc"].address, [1], device_id=1).isError()
        assert not self.client.write_registers(REG["claim_request"].address, self.TOKEN, device_id=1).isError()
        assert self.read(REG["claim_owner"].address, 2) == self.TOKEN

    def read(self, address, count):
        rr = self.client.read_holding_registers(address, count=count, device_id=1)
        assert not rr.isError()
        return list(rr.registers)

    def command(self, code: Command, joints=(0.0,) * 6, pose=(0.0,) * 6, elbow=1, speed=500):
        self.seq = self.seq % 0xFFFF + 1
        block = [int(code), self.seq, elbow & 0xFFFF, speed]
        target = pose if code == Command.MOVE_CARTESIAN else list(joints) + [0.0] * (6 - len(joints))
        block += _i32_words(target) + self.TOKEN
        assert not self.client.write_registers(_CMD_FIRST, block, device_id=1).isError()
        deadline = time.monotonic() + 5.0
        while True:  # resolved: done_seq or error_seq is this command's number
            ack, done, err, code_, bits, joint, bound = self.read(_ST_FIRST, _ST_COUNT)
            if ack == self.seq and self.seq in (done, err):
                as_i16 = lambda w: w - 0x10000 if w & 0x8000 else w  # noqa: E731
                return (done == self.seq), code_, StatusBit(bits), as_i16(joint), as_i16(bound)
            assert time.monotonic() < deadline, "command never resolved (stuck)"
            time.sleep(0.002)

    def close(self):
        self.client.close()


@pytest.fixture(scope="module")
def raw():
    sim = SimulatedController(time_scale=0.0, watchdog=60.0).start()
    client = RawClient(sim.port)
    yield sim, client
    client.close()
    sim.stop()


HOME = [0.0, 0.0, -100.0, 0.0]


@pytest.mark.parametrize("bad", [2147.483647, -2147.483648])
@pytest.mark.parametrize("joint", [0, 2])
def test_extreme_joint_target_is_refused_and_never_stuck(raw, bad, joint):
    sim, client = raw
    target = list(HOME)
    target[joint] = bad
    ok, code, bits, err_joint, bound = client.command(Command.MOVE_JOINTS, joints=target)
    assert not ok and code == ErrorCode.SOFT_LIMIT and err_joint == joint + 1 and bound == (1 if bad > 0 else -1)
    assert not bits & StatusBit.MOVING and bits & StatusBit.READY
    assert np.all(np.isfinite(sim.joints))
    ok, *_ = client.command(Command.MOVE_JOINTS, joints=HOME)  # and it still moves
    assert ok


@pytest.mark.parametrize("bad", [2147.483647, -2147.483648])
@pytest.mark.parametrize("axis", [0, 2])  # (a yaw of 2147 rad is reachable: it wraps)
def test_extreme_cartesian_target_is_refused(raw, bad, axis):
    _, client = raw
    pose = [550.0, 150.0, 320.0, 0.0, 0.0, 0.3]
    pose[axis] = bad
    ok, code, bits, _, _ = client.command(Command.MOVE_CARTESIAN, pose=pose)
    assert not ok and code in (ErrorCode.UNREACHABLE, ErrorCode.SOFT_LIMIT)
    assert not bits & StatusBit.MOVING


_LIM = SimulatedController().soft_limits  # the sr800's, as the simulator publishes them


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.one_of(st.floats(-1e4, 1e4), st.floats(-3.0, 3.0), st.floats(-400.0, 50.0)),
                min_size=4, max_size=4))
def test_property_a_joint_move_is_done_only_inside_the_limits(raw, q):
    sim, client = raw
    ok, code, bits, err_joint, bound = client.command(Command.MOVE_JOINTS, joints=q)
    assert not bits & StatusBit.MOVING  # resolved, never left moving
    q = np.clip(np.rint(np.asarray(q, dtype=float) / 1e-6) * 1e-6, -2147.483648, 2147.483647)  # as on the wire
    inside = (q >= _LIM[:, 0]) & (q <= _LIM[:, 1])
    if inside.all():
        assert ok, f"refused a valid target {q} (code {code})"
        np.testing.assert_allclose(sim.joints, q, atol=1e-5)
        return
    assert not ok
    j = int(np.argmin(inside))  # the first joint that fails
    assert code == ErrorCode.SOFT_LIMIT and err_joint == j + 1
    assert bound == (-1 if q[j] < _LIM[j, 0] else 1)
    assert np.all(np.isfinite(sim.joints))


def test_simulator_refuses_non_finite_or_unordered_soft_limits():
    for bad in ([[math.nan, 1.0]] * 4, [[1.0, -1.0]] * 4, [[-1.0, math.inf]] * 4):
        with pytest.raises(ValueError, match="soft limits"):
            SimulatedController(soft_limits=np.array(bad))


def test_driver_refuses_non_finite_targets_before_writing_anything():
    with SimulatedController() as sim:
        c = ModbusController("127.0.0.1", sim.port, heartbeat_period=None)
        c.connect()
        writes = sim.requests
        for q in ([math.nan, 0, -100, 0], [0, math.inf, -100, 0]):
            with pytest.raises(ValueError, match="NaN or infinity"):
                c.move_joints(q)
        with pytest.raises(ValueError, match="finite"):
            c.move_cartesian([550.0, math.nan, 320.0, 0, 0, 0])
        assert sim.requests == writes and sim.command_writes == []  # not one request went out
        with pytest.raises(MotionRejected):  # and a real refusal still comes back typed
            c.move_joints([0.0, 0.0, -100.0, 99.0]).wait(2.0)
        c.close()
