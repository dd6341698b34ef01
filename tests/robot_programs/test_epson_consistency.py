"""One Modbus read sees one state of the register image: the shipped Epson program copies a read's
registers, and its tasks publish theirs, under SyncLock REGS_LOCK [REF-SYNCLOCK].

SPEL+ switches tasks preemptively (the executor: after ``budget`` statements), so without the
lock a read of the status block that main updates in the middle of the copy shows error_seq = n
beside the old ack_seq. `station conformance` found it on CI (paced to the wall clock over
loopback: 7 torn reads in 1178 commands); here it is played in the controller's simulated time
(simulators/epson/bench.py), each read at another point of the server's time slice."""

from __future__ import annotations

import math
import re

import numpy as np
from pymodbus.pdu.register_message import ReadHoldingRegistersRequest, WriteMultipleRegistersRequest

from drivers.controller_map import REG, Command, XferOp, encode
from drivers.correction_table import WireAxis, WireTable, header_registers, value_pages
from simulators.epson.bench import Station
from simulators.epson.controller import SHIPPED_PRG, EpsonController

SOURCE = SHIPPED_PRG.read_text(encoding="utf-8")
PARK = (0.0, math.radians(30.0), -1.0, 0.0)
#: registers of the read in front of each command: the server's copy takes about 5 statements a
#: register, its time slice 400 (the executor's), so these move the copy of ack_seq through the
#: slice
FILLER = list(range(1, 100))
COMMANDS = 4 * len(FILLER)


def without_the_lock(source: str) -> str:
    stripped, n = re.subn(r"(?m)^[ \t]*Sync(?:Lock|Unlock) REGS_LOCK[ \t]*\n", "", source)
    # the server's three sections and its error handler's unlock, the heartbeat's section and its
    # handler's, main's loop, StopMotion's pair, TABLE_STAGE's pair and StageTable's two sections
    assert n == 20, n
    return stripped


def status_reads(source: str) -> tuple[int, int, list[tuple[int, int, int, int]]]:
    """Sends COMMANDS commands the program refuses at once (unknown code 99), each with a read of
    the status block (ack_seq .. table_previous_crc in one read) right behind it, and reads on
    until each is answered; returns the commands, the reads, and the reads that showed an answer
    without its acknowledgement."""
    ep = EpsonController(source, q0=PARK)
    ep.power_up()
    s = Station(ep)
    first, count = REG["ack_seq"].address, REG["table_previous_crc"].address + 2 - REG["ack_seq"].address
    at = {name: REG[name].address - first for name in ("ack_seq", "done_seq", "error_seq")}
    torn: list[tuple[int, int, int, int]] = []
    reads = 0
    try:
        s.connect()
        s.until(lambda: s.read("map_version") == 3)
        assert s.claim() == s.token
        for i in range(COMMANDS):
            if i % len(FILLER) == 0:  # each pass at another phase of main's 2 ms loop
                ep.ticks(1)
            # the command block and the first read in one send, as a client that does not wait
            # for the write's answer: the server copies the read while main takes the command
            seq = s.seq % 0xFFFF + 1
            s.seq = seq
            block = encode("cmd_code", 99) + encode("cmd_seq", seq) + [0] * (REG["cmd_token"].address
                                                                             - REG["cmd_elbow"].address)
            block += encode("cmd_token", s.token)
            # a read of FILLER[i] registers first: the server then reaches ack_seq at another
            # point of its time slice each time
            frames = s.frame(ReadHoldingRegistersRequest(address=0, count=FILLER[i % len(FILLER)]))
            frames += s.frame(WriteMultipleRegistersRequest(address=REG["cmd_code"].address, registers=block))
            frames += s.frame(ReadHoldingRegistersRequest(address=first, count=count))
            s.send_raw(frames)
            answers = []
            while len(answers) < 3:
                s.pull()
                used, resp = s.framer.handleFrame(bytes(s.rx), 0, 0)
                if resp is None:
                    assert not s.eof and ep.rt.now < 600, "the program stopped answering"
                    ep.ticks(1)
                    continue
                del s.rx[:used]
                answers.append(resp)
            assert not any(a.isError() for a in answers), answers
            words = list(answers[2].registers)
            while True:
                reads += 1
                ack, done, err = words[at["ack_seq"]], words[at["done_seq"]], words[at["error_seq"]]
                if seq in (done, err):
                    if ack != seq:
                        torn.append((seq, ack, done, err))
                    break
                words = s.read_words(first, count)
            if i % 20 == 19:  # the PC heartbeat, so that the claim holds
                s.wait(0.01)
        assert not ep.rt.errors, ep.rt.errors
    finally:
        s.close()
        ep.stop()
    return COMMANDS, reads, torn


def test_a_read_of_the_status_block_never_shows_an_answer_without_its_acknowledgement():
    commands, reads, torn = status_reads(SOURCE)
    assert reads >= commands
    assert torn == []


def test_the_same_reads_without_the_lock_see_half_written_updates():
    """The check above can fail: the program without its SyncLock lines tears reads."""
    _commands, _reads, torn = status_reads(without_the_lock(SOURCE))
    assert len(torn) >= 2, torn
    assert all(ack == seq - 1 for seq, ack, _done, _err in torn), torn


def test_the_server_answers_while_a_table_is_staged():
    """TABLE_STAGE's checks, CRC and copy take long with a large table (the default SCARA table
    has 31,680 values: about 2.6 s of executor time): they run without the lock, so the server
    answers reads meanwhile and the station's 1 s Modbus timeout never fires. The same
    program holding the lock through StageTable (the check can fail) stops answering for the
    whole stage."""
    gaps = {name: stage_read_gaps(src) for name, src in (
        ("shipped", SOURCE),
        ("locked through the stage", SOURCE.replace("        SyncUnlock REGS_LOCK\n        ec = StageTable()\n"
                                                    "        SyncLock REGS_LOCK\n", "        ec = StageTable()\n")
         .replace("    SyncLock REGS_LOCK\n    b = SlotOf(SLOT_STAGED)\n", "    b = SlotOf(SLOT_STAGED)\n")
         .replace("    SlotRef(SLOT_STAGED) = 0\n    SyncUnlock REGS_LOCK\n", "    SlotRef(SLOT_STAGED) = 0\n")
         .replace("    SyncLock REGS_LOCK\n    SlotRef(SLOT_STAGED) = b + 1\n    SyncUnlock REGS_LOCK\n",
                  "    SlotRef(SLOT_STAGED) = b + 1\n")))}
    (stage_s, longest_s), (stage_locked_s, longest_locked_s) = gaps["shipped"], gaps["locked through the stage"]
    assert stage_s > 0.1 and stage_locked_s > 0.1  # a stage long enough to see
    assert longest_s < 0.03, gaps  # the server's own 10 ms receive poll, and a read's copy
    assert longest_locked_s > 0.8 * stage_locked_s, gaps


def stage_read_gaps(source: str) -> tuple[float, float]:
    """Uploads a 2048-value table, sends TABLE_STAGE and reads the status block until it is
    answered; returns the stage's controller time and the longest controller time between two
    answered reads."""
    n = 16
    values = np.random.default_rng(0).normal(0.0, 1e-4, (2, n, n, 4))
    table = WireTable((WireAxis(-1.0, 0.5, n), WireAxis(-1.0, 0.5, n)), values)
    ep = EpsonController(source, q0=PARK)
    ep.power_up()
    s = Station(ep)
    try:
        s.connect()
        s.until(lambda: s.read("map_version") == 3)
        assert s.claim() == s.token
        assert s.transfer(XferOp.WRITE_HEADER, 0, header_registers(table))[0] == 0
        for k, page in enumerate(value_pages(table)):
            assert s.transfer(XferOp.WRITE_PAGE, k, page)[0] == 0
        assert s.claim() == s.token  # the upload's ticks carried no PC heartbeat: claimed again
        t0 = ep.rt.now
        seq = s.command(Command.TABLE_STAGE)
        last, longest = ep.rt.now, 0.0
        while True:
            words = s.read_words(REG["done_seq"].address, 2)
            longest, last = max(longest, ep.rt.now - last), ep.rt.now
            if seq in words:
                break
        assert words[0] == seq, (words, s.read("error_code"))  # done, not refused
        assert s.read("table_staged_crc") == table.crc32()
        assert not ep.rt.errors, ep.rt.errors
        return ep.rt.now - t0, longest
    finally:
        s.close()
        ep.stop()
