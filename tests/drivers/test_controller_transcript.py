"""Exact register transactions of the driver against a scripted fake pymodbus client."""

import numpy as np
import pytest

from drivers.controller import HandshakeTimeout, ModbusController, ModbusExceptionError
from drivers.controller_map import REG, WordOrder, encode, encode_f32_array
from drivers.correction_table import CorrectionTableData, TableAxis, TableVerifyError


class _Resp:
    def __init__(self, registers=None, exception_code=None):
        self.registers = registers or []
        self.exception_code = exception_code

    def isError(self):
        return self.exception_code is not None


class FakeClient:
    """Records every transaction; reads are answered from a register image that a script may
    change after each request (what the robot would do)."""

    def __init__(self, order=WordOrder.BIG):
        self.regs = [0] * 65536
        self.log = []
        self.on_request = None
        self.order = order
        self.put("map_version", 1)
        self.put("n_joints", 4)
        self.put("soft_limits", [-2, 2, -2.5, 2.5, -200, 0, -6, 6])

    def put(self, name, value):
        r = REG[name]
        w = encode(r, value, self.order)
        self.regs[r.address:r.address + len(w)] = w

    def connect(self):
        self.log.append(("connect",))
        return True

    def close(self):
        self.log.append(("close",))

    def read_holding_registers(self, address, *, count=1, device_id=1):
        self.log.append(("read", address, count, device_id))
        out = _Resp(self.regs[address:address + count])
        if self.on_request:
            self.on_request(self, ("read", address, count))
        return out

    def write_registers(self, address, values, *, device_id=1):
        self.log.append(("write", address, list(values), device_id))
        self.regs[address:address + len(values)] = list(values)
        if self.on_request:
            self.on_request(self, ("write", address, values))
        return _Resp()


def _connect(fake, **kw):
    c = ModbusController("fake", 0, device_id=7, heartbeat_period=None, client=fake, **kw)
    c.connect()
    return c


def test_connect_transcript():
    fake = FakeClient()
    c = _connect(fake)
    assert fake.log == [("connect",), ("read", 2, 1, 7), ("read", 3, 1, 7), ("read", 72, 24, 7),
                        ("read", 11, 1, 7)]
    assert c.n_joints == 4
    np.testing.assert_array_equal(c.soft_limits(), [[-2, 2], [-2.5, 2.5], [-200, 0], [-6, 6]])


@pytest.mark.parametrize("order", list(WordOrder))
def test_move_handshake_transcript(order):
    fake = FakeClient(order)
    fake.put("cmd_seq", 41)  # a previous session used 41: continue with 42
    c = _connect(fake, word_order=order)
    reads_of_status = []

    def robot(f, req):  # the robot acts after each request has been answered
        if req[0] == "write" and req[1] == 10:
            f.put("ack_seq", 42)            # acknowledges the command
        if req[0] == "read" and req[1] == 40:
            reads_of_status.append(1)
            if len(reads_of_status) == 1:
                f.put("done_seq", 42)       # finishes after the first status poll

    fake.on_request = robot
    fake.log.clear()
    q = [0.1, -0.2, -50.0, 1.0]
    st = c.move_joints(q, speed=0.25)
    st.wait(timeout=1.0)
    expected_block = ([1, 42, 0, 250] + encode_f32_array(q + [0, 0], order)
                      + encode_f32_array(np.zeros(6), order))
    assert fake.log == [
        ("write", 10, expected_block, 7),   # whole command block in ONE request
        ("read", 40, 7, 7),                 # ack poll -> ack_seq == 42
        ("read", 40, 7, 7),                 # done poll -> done_seq == 42
    ]
    assert st.done and st.success


def test_missing_ack_is_not_resent():
    fake = FakeClient()
    c = _connect(fake, ack_timeout=0.05)
    fake.log.clear()
    with pytest.raises(HandshakeTimeout, match="NOT re-sent"):
        c.move_cartesian([500, 0, 300, 0, 0, 0], elbow=-1)
    writes = [e for e in fake.log if e[0] == "write"]
    assert len(writes) == 1 and writes[0][2][:3] == [2, 1, 0xFFFF]
    assert all(e == ("read", 40, 7, 7) for e in fake.log[1:])


def test_modbus_exception_carries_code():
    fake = FakeClient()
    c = _connect(fake)
    fake.read_holding_registers = lambda address, *, count=1, device_id=1: _Resp(exception_code=2)
    with pytest.raises(ModbusExceptionError, match="illegal data address") as ei:
        c.read_joints()
    assert ei.value.code == 2 and ei.value.address == REG["act_joints"].address


def _table(n_first=2):
    axes = (TableAxis(400.0, 100.0, n_first), TableAxis(-100.0, 100.0, 3))
    vals = np.arange(1 * n_first * 3 * 4, dtype=np.float32).reshape(1, n_first, 3, 4) * 1e-4
    return CorrectionTableData(axes, vals)


def test_table_upload_and_readback_transcript():
    fake = FakeClient()
    c = _connect(fake)
    t = _table(2)  # 24 values = 48 registers
    fake.log.clear()
    c.upload_table(t)
    assert fake.log == [("write", 100, t.header_registers(), 7),
                        ("write", 1000, t.data_registers(), 7)]
    fake.log.clear()
    back = c.read_table()
    assert back.same_as(t)
    assert fake.log == [("read", 100, 29, 7), ("read", 1000, 48, 7)]


def test_large_table_is_chunked_within_modbus_limits():
    fake = FakeClient()
    c = _connect(fake)
    t = _table(30)  # 360 values = 720 registers
    fake.log.clear()
    c.upload_table(t)
    writes = [e for e in fake.log if e[0] == "write" and e[1] >= 1000]
    assert [w[1] for w in writes] == [1000 + 122 * i for i in range(6)]
    assert all(len(w[2]) <= 123 and len(w[2]) % 2 == 0 for w in writes)
    assert sum(len(w[2]) for w in writes) == 720
    fake.log.clear()
    c.read_table()
    reads = [e for e in fake.log if e[1] >= 1000]
    assert [r[1] for r in reads] == [1000 + 124 * i for i in range(6)]
    assert all(r[2] <= 125 for r in reads)


def test_activation_refused_without_readback_or_with_difference():
    fake = FakeClient()
    c = _connect(fake)
    t = _table(2)
    c.upload_table(t)
    fake.log.clear()
    with pytest.raises(TableVerifyError, match="not read back"):
        c.activate_table()
    assert fake.log == []  # refused before touching the controller
    fake.regs[1000 + 5] ^= 1  # one bit of value 2 flips in the controller
    c.read_table()
    with pytest.raises(TableVerifyError, match="first at flat index 2"):
        c.activate_table()
