"""The conformance kit's plumbing: the register-level link to the controller, the answer to one
command, and the kit's state with its guarded command loop, which the checks
(:mod:`station.cell.conformance.checks`, :mod:`station.cell.conformance.table`) build on.

The link is the driver (:class:`drivers.controller.ModbusController`) with what a conforming
station never sends (a wrong sequence number, an unknown command code, a zero speed); every
motion target passes the park-zone guards before it is written.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from drivers.controller import ModbusController
from drivers.controller_errors import ControllerConnectionError, HandshakeTimeout
from drivers.controller_map import MAX_JOINTS, REG, Command, ErrorCode, WordOrder, encode, registers_crc32
from drivers.controller_status import ControllerStatus
from station.cell.config.cell_config import CellConfig
from station.cell.config.sections import ConformanceConfig
from station.cell.conformance.report import REQUIREMENTS, Requirement
from station.cell.limits.motion_guard import MotionGuard
from station.core.table.values import CorrectionTableData

_CMD_FIRST = REG["cmd_code"].address
_XFER_FIRST = REG["xfer_seq"].address
_ACK = REG["xfer_ack"].address  # xfer_ack, xfer_error: two consecutive registers
_ANSWER_TIMEOUT = 3.0  # seconds for a non-motion command to be answered


def _next(seq: int) -> int:
    return seq % 0xFFFF + 1


class _Link(ModbusController):
    """The driver, with the register-level access the kit needs."""

    def open_socket(self) -> None:
        """Connect the socket only (no checks): the kit reads the identification itself first."""
        with self._io_lock:
            ok = self._client.connect()
        if not ok:
            raise ControllerConnectionError(
                f"cannot connect to the controller at {self.host}:{self.port}: check that it is powered, the IP "
                f"address and port, and that the robot program is running")

    #: the program did not grant the kit's claim as the map says (the ``claim`` requirement failed):
    #: the kit goes on without one, so that the other requirements still show what the program does
    claim_failed = False

    def claim(self, owner: int | None = None) -> None:
        if not self.claim_failed:
            super().claim(owner)

    def claim_after_lapse(self) -> None:
        """Ask for the controller again after the kit let its claim lapse on purpose (the
        watchdog check): the lapse is that step's expected outcome, so the driver's warning that
        a claim lapsed - a fault in a run - is not given."""
        self._claimed = False
        self.claim()

    def read_registers(self, address: int, count: int) -> list[int]:
        return self._read(address, count)

    def write_registers(self, address: int, values: Sequence[int]) -> None:
        self._write(address, values)

    def read_entry(self, name: str) -> Any:
        return self._read_entry(name)

    @property
    def last_seq(self) -> int:
        return self._seq

    def sync_transfer(self) -> None:
        """Continue the transfer numbers from the program's ``xfer_ack`` (connect() does it too;
        the kit reads the soft limits before it connects)."""
        self._xfer_seq = int(self._read_entry("xfer_ack"))

    def read_info_raw(self, name: str) -> list[int]:
        """The raw registers of info entry ``name`` (``soft_limits``, ``act_pose``)."""
        return self._read_info_raw(name)

    def raw_transfer(self, op: int, index: int, data: Sequence[int] = (), *, length: int | None = None,
                     crc: int | None = None) -> int:
        """Send one transfer request as given - any operation, page length or page CRC, which a
        conforming station never sends: the kit tests the refusals - and return the program's
        ``xfer_error``. Raises :class:`HandshakeTimeout` when it is not answered."""
        with self._xfer_lock:
            seq = _next(self._xfer_seq)
            self._xfer_seq = seq  # consumed even if the write fails
            words = [int(w) for w in data]
            n = len(words) if length is None else int(length)
            c = registers_crc32(words) if crc is None else int(crc)
            self._write(_XFER_FIRST, [seq, int(op), int(index), n, *encode("page_crc", c, self.word_order), *words])
            deadline = time.monotonic() + _ANSWER_TIMEOUT
            while True:
                ack, error = self._read(_ACK, 2)
                if ack == seq:
                    return int(error)
                if time.monotonic() >= deadline:
                    raise HandshakeTimeout(f"transfer request {op} page {index} (xfer_seq {seq}) was not answered "
                                           f"within {_ANSWER_TIMEOUT} s (xfer_ack is {ack})")
                time.sleep(self.poll_interval)

    def send_block(self, code: int, seq: int, joints: np.ndarray | None = None, speed: float = 0.0,
                   token: int | None = None) -> None:
        """Write the whole command block in one request, as the handshake prescribes (any code,
        any sequence number, any speed, any token: the kit tests the refusals)."""
        o = self.word_order
        jj = np.zeros(MAX_JOINTS)
        if joints is not None:
            jj[:len(joints)] = joints
        regs = (encode("cmd_code", int(code), o) + encode("cmd_seq", int(seq), o) + encode("cmd_elbow", 0, o)
                + encode("cmd_speed", speed, o) + encode("cmd_target", jj, o)
                + encode("cmd_token", self.claim_token if token is None else int(token), o))
        self._seq = int(seq)  # consumed: the next command continues from here
        self._write(_CMD_FIRST, regs)


@dataclass
class _Answer:
    """What the controller did with one command of the kit."""

    code: int
    seq: int
    motion: bool
    target: np.ndarray | None = None
    ack_seen: bool = False
    last_ack: int = -1
    result: str = "none"  # "done", "error" or "none" (no answer in time)
    status: ControllerStatus | None = None  # the snapshot that carried the result
    moving_seen: bool = False
    stopped: bool = False
    #: one status read showed the command's done_seq / error_seq beside another ack_seq: the
    #: program wrote the block while the read copied it (or wrote the result before the ack)
    torn: bool = False

    @property
    def name(self) -> str:
        try:
            return Command(self.code).name
        except ValueError:
            return f"code {self.code}"

    def describe(self) -> str:
        if self.result == "error" and self.status is not None:
            try:
                code = ErrorCode(self.status.error_code).name
            except ValueError:
                code = f"unknown error code {self.status.error_code}"
            return f"{self.name} seq {self.seq}: error {code} (error_joint {self.status.error_joint}, " \
                   f"error_bound {self.status.error_bound})"
        if self.result == "done":
            return f"{self.name} seq {self.seq}: done"
        return f"{self.name} seq {self.seq}: no done_seq or error_seq within the timeout"

    def error_is(self, code: ErrorCode) -> bool:
        return self.result == "error" and self.status is not None and self.status.error_code == int(code)


class _KitBase:
    """The kit's state and plumbing; the checks are its subclasses' methods."""

    def __init__(self, cfg: CellConfig, conf: ConformanceConfig, link: _Link,
                 emit: Callable[[str], None]) -> None:
        self.cfg, self.conf, self.link, self.emit = cfg, conf, link, emit
        self.req = {rid: Requirement(rid, title) for rid, title in REQUIREMENTS}
        self.notes: list[str] = []
        self.answers: list[_Answer] = []
        self.detected: WordOrder | None = None
        self.g = cfg.model.n_joints
        self.zone_guard: MotionGuard | None = None
        self.motion_guard: MotionGuard | None = None
        self.ctrl_limits: np.ndarray | None = None
        self.may_move = False
        self.why_not_move = ""
        #: the slots as found (CRC-32 per slot, 0 empty) and their tables (None: empty or unread)
        self.crc0: dict[str, int] = {}
        self.found: dict[str, CorrectionTableData | None] = {}
        #: why the kit must not change the slots (a table it could not read back), "" if it may
        self.why_not_tables = "the slots were not read"
        #: the TABLE_NOT_STAGED check waits until the slot rules have left nothing staged
        self.not_staged_pending = False

    @property
    def uses_table(self) -> bool:
        """The station uploads a correction table to this cell's controller (SCARA robots)."""
        return bool(self.cfg.model.is_scara)

    # -- plumbing --------------------------------------------------------------------------
    def _guarded(self, target: np.ndarray, what: str, probe: bool = False) -> np.ndarray:
        """Every motion target passes the park-zone guard; every one but the soft-limit probe
        also the guard of the zone intersected with the soft limits."""
        assert self.zone_guard is not None and self.motion_guard is not None
        q = self.zone_guard.check_joints(target, f"conformance {what} (park zone)")
        if not probe:
            q = self.motion_guard.check_joints(q, f"conformance {what}")
        return q

    def _command(self, code: int, *, seq: int | None = None, target: np.ndarray | None = None,
                 speed: float = 0.0, what: str = "", probe: bool = False, token: int | None = None) -> _Answer:
        motion = code in (Command.MOVE_JOINTS, Command.MOVE_CARTESIAN)
        if motion:
            if target is None:
                raise ValueError("a motion needs a target")
            target = self._guarded(np.asarray(target, dtype=float), what or "motion", probe)
        seq = _next(self.link.last_seq) if seq is None else seq
        ans = _Answer(int(code), int(seq), motion, target)
        self.answers.append(ans)
        self.link.send_block(code, seq, target, speed, token)
        timeout = self.cfg.devices.motion_timeout_s if motion else _ANSWER_TIMEOUT
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            st = self.link.status()
            ans.last_ack = st.ack_seq
            ans.ack_seen |= st.ack_seq == seq
            ans.moving_seen |= st.moving
            if probe and st.moving and not ans.stopped:  # a refused target must never move
                ans.stopped = True
                self.link.send_block(Command.STOP, _next(self.link.last_seq))
                self.notes.append(f"the controller started moving towards the out-of-limits target of seq {seq}: "
                                  f"STOP sent")
            if st.done_seq == seq or st.error_seq == seq:
                ans.torn |= st.ack_seq != seq
                ans.result = "done" if st.done_seq == seq else "error"
                ans.status = st
                break
            time.sleep(0.003)
        if motion:
            self._settle()
        return ans

    def _settle(self) -> None:
        """Wait until the controller reports no motion (a program that reports done early must
        not make the next command a refused 'busy' one)."""
        deadline = time.monotonic() + self.cfg.devices.motion_timeout_s
        while self.link.status().moving and time.monotonic() < deadline:
            time.sleep(0.005)

    def _joints(self) -> np.ndarray:
        return self.link.read_joints()
