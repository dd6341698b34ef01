"""Simulated robot controller: pymodbus async TCP server + robot program, in a background thread.

The register map (map 3) and the handshake are those of :mod:`drivers.controller_map` /
``docs/protocols.md``. The controller hosts the map's window at ``register_base`` and refuses
every address outside ``[register_base, register_base + register_count)`` with Modbus exception
2, and every function code but 3, 4, 6 and 16 with exception 1; ``requests_log`` records every
request it served or refused in the action hook. The robot program carries out requests of the
transfer block (table pages, info pages) at once, while the request is served, and reacts to
writes of the command block on its program loop: it acknowledges,
validates (soft limits, reachability, correction-table range), moves with a simple max-speed
motion-time model scaled by ``time_scale`` (0 = instant), and reports done or error with the
same sequence number. Cartesian moves use the controller's NOMINAL kinematics in the robot base
frame, its own and not the station's (:class:`simulators.arm_kinematics.ArmKinematics`: a SCARA's
closed form refined by Newton; for an articulated arm general inverse kinematics from the joints
the robot stands at, which keeps its configuration), plus the multilinear table correction
(:meth:`simulators.program_words.ProgramTable.correction`, the rule of ``docs/protocols.md`` written again,
not the station's) when a table is active; registers are read and written with the program's own
words (:mod:`simulators.program_words`), not the driver's codec; the
table area itself is :class:`simulators.controller_tables.TableSlots`. One station per controller:
the claim block follows :class:`simulators.controller_claim.ClaimRules` - a request is served at
once, the watchdog (``hb_pc`` silent for ``watchdog``) frees a claim on the program tick, and every
command but STOP whose ``cmd_token`` is not the owner's is refused with NOT_CLAIMED;
``command_log`` records (code, seq, token) of every command block written. With ``collision`` (a
:class:`simulators.collision_check.CellCollision`, ``[simulation] collision_check``) every motion's
target and the joint-space path to it are checked after the soft limits; a colliding one is refused
with COLLISION (nothing moves) and kept in ``collisions``.

Faults are injected at run time through methods of :class:`SimulatedController` (thread-safe).
A robot program that implements the protocol *wrongly* is played with ``quirks`` (see
:data:`QUIRKS`): deliberate, documented deviations that ``station conformance`` must catch. The
default (no quirks) is the conforming program.

Requires the pymodbus 3.16 server data model (``pymodbus.simulator.SimDevice`` with ``action``).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
import time
from typing import TYPE_CHECKING, Iterable, cast

import numpy as np
from pymodbus.constants import ExcCodes
from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from drivers.controller_map import (
    FUNCTION_CODES,
    INFO_PAGES,
    MAP_VERSION,
    MAX_JOINTS,
    ORDER_CHECK_VALUE,
    REG,
    REGISTERS,
    WINDOW_SIZE,
    Command,
    ErrorCode,
    StatusBit,
    WordOrder,
    register_span,
)
from simulators.arm_kinematics import ArmKinematics, Unreachable
from simulators.controller_claim import ClaimRules
from simulators.controller_faults import QUIRKS, FaultInjection, ModbusFault
from simulators.controller_tables import TableSlots, serve_transfer
from simulators.program_words import OutsideTable, ProgramTable, get_value, put_value
from simulators.truth_kinematics import matrix_pose, pose_matrix
from station.core.kinematics.model import RobotModel
from station.io.robot.files import load_robot

if TYPE_CHECKING:
    from simulators.cell import SimulatedCell
    from simulators.collision_check import CellCollision, Hit

__all__ = ["SimulatedController", "ModbusFault", "QUIRKS"]

log = logging.getLogger(__name__)

_CMD_FIRST, _CMD_COUNT = register_span("cmd_code", "cmd_token")
_LATCHING = (ErrorCode.ESTOP, ErrorCode.DRIVE_FAULT, ErrorCode.WATCHDOG_TIMEOUT)

class _Abort(Exception):
    def __init__(self, code: ErrorCode, joint: int = 0):
        super().__init__(code.name)
        self.code = code
        self.joint = joint


class SimulatedController(FaultInjection):
    """The simulated controller. ``start()`` returns once the port accepts connections.

    ``quirks``: names from :data:`QUIRKS`, each a deliberate deviation from the protocol that
    plays a wrong robot program (fault injection for ``station conformance``); the default, none,
    is the conforming program.
    """

    def __init__(self, model: RobotModel | None = None, cell: "SimulatedCell | None" = None,
                 host: str = "127.0.0.1", port: int = 0, word_order: WordOrder = WordOrder.BIG,
                 time_scale: float = 0.0, heartbeat_period: float = 0.1, watchdog: float = 1.0,
                 max_speed: np.ndarray | None = None, soft_limits: np.ndarray | None = None,
                 map_version: int = MAP_VERSION, quirks: Iterable[str] = (), register_base: int = 0,
                 register_count: int = WINDOW_SIZE, correction_state: int = 0,
                 collision: "CellCollision | None" = None):
        if model is None:
            model = cell.truth.model if cell is not None else load_robot("sr800")
        self.model = model
        #: the controller's nominal kinematics, its own code (a slip shared with the station's
        #: would cancel end to end)
        self.kinematics = ArmKinematics([t.joint for t in model.transforms], model.nominal)
        self.cell = cell
        self.g = model.n_joints
        if self.g > MAX_JOINTS:
            raise ValueError(f"the register map holds at most {MAX_JOINTS} joints")
        self.host, self._port_req = host, int(port)
        self.port = 0
        #: deliberate protocol deviations (:data:`QUIRKS`); empty for the conforming program
        self.quirks = frozenset(quirks)
        unknown = sorted(self.quirks - set(QUIRKS))
        if unknown:
            raise ValueError(f"unknown quirks {unknown}; known: {sorted(QUIRKS)}")
        if "swapped_word_order" in self.quirks:
            word_order = WordOrder.LITTLE if word_order is WordOrder.BIG else WordOrder.BIG
        #: the word order the program uses (the link's, unless the swapped_word_order quirk)
        self.word_order = word_order
        self.time_scale = float(time_scale)
        self.heartbeat_period = float(heartbeat_period)
        self.watchdog = float(watchdog)
        if max_speed is None:
            max_speed = np.array([2.5 if t == "revolute" else 1000.0 for t in model.joint_types])
        self.max_speed = np.asarray(max_speed, dtype=float)
        self.soft_limits = np.array(model.joint_limits if soft_limits is None else soft_limits, float)
        if self.soft_limits.shape != (self.g, 2) or not np.all(np.isfinite(self.soft_limits)) \
                or not np.all(self.soft_limits[:, 0] < self.soft_limits[:, 1]):
            raise ValueError(f"soft limits must be ({self.g}, 2) finite [lower, upper] pairs with "
                             f"lower < upper, got {self.soft_limits.tolist()}")
        #: the version published in ``map_version`` (another one plays a foreign robot program)
        self.map_version = int(map_version)
        #: the window it hosts: wire addresses register_base .. register_base + register_count - 1
        self.register_base, self.register_count = int(register_base), int(register_count)
        if not 1 <= self.register_count or self.register_base < 0 \
                or self.register_base + self.register_count > 65536:
            raise ValueError(f"register window {register_base}+{register_count} outside 0..65535")
        #: what the program reports in correction_state (CorrectionState)
        self.correction_state = int(correction_state)
        #: the controller's own collision check of every motion (None: off, ``[simulation]
        #: collision_check``); every refusal is kept in ``collisions`` as (seq, what hit what)
        self.collision = collision
        self.collisions: list[tuple[int, "Hit"]] = []
        # the image by window offset (the map's 128, or more when the window is larger)
        self._regs = [0] * max(WINDOW_SIZE, self.register_count)
        self._readonly = [False] * len(self._regs)
        for r in REGISTERS:
            if r.access == "r":
                self._readonly[r.address:r.end] = [True] * r.n_registers
        self._lock = threading.Lock()
        # robot state
        self._q = np.zeros(self.g)
        self._bits = StatusBit.READY | StatusBit.IN_POSITION
        self._last_seq = 0
        self._latched: ErrorCode | None = None
        self._tables = TableSlots(crc_little_endian="crc_mismatch" in self.quirks, quirks=self.quirks)
        self._claim = ClaimRules(self.word_order, self.quirks)
        self._move_task: asyncio.Task | None = None
        self._stop_request = False
        self._hb_robot = 0
        self._hb_pc_last = 0
        self._hb_pc_changed = time.monotonic()
        # faults
        self._faults: list[ModbusFault] = []
        self._latency = 0.0
        self._lose_ack = False
        self._last_ack_late = 0  # quirk ack_after_answer: the seq whose ack is still due
        self._estop_next = False
        self._drive_fault_next: int = 0
        self._hb_frozen = "no_heartbeat" in self.quirks
        # introspection
        self.command_writes: list[tuple[int, int]] = []  # (code, seq) per write of the command block
        #: (code, seq, cmd_token) per write of the command block: whose command it was
        self.command_log: list[tuple[int, int, int]] = []
        #: (function code, wire address, count) of every request that reached the program
        self.requests_log: list[tuple[int, int, int]] = []
        self._corrupt_next_page = False
        self._switch_faults: dict[str, tuple[int, bool]] = {}  # TABLE_ACTIVATE/ROLLBACK to fail next
        self._xfer_last = 0
        self.requests = 0
        self.motion_failures = 0  # motions that ended in an internal error (reported DRIVE_FAULT)
        self.failure: BaseException | None = None
        # thread/loop
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._ready = threading.Event()
        self._cmd_event: asyncio.Event | None = None
        self._stop_event: asyncio.Event | None = None
        self._server: ModbusTcpServer | None = None
        self._init_registers()
        if cell is not None:
            self._q = np.array(cell.encoder_joints(), dtype=float)
        self._publish_state()

    # ------------------------------------------------------------------ registers
    def _set(self, name: str, value) -> None:
        put_value(self._regs, REG[name], value, self.word_order)

    @staticmethod
    def _word(v: int) -> int:
        return v + 0x10000 if v < 0 else v

    def _get(self, name: str):
        # read as a UR's read_port_register returns a register, "signed ... (-32768 : 32767)" (Script Directory
        # §17.38), then made the map's word, as robot-programs/ur does (tests/robot_programs/test_sim_signed_words.py)
        r = REG[name]
        signed = [w - 0x10000 if w >= 0x8000 else w for w in self._regs[r.address:r.end]]
        value = get_value([self._word(v) for v in signed], r, self.word_order, base=-r.address)
        return np.asarray(value, dtype=float) if r.count > 1 else value

    def _init_registers(self) -> None:
        self._set("map_version", self.map_version)
        self._set("n_joints", self.g)
        self._set("watchdog_ms", int(round(self.watchdog * 1000)))
        self._set("correction_state", self.correction_state)
        self._set("order_check", ORDER_CHECK_VALUE)

    def _publish_state(self) -> None:
        q = np.zeros(MAX_JOINTS)
        q[:self.g] = self._q
        self._set("act_joints", q)
        self._bits = self._tables.status_bits(self._bits)
        self._set("status", int(self._bits))
        for k, crc in self._tables.crcs().items():
            self._set(f"table_{k}_crc", crc)

    def _info_page(self, number: int) -> list[int] | None:
        """Info page ``number`` as the program fills it (None: no such page)."""
        if number == INFO_PAGES["soft_limits"][0]:
            lim = np.zeros(2 * MAX_JOINTS)
            lim[:2 * self.g] = self.soft_limits.ravel()
            return self._page_words(INFO_PAGES["soft_limits"][1], lim)
        if number == INFO_PAGES["act_pose"][0]:
            T = self.kinematics.forward(self._q)
            return self._page_words(INFO_PAGES["act_pose"][1], matrix_pose(T))
        return None

    def _page_words(self, entry, values) -> list[int]:
        page = [0] * entry.n_registers
        put_value(page, entry, values, self.word_order, base=-entry.address)
        return page

    def _transfer(self) -> None:
        """The program's side of a transfer request (caller holds the lock)."""
        self._xfer_last = int(self._get("xfer_seq"))
        corrupt, self._corrupt_next_page = self._corrupt_next_page, False
        serve_transfer(self._regs, self._tables, self.word_order, self._info_page, corrupt)

    def _build_device(self) -> SimDevice:
        # one block: the whole window; pymodbus refuses any address outside it with exception 2
        block = SimData(self.register_base, count=self.register_count, values=0, datatype=DataType.REGISTERS)
        return SimDevice(0, simdata=[block], action=self._action)

    async def _action(self, function_code: int, start_address: int, address: int, count: int,
                      registers: list[int], set_values) -> ExcCodes | None:
        """pymodbus hook: runs on every request before it is served (on the server loop)."""
        self.requests += 1
        self.requests_log.append((int(function_code), int(address), int(count)))
        if function_code not in FUNCTION_CODES:
            return ExcCodes.ILLEGAL_FUNCTION
        if self._latency > 0:
            await asyncio.sleep(self._latency)
        first = address - self.register_base
        with self._lock:
            for f in self._faults:
                if (address <= f.address < address + count
                        and (f.function_code is None or f.function_code == function_code)):
                    f.times -= 1
                    if f.times <= 0:
                        self._faults.remove(f)
                    return ExcCodes(f.code)
            if set_values:
                vals = [int(v) for v in set_values]
                if any(self._readonly[first:first + len(vals)]):
                    return ExcCodes.ILLEGAL_ADDRESS
                self._regs[first:first + len(vals)] = vals
                hb = REG["hb_pc"].address
                if first <= hb < first + len(vals) and vals[hb - first] != self._hb_pc_last:
                    self._hb_pc_last = vals[hb - first]
                    self._hb_pc_changed = time.monotonic()
                xs = REG["xfer_seq"].address
                if first <= xs < first + len(vals) and vals[xs - first] != self._xfer_last:
                    self._transfer()
                cr = REG["claim_request"].address
                if first <= cr < first + len(vals):  # carried out at once, as a transfer request
                    self._claim.serve(self._regs, not self._watchdog_expired())
                seq_addr = REG["cmd_seq"].address
                if first <= seq_addr < first + len(vals):
                    code_seq = (int(self._get("cmd_code")), int(self._get("cmd_seq")))
                    self.command_writes.append(code_seq)
                    self.command_log.append((*code_seq, self._claim.u32(self._regs, "cmd_token")))
                    if self._cmd_event is not None:
                        self._cmd_event.set()
            else:
                off = address - start_address
                registers[off:off + count] = self._regs[first:first + count]
        return None

    # ------------------------------------------------------------------ lifetime
    def start(self, timeout: float = 10.0) -> "SimulatedController":
        if self._thread is not None:
            raise RuntimeError("controller simulator already started")
        self._thread = threading.Thread(target=self._run, name="controller-sim", daemon=True)
        self._thread.start()
        if not self._ready.wait(timeout):
            raise RuntimeError(f"controller simulator did not start within {timeout} s")
        if self.failure is not None:
            raise RuntimeError(f"controller simulator failed to start: {self.failure}") from self.failure
        return self

    def _run(self) -> None:
        loop = asyncio.new_event_loop()
        self._loop = loop
        try:
            loop.run_until_complete(self._main())
        except BaseException as exc:  # reported through .failure and stop()
            self.failure = exc
            log.exception("controller simulator failed")
        finally:
            self._ready.set()
            loop.close()

    async def _main(self) -> None:
        self._cmd_event = asyncio.Event()
        self._stop_event = asyncio.Event()
        self._server = ModbusTcpServer(self._build_device(), address=(self.host, self._port_req))
        await self._server.serve_forever(background=True)
        # pymodbus annotates the transport as BaseTransport; a TCP listener's is the asyncio.Server
        listener = cast(asyncio.Server, self._server.transport)
        self.port = int(listener.sockets[0].getsockname()[1])
        program = asyncio.create_task(self._program())
        self._ready.set()
        await self._stop_event.wait()
        program.cancel()
        if self._move_task is not None:
            self._move_task.cancel()
        await asyncio.gather(program, *( [self._move_task] if self._move_task else []),
                             return_exceptions=True)
        await self._server.shutdown()
        if program.done() and not program.cancelled() and program.exception() is not None:
            raise program.exception()  # type: ignore[misc]

    def stop(self) -> None:
        if self._thread is None:
            return
        if self._loop is not None and self._stop_event is not None and self._thread.is_alive():
            self._loop.call_soon_threadsafe(self._stop_event.set)
        self._thread.join(10.0)
        if self._thread.is_alive():
            raise RuntimeError("controller simulator thread did not stop")
        self._thread = None
        if self.failure is not None:
            raise RuntimeError("controller simulator failed while running") from self.failure

    def __enter__(self) -> "SimulatedController":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    @property
    def address(self) -> str:
        return f"{self.host}:{self.port}"

    # ------------------------------------------------------------------ introspection
    @property
    def joints(self) -> np.ndarray:
        return self._q.copy()

    @property
    def active_table(self) -> ProgramTable | None:
        return self._tables.active

    def register(self, name: str):
        with self._lock:
            return self._get(name)

    # ------------------------------------------------------------------ the robot program
    async def _program(self) -> None:
        assert self._cmd_event is not None
        next_tick = time.monotonic()
        while True:
            timeout = max(0.0, next_tick - time.monotonic())
            # Wake on a new command or at the next program tick, whichever comes first.
            with contextlib.suppress(asyncio.TimeoutError):
                await asyncio.wait_for(self._cmd_event.wait(), timeout)
            self._cmd_event.clear()
            if time.monotonic() >= next_tick:
                next_tick = time.monotonic() + self.heartbeat_period
                with self._lock:
                    if not self._hb_frozen:
                        self._hb_robot = (self._hb_robot + 1) & 0xFFFF
                        self._set("hb_robot", self._hb_robot)
                    self._serve_claim()
            await self._poll_command()

    def _watchdog_expired(self) -> bool:
        return time.monotonic() - self._hb_pc_changed > self.watchdog

    def _serve_claim(self) -> None:
        """The claim block on a program pass (caller holds the lock): the watchdog frees a claim
        whose holder stopped its heartbeat, then a pending request is granted if it may be."""
        live = not self._watchdog_expired()
        if not live:
            self._claim.expire(self._regs)
        self._claim.serve(self._regs, live)

    async def _poll_command(self) -> None:
        with self._lock:
            seq = int(self._get("cmd_seq"))
            if seq == self._last_seq:
                return
            expected = self._last_seq % 0xFFFF + 1
            self._last_seq = seq
            code = int(self._get("cmd_code"))
            elbow = int(self._get("cmd_elbow"))
            speed = float(self._get("cmd_speed"))
            pose = np.asarray(self._get("cmd_target"))
            joints = pose[:self.g]
            self._serve_claim()  # a holder silent for the watchdog period commands nothing more
            claimed = self._claim.allows(self._regs, int(self._get("cmd_token")))
            if self._lose_ack:
                self._lose_ack = False
                log.info("fault: command seq %d lost (not acknowledged)", seq)
                return
            if "ack_after_answer" in self.quirks:  # the previous command's ack, late
                self._set("ack_seq", self._last_ack_late)
                self._last_ack_late = seq
            else:
                self._set("ack_seq", 1 if "ack_without_seq" in self.quirks else seq)
        if seq != expected:
            return self._error(seq, ErrorCode.SEQUENCE_ERROR)
        try:
            cmd = Command(code)
        except ValueError:
            return self._error(seq, ErrorCode.BAD_COMMAND)
        busy = self._move_task is not None and not self._move_task.done()
        if cmd is Command.STOP:
            if busy:
                self._stop_request = True
                await asyncio.gather(self._move_task, return_exceptions=True)  # type: ignore[arg-type]
            return self._done(seq)
        if not claimed:  # STOP is obeyed from anyone; everything else only from the holder
            return self._error(seq, ErrorCode.NOT_CLAIMED)
        if cmd is Command.RESET:
            if busy:
                return self._error(seq, ErrorCode.BAD_COMMAND)
            with self._lock:
                self._latched = None
                self._bits = (self._bits & ~(StatusBit.ERROR | StatusBit.ESTOP)) | StatusBit.READY
                self._set("error_code", 0)
                self._set("error_joint", 0)
                self._set("error_bound", 0)
                self._publish_state()
            return self._done(seq)
        if busy:
            return self._error(seq, ErrorCode.BAD_COMMAND)
        if cmd in (Command.MOVE_JOINTS, Command.MOVE_CARTESIAN):
            if self._latched is not None:
                return self._error(seq, ErrorCode.NOT_READY)
            if not 0.001 <= speed <= 1.0:
                return self._error(seq, ErrorCode.BAD_COMMAND)
            # Safety invariants (the station's guard enforces the same): every target is
            # finite, and every joint the robot would move to (after the correction table) lies
            # inside the soft limits. A NaN compares false with everything, so the checks are
            # written to let only values that positively pass through.
            if cmd is Command.MOVE_JOINTS:
                target = joints.astype(float)
                bad = np.flatnonzero(~np.isfinite(target))
                if bad.size:
                    return self._error(seq, ErrorCode.BAD_COMMAND, int(bad[0]) + 1)
            else:
                if elbow not in (1, -1) or not np.all(np.isfinite(pose)):
                    return self._error(seq, ErrorCode.BAD_COMMAND)
                try:
                    target = self.cartesian_target(pose, elbow)
                except _Abort as a:
                    return self._error(seq, a.code, a.joint)
            for j in range(self.g):
                lo, hi = self.soft_limits[j]
                if not lo <= target[j] <= hi:
                    return self._error(seq, ErrorCode.SOFT_LIMIT, j + 1, -1 if target[j] < lo else 1)
            if self.collision is not None:  # the target and the joint-space path to it, before anything moves
                hit = self.collision.check_move(self._q, target)
                if hit is not None:
                    log.info("motion seq %d refused: %s", seq, hit.describe())
                    self.collisions.append((seq, hit))
                    return self._error(seq, ErrorCode.COLLISION)
            self._move_task = asyncio.create_task(self._move(seq, target, speed))
            return None
        return self._table_command(seq, cmd)

    def cartesian_target(self, pose: np.ndarray, elbow: int) -> np.ndarray:
        """Joints the controller commands for a Cartesian target (nominal IK + table)."""
        T = pose_matrix(np.asarray(pose, dtype=float))
        try:
            if self.kinematics.is_scara:
                q = self.kinematics.scara_inverse(T, elbow)
            else:
                # An articulated arm keeps the configuration it stands in: general IK on the
                # nominal model from the current joints (the register map has no configuration
                # word; the elbow flag is only checked to be +1 or -1). Joints beyond the robot's
                # own limits are no solution: the arm cannot take them.
                q = self.kinematics.inverse(T, self._q)
                if not np.all((self.model.joint_limits[:, 0] <= q) & (q <= self.model.joint_limits[:, 1])):
                    raise Unreachable("the solution leaves the robot's joint limits")
        except Unreachable as exc:
            raise _Abort(ErrorCode.UNREACHABLE) from exc
        if not np.all(np.isfinite(q)):
            raise _Abort(ErrorCode.UNREACHABLE)
        try:
            return self._tables.correct(q, pose, elbow)
        except OutsideTable as exc:
            raise _Abort(ErrorCode.TARGET_OUTSIDE_TABLE) from exc

    def _error(self, seq: int, code: ErrorCode, joint: int = 0, bound: int = 0) -> None:
        with self._lock:
            self._set("error_code", int(code))
            self._set("error_joint", joint)
            self._set("error_bound", bound)
            if code in _LATCHING:
                self._latched = code
                self._bits = (self._bits | StatusBit.ERROR) & ~StatusBit.READY
                if code is ErrorCode.ESTOP:
                    self._bits |= StatusBit.ESTOP
                self._publish_state()
            self._set("error_seq", seq)

    def _done(self, seq: int) -> None:
        with self._lock:
            self._set("done_seq", seq)

    def _physical_move(self, q: np.ndarray) -> np.ndarray:
        if self.cell is not None:
            return np.asarray(self.cell.command_joints(q), dtype=float)
        return np.array(q, dtype=float)

    async def _move(self, seq: int, target: np.ndarray, speed: float) -> None:
        q0 = self._q.copy()
        dq = target - q0
        duration = self.time_scale * (float(np.max(np.abs(dq) / (self.max_speed * speed))) + 0.05)
        estop, self._estop_next = self._estop_next, False
        drive, self._drive_fault_next = self._drive_fault_next, 0
        self._stop_request = False
        with self._lock:
            self._bits = (self._bits | StatusBit.MOVING) & ~StatusBit.IN_POSITION
            self._publish_state()
        if "done_before_motion" in self.quirks:
            self._done(seq)
        t0 = time.monotonic()
        try:
            while True:
                frac = 1.0 if duration <= 0 else min(1.0, (time.monotonic() - t0) / duration)
                if (estop or drive) and (frac >= 0.5 or duration <= 0):
                    frac = 0.5
                    raise _Abort(ErrorCode.ESTOP) if estop else _Abort(ErrorCode.DRIVE_FAULT, drive)
                if self._stop_request:
                    raise _Abort(ErrorCode.MOTION_ABORTED)
                if duration > 0 and self._watchdog_expired():
                    raise _Abort(ErrorCode.WATCHDOG_TIMEOUT)
                with self._lock:
                    self._q = q0 + frac * dq
                    if frac < 1.0:
                        self._publish_state()
                if frac >= 1.0:
                    break
                await asyncio.sleep(min(0.01, duration / 20))
            enc = self._physical_move(target)
            with self._lock:
                self._q = enc
                self._bits = (self._bits & ~StatusBit.MOVING) | StatusBit.IN_POSITION
                self._publish_state()
            self._done(seq)
        except _Abort as a:
            enc = self._physical_move(q0 + frac * dq)
            with self._lock:
                self._q = enc
                self._bits = self._bits & ~StatusBit.MOVING
                self._publish_state()
            self._error(seq, a.code, a.joint)
        except Exception:  # a bug of the simulated program must not leave it MOVING for good
            log.exception("controller simulator: motion seq %d failed", seq)
            self.motion_failures += 1
            with self._lock:
                self._bits = self._bits & ~StatusBit.MOVING
                self._publish_state()
            self._error(seq, ErrorCode.DRIVE_FAULT, 0)
        finally:
            self._stop_request = False

    def _table_command(self, seq: int, cmd: Command) -> None:
        with self._lock:
            fault = self._switch_faults.pop(cmd.name, None)
            if cmd is Command.TABLE_STAGE:
                code = self._tables.stage(self.word_order, self.g)
            elif fault is not None and not fault[1]:
                code = ErrorCode(fault[0])  # refused: the slots stay as they were
            else:
                code = self._tables.switch(cmd)
                if fault is not None:  # switched, then failed before its acknowledgement
                    code = ErrorCode(fault[0])
            self._publish_state()
        if code is not ErrorCode.NONE:
            return self._error(seq, code)
        return self._done(seq)
