"""The shipped robot-programs/ur/station_link.script, unchanged, in the URScript executor, in
controller time (frames): the calibration handshake step by step, UR's signed registers, the
info pages' CRC-32, the deadlines at the executor's statement budget - and the old unsigned
reads, patched back into a copy, caught."""

from __future__ import annotations

import re
import zlib

import numpy as np
import pytest

from drivers.controller_map import (
    INFO_PAGES,
    MAP_VERSION,
    Command,
    ErrorCode,
    StatusBit,
    WordOrder,
    decode,
    registers_crc32,
    release_code,
)
from simulators.urscript import DEFAULT_BUDGET
from simulators.urscript.controller import SHIPPED_SCRIPT
from simulators.urscript.interp import FRAME_S
from simulators.urscript.parser import parse
from simulators.urscript.timing import DEADLINES_S, Bench, measure

SOURCE = SHIPPED_SCRIPT.read_text(encoding="utf-8")
HOME = [0.0, 0.0, 0.0, 0.0, 0.5, 0.0]


def started(source: str | None = None, budget: int = DEFAULT_BUDGET, claim: bool = True) -> Bench:
    b = Bench(budget, q0=HOME, source=source)
    b.until(lambda: b.read("map_version") == MAP_VERSION)
    if claim:
        assert b.claim() == b.token  # the station holds the controller before its first command
    return b


def answer(b: Bench, seq: int, frames: int = 5000) -> str:
    b.until(lambda: b.read("done_seq") == seq or b.read("error_seq") == seq, frames)
    return "done" if b.read("done_seq") == seq else ErrorCode(b.read("error_code")).name


def old_unsigned_reads(source: str) -> str:
    """The program with the reads of the first version: every register taken as 0..65535, which
    §17.38 read_port_register never returns (it returns -32768..32767)."""
    fixed_u16 = "    local w = rd(off)\n    if w < 0:\n      w = w + 65536\n    end\n"
    fixed_i32 = "    if lw < 0:\n      lw = lw + 65536\n    end\n"
    assert source.count(fixed_u16) == 1 and source.count(fixed_i32) == 1
    return source.replace(fixed_u16, "    local w = rd(off)\n").replace(fixed_i32, "")


def test_a_calibration_step_sequence():
    b = started()
    assert b.read("n_joints") == 6 and b.read("order_check") == 1 and b.read("correction_state") == 1
    # move: acknowledged at once, MOVING while it runs, done only once the arm stands at the target
    target = [0.2, -0.3, 1.5708, -2.0, 0.5, 3.0]
    seq = b.command(Command.MOVE_JOINTS, target)
    b.until(lambda: b.read("ack_seq") == seq, 10)
    b.until(lambda: not b.c.arm.idle, 10)
    assert b.read("status") & StatusBit.MOVING and not b.read("status") & StatusBit.IN_POSITION
    while not b.c.arm.idle:
        assert b.read("done_seq") != seq
        b.frames(1)
    assert answer(b, seq) == "done"
    np.testing.assert_allclose(b.c.arm.q, target, atol=1e-6)
    np.testing.assert_allclose(b.read("act_joints"), target, atol=1e-6)
    assert b.read("status") & StatusBit.IN_POSITION and not b.read("status") & StatusBit.MOVING
    # refusals with their codes; none of them moves the arm or latches
    q = b.c.arm.q.copy()
    seq = b.command(Command.MOVE_JOINTS, [0.2, -0.3, 3.5, -2.0, 0.5, 3.0])
    assert answer(b, seq) == "SOFT_LIMIT" and (b.read("error_joint"), b.read("error_bound")) == (3, 1)
    seq = b.command(Command.MOVE_JOINTS, [0.2, -6.5, 0.0, -2.0, 0.5, 3.0])
    assert answer(b, seq) == "SOFT_LIMIT" and (b.read("error_joint"), b.read("error_bound")) == (2, -1)
    assert answer(b, b.command(Command.MOVE_JOINTS, target, speed=0.0)) == "BAD_COMMAND"
    assert answer(b, b.command(99)) == "BAD_COMMAND"
    assert answer(b, b.command(Command.TABLE_STAGE)) == "TABLE_SHAPE_INVALID"
    assert answer(b, b.command(Command.TABLE_ACTIVATE)) == "TABLE_NOT_STAGED"
    assert answer(b, b.command(Command.TABLE_ROLLBACK)) == "NO_PREVIOUS_TABLE"
    assert answer(b, b.command(Command.TABLE_DEACTIVATE)) == "done"
    assert answer(b, b.command(Command.MOVE_JOINTS, target, seq=b.seq + 2)) == "SEQUENCE_ERROR"
    np.testing.assert_allclose(b.c.arm.q, q, atol=1e-12)
    assert b.read("status") & StatusBit.READY
    # STOP during a move: the move ends in MOTION_ABORTED, the STOP is done
    move = b.command(Command.MOVE_JOINTS, HOME, speed=0.05)
    b.frames(100)
    stop = b.command(Command.STOP)
    assert answer(b, stop) == "done" and b.read("error_seq") == move
    assert ErrorCode(b.read("error_code")) is ErrorCode.MOTION_ABORTED and b.c.arm.idle
    # the watchdog: the PC heartbeat stops during a move: stopped, latched, then NOT_READY
    b.pc_heartbeat = False
    move = b.command(Command.MOVE_JOINTS, HOME, speed=0.05)
    assert answer(b, move) == "WATCHDOG_TIMEOUT"
    assert b.read("status") & StatusBit.ERROR and not b.read("status") & StatusBit.READY and b.c.arm.idle
    stopped_at = b.c.arm.q.copy()
    assert b.read("claim_owner") == 0  # the same watchdog freed the silent station's claim
    b.pc_heartbeat = True
    assert answer(b, b.command(Command.MOVE_JOINTS, HOME)) == "NOT_CLAIMED"
    assert b.claim() == b.token
    assert answer(b, b.command(Command.MOVE_JOINTS, HOME)) == "NOT_READY"
    assert answer(b, b.command(Command.RESET)) == "done" and b.read("status") & StatusBit.READY
    assert b.read("error_code") == 0
    np.testing.assert_allclose(b.c.arm.q, stopped_at, atol=1e-12)
    assert answer(b, b.command(Command.MOVE_JOINTS, HOME)) == "done"
    np.testing.assert_allclose(b.c.arm.q, HOME, atol=1e-6)


def test_signed_registers_decode_every_target_and_sequence_number():
    b = started()
    # low words >= 0x8000: 1.5708 rad = 0x0017F7F0 counts; negative values; the i32 extremes of the map
    target = [1.5708, -1.5708, 0.032768, -0.032769, 0.5, -3.0]
    assert answer(b, b.command(Command.MOVE_JOINTS, target)) == "done"
    np.testing.assert_allclose(b.c.arm.q, target, atol=1e-6)
    # cmd_seq past 32767 and the wrap 65535 -> 1: every number accepted (after the jump to the
    # first of them, which skips numbers and is refused as it must be)
    for first in (32766, 65534):
        b.seq = first - 1
        assert answer(b, b.command(Command.TABLE_DEACTIVATE)) == "SEQUENCE_ERROR"
        for _ in range(3):
            assert answer(b, b.command(Command.TABLE_DEACTIVATE)) == "done"
    assert b.read("ack_seq") == 2


def test_a_cartesian_move_goes_through_the_controllers_inverse_kinematics():
    from scipy.spatial.transform import Rotation

    b = started()
    goal = np.array([0.3, 0.2, -0.1, 0.4, 0.6, 0.2])
    x = b.c.arm.forward(goal, [0.0] * 6)  # m, rotation vector (§15.11)
    rpy = Rotation.from_rotvec(x[3:]).as_euler("xyz")  # Rz(yaw) Ry(pitch) Rx(roll), §16.28
    pose = [*(np.array(x[:3]) * 1000.0), *rpy]  # the map: mm, rad
    b.c.arm.q = goal + 0.05  # stand near the goal: the IK keeps this configuration
    assert answer(b, b.command(Command.MOVE_CARTESIAN, pose=pose, elbow=1)) == "done"
    np.testing.assert_allclose(b.c.arm.q, goal, atol=1e-5)
    assert answer(b, b.command(Command.MOVE_CARTESIAN, pose=pose, elbow=0)) == "BAD_COMMAND"
    far = [2000.0, 2000.0, 2000.0, 0.0, 0.0, 0.0]  # 3.5 m from the base of a 1.65 m arm
    assert answer(b, b.command(Command.MOVE_CARTESIAN, pose=far, elbow=1)) == "UNREACHABLE"


@pytest.mark.parametrize("order", [WordOrder.BIG, WordOrder.LITTLE])
def test_info_pages_carry_the_zlib_crc(order):
    source = SOURCE if order is WordOrder.BIG else SOURCE.replace(
        "global WORD_ORDER_BIG = True", "global WORD_ORDER_BIG = False")
    b = started(source)
    assert b.read("order_check") == (1 if order is WordOrder.BIG else 65536)
    for page in (0, 1):
        x = b.transfer(5, page)
        b.until(lambda x=x: b.read("xfer_ack") == x, 500)
        n = b.read("page_len")
        words = b.c.ports.words(128 + 69, n)
        crc = b.c.ports.words(128 + 67, 2)
        crc_value = crc[0] << 16 | crc[1] if order is WordOrder.BIG else crc[1] << 16 | crc[0]
        assert b.read("xfer_error") == 0 and crc_value == registers_crc32(words)
        assert registers_crc32(words) == zlib.crc32(b"".join(w.to_bytes(2, "big") for w in words))
    x = b.transfer(5, 0)
    b.until(lambda: b.read("xfer_ack") == x, 500)
    limits = decode(INFO_PAGES["soft_limits"][1], b.c.ports.words(128 + 69, 24), order)
    np.testing.assert_allclose(limits, [-6.2, 6.2, -6.2, 6.2, -3.1, 3.1] + [-6.2, 6.2] * 3)
    x = b.transfer(2, 0)  # a table page: no table lives on this controller
    b.until(lambda: b.read("xfer_ack") == x, 500)
    assert ErrorCode(b.read("xfer_error")) is ErrorCode.PAGE_INVALID


def test_the_old_unsigned_reads_are_caught():
    b = started(old_unsigned_reads(SOURCE), claim=False)
    # the token's low word 0xDE01 is read unsigned, the owner written back is another number
    assert b.claim() not in (0, b.token)
    target = [0.0, 0.0, 1.5708, 0.0, 0.5, 0.0]
    assert answer(b, b.command(Command.MOVE_JOINTS, target)) == "done"
    # the observation: joint 3 commanded to 1.5708 rad arrives 65 536 µrad short
    assert b.c.arm.q[2] == pytest.approx(1.5708 - 0.065536, abs=1e-6)
    b.seq = 32766
    assert answer(b, b.command(Command.TABLE_DEACTIVATE)) == "SEQUENCE_ERROR"  # the jump to 32767
    assert answer(b, b.command(Command.TABLE_DEACTIVATE)) == "SEQUENCE_ERROR"  # 32768: read as -32768
    # the shipped program, the same steps: right
    b = started()
    assert answer(b, b.command(Command.MOVE_JOINTS, target)) == "done"
    assert b.c.arm.q[2] == pytest.approx(1.5708, abs=1e-6)
    b.seq = 32766
    assert answer(b, b.command(Command.TABLE_DEACTIVATE)) == "SEQUENCE_ERROR"
    assert answer(b, b.command(Command.TABLE_DEACTIVATE)) == "done"


@pytest.mark.parametrize("budget", [2, DEFAULT_BUDGET])
def test_the_program_meets_the_stations_deadlines(budget):
    t = measure(budget)
    assert t.met(), {k: t.seconds(k) for k in t.frames}
    assert all(t.seconds(k) <= DEADLINES_S[k] for k in ("ack", "info_page_0", "info_page_1", "heartbeat"))


def test_act_joints_are_written_within_one_frame_at_the_budget():
    b = started()
    writes: list[int] = []
    original = b.c.ports.write_any

    def spy(address: int, value: int) -> None:
        if 128 + 45 <= address < 128 + 57:
            writes.append(address)
        original(address, value)

    b.c.ports.write_any = spy  # type: ignore[method-assign]
    seq = b.command(Command.MOVE_JOINTS, [0.5, 0.2, -0.2, 0.1, 0.6, 0.3])
    torn = 0
    for _ in range(int(2.0 / FRAME_S)):
        writes.clear()
        b.frames(1)
        torn += len(writes) % 12 != 0
    assert torn == 0 and answer(b, seq) == "done"


def _functions(nodes):
    for n in nodes:
        if n.kind == "def":
            yield n.a
            yield from _functions(n.a.body)


def _assignments(stmts):
    for s in stmts:
        if s.kind == "assign" and s.a.kind == "name":
            yield s
        if s.kind == "while":
            yield from _assignments(s.b)
        if s.kind == "if":
            for _c, body in s.a:
                yield from _assignments(body)
            yield from _assignments(s.b)


def test_no_scratch_name_is_shared_between_functions_and_threads():
    """§9: a variable without a qualifier is the global of that name if there is one. Every
    variable a function or thread assigns is declared ``local`` (or is a parameter), or is a
    global written with ``global``: none of them can land on a global by accident."""
    top = parse(SOURCE)
    program = next(n.a for n in top if n.kind == "def")
    globals_ = {s.a.a for s in _assignments(program.body)}
    for f in _functions(program.body):
        declared = {p for p, _d in f.params}
        for s in _assignments(f.body):
            name = s.a.a
            if s.c == "local":
                assert name not in globals_, f"{f.name}: local {name} shadows a global"
                declared.add(name)
            elif s.c == "global":
                assert name in globals_, f"{f.name}: global {name} is not declared by the program"
            else:
                assert name in declared, f"{f.name} (line {s.line}): {name} assigned without local or global"
    assert not re.search(r"(?m)^[^#\n]*%", SOURCE)


def test_one_station_per_controller_in_the_program():
    """The claim block in controller time: a second claim is refused, a command with another token
    is refused without moving, the holder's release frees the controller (and names nobody), and a
    holder that stops its heartbeat loses it by the program's watchdog, not by hand."""
    b = started()
    other = 0x80000001  # another station's token; its high word reads negative (§17.38)
    assert b.claim(other, max_frames=200) == b.token  # refused: the holder keeps the controller
    q = b.c.arm.q.copy()
    assert answer(b, b.command(Command.MOVE_JOINTS, [0.1] * 6, token=other)) == "NOT_CLAIMED"
    b.frames(50)
    np.testing.assert_allclose(b.c.arm.q, q, atol=1e-12)
    assert answer(b, b.command(Command.MOVE_JOINTS, [0.0, 0.0, 0.2, 0.0, 0.5, 0.0])) == "done"  # undisturbed
    # STOP is obeyed from anyone (safety), and is not a claim
    assert answer(b, b.command(Command.STOP, token=other)) == "done" and b.read("claim_owner") == b.token
    # the holder names itself, then gives the controller back: all of the block is cleared
    b.write("claim_host", 0x7F000001)
    b.write("claim_pid", 4711)
    b.write("claim_since", 1796199978)
    b.write("claim_request", release_code(b.token))
    b.until(lambda: b.read("claim_owner") == 0, 200)
    assert [b.read(n) for n in ("claim_request", "claim_host", "claim_pid", "claim_since")] == [0, 0, 0, 0]
    assert b.claim(other) == other
    # the holder dies: hb_pc silent; no new claim is granted meanwhile, and the watchdog frees it
    b.pc_heartbeat = False
    frames = b.until(lambda: b.read("claim_owner") == 0, 2000)
    assert 1.0 <= frames * FRAME_S <= 1.3  # WATCHDOG_MS = 1000 of controller time, checked every 0.1 s
    assert b.claim(max_frames=300) == 0  # no live heartbeat: nobody is granted the controller
    b.pc_heartbeat = True
    b.until(lambda: b.read("claim_owner") == b.token, 200)  # the request stood; granted once hb_pc lives
