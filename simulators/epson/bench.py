"""The station's side of the link written by hand, over a real loopback socket to the Modbus
TCP server the SPEL+ program serves itself, in the controller's simulated time: the controller's
clock advances only while the bench waits (no pacing thread, no wall clock), so a test of a 2 s
receive timeout takes a fraction of a second and never depends on the machine's load.

Frames are built and parsed by pymodbus (its socket framer and PDU classes), the register words
by the map (:mod:`drivers.controller_map`); the raw socket stays reachable for the faults a line
produces (a frame cut short, a client gone mid-request).
"""

from __future__ import annotations

import contextlib
import socket
from typing import Any, Callable

import numpy as np
from pymodbus.framer import FramerSocket
from pymodbus.pdu import DecodePDU, ModbusPDU
from pymodbus.pdu.register_message import ReadHoldingRegistersRequest, WriteMultipleRegistersRequest

from drivers.controller_map import PAGE_DATA_REGISTERS, REG, ErrorCode, decode, encode, registers_crc32
from simulators.epson.controller import EpsonController

__all__ = ["Link", "Station", "LinkClosed"]

#: the PC heartbeat period of the station (drivers/controller.py writes hb_pc every 0.1 s)
HB_PERIOD_S = 0.1


class LinkClosed(ConnectionError):
    """The program closed the connection (or never answered on it)."""


class Link:
    """One Modbus TCP client connection to the program, advancing the controller's clock while
    it waits for bytes."""

    def __init__(self, ep: EpsonController):
        self.ep = ep
        self.sock: socket.socket | None = None
        self.rx = bytearray()
        self.eof = False
        self.tid = 0
        self.framer = FramerSocket(DecodePDU(is_server=False))

    def connect(self) -> None:
        host, port = self.ep.address.rsplit(":", 1)
        self.sock = socket.create_connection((host, int(port)), timeout=5.0)
        self.sock.setblocking(False)
        self.rx, self.eof = bytearray(), False

    def close(self) -> None:
        if self.sock is not None:
            self.sock.close()
            self.sock = None

    def send_raw(self, data: bytes) -> None:
        assert self.sock is not None
        self.sock.sendall(data)

    def pull(self) -> None:
        """Whatever the program sent; ``eof`` once it closed the connection."""
        assert self.sock is not None
        while not self.eof:
            try:
                data = self.sock.recv(65536)
            except BlockingIOError:
                return
            except ConnectionResetError:
                data = b""
            if not data:
                self.eof = True
                return
            self.rx += data

    def frame(self, pdu: ModbusPDU) -> bytes:
        self.tid = self.tid % 0xFFFF + 1
        pdu.transaction_id, pdu.dev_id = self.tid, 1
        return self.framer.buildFrame(pdu)

    def request(self, pdu: ModbusPDU, max_s: float = 1.0) -> ModbusPDU:
        """Send ``pdu``; the response, parsed, once the controller has answered it within
        ``max_s`` of controller time."""
        self.send_raw(self.frame(pdu))
        t0 = self.ep.rt.now
        while True:
            self.pull()
            used, resp = self.framer.handleFrame(bytes(self.rx), 0, 0)
            if resp is not None:
                del self.rx[:used]
                if resp.transaction_id != self.tid:
                    raise AssertionError(f"transaction {resp.transaction_id} answered, {self.tid} asked")
                return resp
            if self.eof:
                raise LinkClosed("the program closed the connection")
            if self.ep.rt.now - t0 > max_s:
                raise TimeoutError(f"no answer within {max_s} s of controller time")
            self.ep.ticks(1)


class Station(Link):
    """The station's handshake by hand (as simulators/urscript/timing.Bench does for UR):
    named registers, commands with the station's token, transfers, the PC heartbeat."""

    def __init__(self, ep: EpsonController, token: int = 0x5EC0DE01):
        super().__init__(ep)
        self.token = token
        self.seq = 0
        self.xfer = 0
        self.hb = 0
        #: the PC heartbeat: ``until`` writes hb_pc every 0.1 s while True
        self.pc_heartbeat = True

    def read_words(self, address: int, count: int) -> list[int]:
        resp = self.request(ReadHoldingRegistersRequest(address=address, count=count))
        if resp.isError():
            raise AssertionError(f"read {address}+{count}: Modbus exception {resp.exception_code}")
        return list(resp.registers)

    def write_words(self, address: int, words: list[int]) -> ModbusPDU:
        return self.request(WriteMultipleRegistersRequest(address=address, registers=list(words)))

    def read(self, name: str) -> Any:
        r = REG[name]
        return decode(r, self.read_words(r.address, r.n_registers))

    def write(self, name: str, value: Any) -> None:
        resp = self.write_words(REG[name].address, encode(REG[name], value))
        if resp.isError():
            raise AssertionError(f"write {name}: Modbus exception {resp.exception_code}")

    def wait(self, seconds: float) -> None:
        """Controller time passes; the PC heartbeat goes on."""
        end = self.ep.rt.now + seconds
        while self.ep.rt.now < end:
            step = min(HB_PERIOD_S, end - self.ep.rt.now)
            self.ep.ticks(max(1, round(step / 0.001)))
            if self.pc_heartbeat:
                self.hb = self.hb % 0xFFFF + 1
                self.write("hb_pc", self.hb)

    def until(self, pred: Callable[[], bool], max_s: float = 5.0) -> float:
        """Controller seconds until ``pred`` holds (checked every 10 ms)."""
        t0 = self.ep.rt.now
        while not pred():
            if self.ep.rt.now - t0 > max_s:
                raise TimeoutError(f"not within {max_s} s of controller time")
            self.wait(0.01) if self.pc_heartbeat else self.ep.ticks(10)
        return self.ep.rt.now - t0

    def claim(self) -> int:
        """Requests the claim and returns the owner the program then names: this station's token
        when granted, another's when refused (a refusal is what the tests look for, so not
        being granted within 1 s of controller time is an answer, not an error)."""
        self.write("claim_request", self.token)
        with contextlib.suppress(TimeoutError):
            self.until(lambda: self.read("claim_owner") == self.token, 1.0)
        return int(self.read("claim_owner"))

    def command(self, code: int, joints=None, speed: float = 0.5, pose=None, elbow: int = 0,
                seq: int | None = None) -> int:
        self.seq = self.seq % 0xFFFF + 1 if seq is None else seq
        target = np.zeros(6)  # six word pairs whatever the robot's joints: cmd_token follows them
        given = joints if joints is not None else pose
        if given is not None:
            target[:len(given)] = given
        regs = (encode("cmd_code", int(code)) + encode("cmd_seq", self.seq) + encode("cmd_elbow", elbow)
                + encode("cmd_speed", speed) + encode("cmd_target", target)
                + encode("cmd_token", self.token))
        self.write_words(REG["cmd_code"].address, regs)
        return self.seq

    def answer(self, seq: int, max_s: float = 10.0) -> str:
        """``done`` or the error code's name the program answered ``seq`` with."""
        self.until(lambda: self.read("done_seq") == seq or self.read("error_seq") == seq, max_s)
        return "done" if self.read("done_seq") == seq else ErrorCode(self.read("error_code")).name

    def transfer(self, op: int, index: int, data: list[int] | None = None) -> tuple[int, list[int]]:
        """One transfer request; (xfer_error, the page's data registers) once answered."""
        self.xfer = self.xfer % 0xFFFF + 1
        block = [self.xfer, int(op), int(index)]
        if data is not None:
            assert len(data) <= PAGE_DATA_REGISTERS
            block += [len(data)] + encode("page_crc", registers_crc32(data)) + list(data)
        self.write_words(REG["xfer_seq"].address, block)
        self.until(lambda: self.read("xfer_ack") == self.xfer, 1.0)
        n = int(self.read("page_len"))
        return int(self.read("xfer_error")), self.read_words(REG["page_data"].address, PAGE_DATA_REGISTERS)[:n]
