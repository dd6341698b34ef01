"""Exact register transactions of the driver (map 3) against a scripted fake pymodbus client.

The fake hosts the 128-register window at a base (128 like a Universal Robots controller unless
a test says otherwise) and answers transfer requests and claims with the simulator's own
robot-program logic (:func:`simulators.controller_tables.serve_transfer`,
:class:`simulators.controller_claim.ClaimRules`)."""

import numpy as np
import pytest

from drivers.controller import ModbusController
from drivers.controller_errors import (
    ClaimIdentity,
    ControllerClaimed,
    HandshakeTimeout,
    MapVersionError,
    ModbusExceptionError,
    RegisterWindowError,
    WordOrderError,
)
from drivers.controller_map import (
    INFO_PAGES,
    REG,
    TABLE_HEADER_REGISTERS,
    WINDOW_SIZE,
    CorrectionState,
    WordOrder,
    XferOp,
    encode,
    encode_i32_array,
    registers_crc32,
    release_code,
)
from drivers.correction_table import (
    TableError,
    TablePageError,
    TableVerifyError,
    data_registers,
    header_registers,
)
from simulators.controller_claim import ClaimRules
from simulators.controller_tables import TableSlots, serve_transfer
from station.core.table.values import CorrectionTableData, TableAxis

BASE = 128
LIMITS = [-2, 2, -2.5, 2.5, -200, 0, -6, 6]
TOKEN = 0x5EC0DE01  # the session token of the station under test
ME = ClaimIdentity("10.0.0.7", 4711, 1796199978.0)
#: what connect() writes once granted: host, PID, since (big word order)
ME_WORDS = [0x0A00, 0x0007, 0, 4711, 0x6B0F, 0xD62A]


class _Resp:
    def __init__(self, registers=None, exception_code=None):
        self.registers = registers or []
        self.exception_code = exception_code

    def isError(self):
        return self.exception_code is not None


class FakeClient:
    """Records every transaction (wire addresses); the image is by window offset. Transfer
    requests are carried out at once, as the simulator's program does."""

    def __init__(self, order=WordOrder.BIG, base=BASE):
        self.base = base
        self.regs = [0] * WINDOW_SIZE
        self.log = []
        self.on_request = None
        self.order = order
        self.tables = TableSlots()
        self.claims = ClaimRules(order)
        self.put("map_version", 3)
        self.put("n_joints", 4)
        self.put("order_check", 1)
        self.put("correction_state", 1)

    def put(self, name, value):
        r = REG[name]
        w = encode(r, value, self.order)
        self.regs[r.address:r.address + len(w)] = w

    def info(self, number):
        if number == 0:
            return encode(INFO_PAGES["soft_limits"][1], LIMITS + [0] * 4, self.order)
        return None

    def connect(self):
        self.log.append(("connect",))
        return True

    def close(self):
        self.log.append(("close",))

    def _window(self, address, count):
        off = address - self.base
        return off if 0 <= off and off + count <= WINDOW_SIZE else None

    def read_holding_registers(self, address, *, count=1, device_id=1):
        self.log.append(("read", address, count, device_id))
        off = self._window(address, count)
        if off is None:
            return _Resp(exception_code=2)
        out = _Resp(self.regs[off:off + count])
        if self.on_request:
            self.on_request(self, ("read", off, count))
        return out

    def write_registers(self, address, values, *, device_id=1):
        self.log.append(("write", address, list(values), device_id))
        off = self._window(address, len(values))
        if off is None:
            return _Resp(exception_code=2)
        self.regs[off:off + len(values)] = list(values)
        if off == REG["xfer_seq"].address:
            serve_transfer(self.regs, self.tables, self.order, self.info)
        if off == REG["claim_request"].address:
            self.claims.serve(self.regs, heartbeat_live=True)
        if self.on_request:
            self.on_request(self, ("write", off, values))
        return _Resp()


def _connect(fake, **kw):
    kw.setdefault("register_base", BASE)
    kw.setdefault("claim_token", TOKEN)
    kw.setdefault("claim_identity", ME)
    c = ModbusController("fake", 0, device_id=7, heartbeat_period=None, client=fake, **kw)
    c.connect()
    return c


def _read_info_request(seq, number):
    return ("write", BASE + 63, [seq, int(XferOp.READ_INFO), number], 7)


def test_connect_transcript():
    fake = FakeClient()
    c = _connect(fake)
    assert fake.log == [("connect",), ("read", BASE, 64, 7), ("read", BASE + 64, 64, 7),
                        ("write", BASE, [1], 7), ("read", BASE + 1, 1, 7),  # a heartbeat: hb_pc is live
                        ("write", BASE + 26, [0x5EC0, 0xDE01], 7),  # claim_request: the session token
                        ("read", BASE + 28, 2, 7),          # claim_owner: granted
                        ("write", BASE + 30, ME_WORDS, 7),  # who holds it: host, PID, since
                        ("read", BASE + 43, 1, 7),          # xfer_ack: where the transfer numbers go on
                        _read_info_request(1, 0),           # soft limits: info page 0
                        ("read", BASE + 43, 84, 7),         # answer + page in one read
                        ("read", BASE + 9, 1, 7)]           # cmd_seq
    assert c.n_joints == 4 and c.map_version == 3 and c.claimed
    assert c.correction_state is CorrectionState.VENDOR
    np.testing.assert_array_equal(c.soft_limits(), np.reshape(LIMITS, (4, 2)))


@pytest.mark.parametrize("order", list(WordOrder))
def test_move_handshake_transcript(order):
    fake = FakeClient(order)
    fake.put("cmd_seq", 41)  # a previous session used 41: continue with 42
    c = _connect(fake, word_order=order)
    reads_of_status = []

    def robot(f, req):  # the robot acts after each request has been answered
        if req[0] == "write" and req[1] == REG["cmd_code"].address:
            f.put("ack_seq", 42)            # acknowledges the command
        if req[0] == "read" and req[1] == REG["ack_seq"].address:
            reads_of_status.append(1)
            if len(reads_of_status) == 1:
                f.put("done_seq", 42)       # finishes after the first status poll

    fake.on_request = robot
    fake.log.clear()
    q = [0.1, -0.2, -50.0, 1.0]
    st = c.move_joints(q, speed=0.25)
    st.wait(timeout=1.0)
    expected_block = [1, 42, 0, 250] + encode_i32_array(q + [0, 0], 1e-6, order) + encode("cmd_token", TOKEN, order)
    assert fake.log == [
        ("write", BASE, [2], 7), ("read", BASE + 1, 1, 7),  # no heartbeat thread: the command beats,
        ("read", BASE + 28, 2, 7),                # and checks that the claim did not lapse meanwhile
        ("write", BASE + 8, expected_block, 7),   # whole command block in ONE request, at 136
        ("read", BASE + 36, 7, 7),                # ack poll -> ack_seq == 42
        ("read", BASE + 36, 7, 7),                # done poll -> done_seq == 42
    ]
    # -50 mm is -50 000 000 counts of 1e-6: two's complement over two registers
    assert expected_block[8:10] == encode_i32_array([-50.0], 1e-6, order)
    assert st.done and st.success


def test_missing_ack_is_not_resent():
    fake = FakeClient()
    c = _connect(fake, ack_timeout=0.05)
    fake.log.clear()
    with pytest.raises(HandshakeTimeout, match="NOT re-sent"):
        c.move_cartesian([500, 0, 300, 0, 0, 0], elbow=-1)
    writes = [e for e in fake.log if e[0] == "write" and e[1] != BASE]  # not the heartbeat
    assert len(writes) == 1 and writes[0][2][:3] == [2, 1, 0xFFFF]
    assert writes[0][2][4:16] == encode_i32_array([500, 0, 300, 0, 0, 0], 1e-6, WordOrder.BIG)  # the pose
    assert writes[0][2][16:] == [0x5EC0, 0xDE01]  # the token
    assert all(e == ("read", BASE + 36, 7, 7) for e in fake.log[4:])


def test_modbus_exception_carries_code():
    fake = FakeClient()
    c = _connect(fake)
    fake.read_holding_registers = lambda address, *, count=1, device_id=1: _Resp(exception_code=4)
    with pytest.raises(ModbusExceptionError, match="server device failure") as ei:
        c.read_joints()
    assert ei.value.code == 4 and ei.value.address == BASE + REG["act_joints"].address


def test_wrong_base_is_named_on_the_first_read():
    fake = FakeClient(base=128)
    with pytest.raises(RegisterWindowError, match=r"first read.*controller_register_base") as ei:
        _connect(fake, register_base=0)
    assert ei.value.code == 2 and ei.value.base == 0
    assert fake.log == [("connect",), ("read", 0, 64, 7)]  # nothing written, nothing commanded


def test_wrong_map_version_names_expected_and_found():
    fake = FakeClient()
    fake.put("map_version", 1)
    with pytest.raises(MapVersionError, match=r"version 1 \(register 130\).*expects version 3") as ei:
        _connect(fake)
    assert (ei.value.found, ei.value.supported) == (1, (3,))
    assert not [e for e in fake.log if e[0] == "write"]


def test_word_order_mismatch_from_order_check():
    fake = FakeClient(WordOrder.LITTLE)
    with pytest.raises(WordOrderError, match="LITTLE"):
        _connect(fake, word_order=WordOrder.BIG)


def _table(n_first=2):
    axes = (TableAxis(400.0, 100.0, n_first), TableAxis(-100.0, 100.0, 3))
    vals = np.arange(1 * n_first * 3 * 4, dtype=np.float32).reshape(1, n_first, 3, 4) * 1e-4
    return CorrectionTableData(axes, vals)


def _page_request(seq, op, index, data):
    return ("write", BASE + 63, [seq, int(op), index, len(data)] + encode("page_crc", registers_crc32(data))
            + list(data), 7)


def test_table_upload_page_and_readback_transcript():
    fake = FakeClient()
    c = _connect(fake)
    t = _table(3)  # 36 values = 72 registers: pages of 29 + 7 values
    fake.log.clear()
    c.upload_table(t)
    data = data_registers(t)
    assert len(header_registers(t)) == TABLE_HEADER_REGISTERS
    assert fake.log == [_page_request(2, XferOp.WRITE_HEADER, 0, header_registers(t)),
                        ("read", BASE + 43, 84, 7),
                        _page_request(3, XferOp.WRITE_PAGE, 0, data[:58]),
                        ("read", BASE + 43, 84, 7),
                        _page_request(4, XferOp.WRITE_PAGE, 1, data[58:]),
                        ("read", BASE + 43, 84, 7)]
    assert all(len(e[2]) <= 123 for e in fake.log if e[0] == "write")
    fake.log.clear()
    back = c.read_table()
    assert back.same_as(t)
    assert fake.log == [("write", BASE + 63, [5, int(XferOp.READ_HEADER), 0], 7), ("read", BASE + 43, 84, 7),
                        ("write", BASE + 63, [6, int(XferOp.READ_PAGE), 0], 7), ("read", BASE + 43, 84, 7),
                        ("write", BASE + 63, [7, int(XferOp.READ_PAGE), 1], 7), ("read", BASE + 43, 84, 7)]


def test_refused_page_raises_and_leaves_nothing_to_stage():
    fake = FakeClient()
    c = _connect(fake)
    t = _table(3)
    real = fake.write_registers

    def flaky(address, values, *, device_id=1):  # the second value page arrives with a bit flipped
        if values[:2] == [4, int(XferOp.WRITE_PAGE)]:
            values = list(values)
            values[6] ^= 1
        return real(address, values, device_id=device_id)

    fake.write_registers = flaky
    with pytest.raises(TablePageError, match="PAGE_CRC_MISMATCH"):
        c.upload_table(t)
    assert 1 not in fake.tables.pages
    with pytest.raises(TableVerifyError, match="last upload failed"):
        c.stage_table()
    assert not [e for e in fake.log if e[0] == "write" and e[1] == BASE + 8]  # no TABLE_STAGE sent


def test_activation_refused_without_readback_or_with_difference():
    fake = FakeClient()
    c = _connect(fake)
    t = _table(2)
    c.upload_table(t)
    fake.log.clear()
    with pytest.raises(TableVerifyError, match="not read back"):
        c.activate_table()
    assert fake.log == []  # refused before touching the controller
    # value 2 changes in the controller's store behind its page: the whole-table CRC-32 catches it
    fake.tables.corrupt_value(2, 1e-6, WordOrder.BIG)
    with pytest.raises(TableError, match="CRC-32"):
        c.read_table()
    with pytest.raises(TableVerifyError, match="read-back failed"):
        c.stage_table()
    with pytest.raises(TableVerifyError, match="read-back failed"):
        c.activate_table()


def test_a_held_controller_is_refused_before_anything_is_written():
    fake = FakeClient()
    holder = _connect(fake)  # another station (same fake controller), granted and named
    fake.log.clear()
    with pytest.raises(ControllerClaimed, match=r"host 10\.0\.0\.7, PID 4711, since 2026-12-02 08:26:18 UTC") as ei:
        _connect(fake, claim_token=0x12345678, claim_identity=ClaimIdentity("10.0.0.8", 99, 1.0))
    assert ei.value.owner_token == TOKEN and ei.value.holder == ME
    assert fake.log == [("connect",), ("read", BASE, 64, 7), ("read", BASE + 64, 64, 7),
                        ("read", BASE + 30, 6, 7)]  # the holder's name; nothing written, not even a heartbeat
    # the holder's orderly end gives the controller back: release code, then claim_owner read until 0
    fake.log.clear()
    holder.close()
    assert fake.log == [("write", BASE + 26, encode("claim_request", release_code(TOKEN)), 7),
                        ("read", BASE + 28, 2, 7), ("close",)]
    assert [fake.regs[REG[n].address] for n in ("claim_owner", "claim_host", "claim_pid", "claim_since")] == [0] * 4
    _connect(fake, claim_token=0x12345678)  # now the other station gets it
