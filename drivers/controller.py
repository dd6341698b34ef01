"""Driver for the robot controller over Modbus TCP (pymodbus synchronous client).

The wire protocol is register map 3, defined in :mod:`drivers.controller_map` and documented in
``docs/protocols.md``: one window of 128 holding registers from ``register_base`` (every address
here is an offset into it), function codes 3 and 16 (the simulator also serves 4 and 6).
Summary of the handshake: the PC writes the whole command block (target, command code, sequence
number) in ONE request; the robot program acknowledges (``ack_seq``), moves, and reports
``done_seq`` or ``error_seq`` + ``error_code`` with the same number. The correction table and the
soft limits travel through the window's transfer block (:mod:`drivers.controller_transfer`).

Safety rules implemented here:

* A command is never re-sent automatically: the pymodbus client runs with ``retries=0`` and a
  missing acknowledgement raises :class:`HandshakeTimeout` instead of retrying.
* Slow actions return a :class:`MotionStatus`; waiting needs an explicit timeout.
* One station per controller: connect() claims the controller (:mod:`drivers.controller_session`)
  and refuses one that another station holds (:class:`ControllerClaimed`, naming the holder)
  before it writes anything; close() gives it back.
* A heartbeat thread writes ``hb_pc`` and checks that ``hb_robot`` advances; when it stops for
  longer than ``link_timeout`` the link is declared lost and every later call (and every pending
  motion) raises :class:`ControllerLinkLost` until :meth:`ModbusController.connect` is called
  again.
* A correction table is only staged after every page was acknowledged and read back with its
  page CRC, and the whole table compared value by value with its CRC-32; it is only activated
  once the controller's staged CRC-32 equals the uploaded one.

This module knows nothing of the station (no ``station`` import). Units: mm and rad. The errors
(:mod:`drivers.controller_errors`), the status objects (:mod:`drivers.controller_status`) and the
table data (:mod:`drivers.correction_table`) live in their own modules; import them from there.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any, Callable, Sequence

import numpy as np
from pymodbus.client import ModbusTcpClient
from pymodbus.exceptions import ConnectionException, ModbusException, ModbusIOException

from .controller_errors import (
    ClaimIdentity,
    ControllerConnectionError,
    HandshakeTimeout,
    MapVersionError,
    ModbusExceptionError,
    ModbusResponseError,
    RegisterWindowError,
    checked_soft_limits,
    error_for,
    word_order_problem,
)
from .controller_map import (
    MAX_JOINTS,
    REG,
    SUPPORTED_MAP_VERSIONS,
    WINDOW_SIZE,
    Command,
    ControllerError,
    CorrectionState,
    RegisterDecodeError,
    WordOrder,
    decode,
    encode,
    register_span,
)
from .controller_session import SessionKeeper, new_token
from .controller_status import CommandStatus, ControllerStatus, MotionStatus
from .controller_transfer import TablePager
from .correction_table import (
    TableError,
    TablePayload,
    TableVerifyError,
    WireTable,
    check_payload,
    decode_header,
    header_registers,
    payload_difference,
    table_crc32,
    table_from_registers,
    value_pages,
)

__all__ = [
    "ModbusController",
]

log = logging.getLogger(__name__)

_STATUS_FIRST, _STATUS_COUNT = register_span("ack_seq", "error_bound")
#: connect() reads the whole window in these two requests: the identification, and the proof
#: that the controller offers every register of the map
_HALF = WINDOW_SIZE // 2


# --------------------------------------------------------------------------------------------
# the driver
# --------------------------------------------------------------------------------------------


class ModbusController(SessionKeeper, TablePager):
    """Robot controller on Modbus TCP.

    ``register_base``: the wire address of the map's first register (``[devices]
    controller_register_base``; 128 on a Universal Robots controller). ``client`` may inject a
    pymodbus-compatible client (tests); otherwise a
    ``ModbusTcpClient(host, port=port, timeout=timeout, retries=0)`` is created. ``claim_token``
    and ``claim_identity`` fix the session token and the holder's identity (tests); by default a
    random token, and the socket's IPv4 address, this process's PID and the time of the grant.
    """

    poll_interval = 0.002

    def __init__(self, host: str, port: int, device_id: int = 1,
                 word_order: WordOrder = WordOrder.BIG, timeout: float = 1.0, register_base: int = 0,
                 heartbeat_period: float | None = 0.2, link_timeout: float | None = None,
                 ack_timeout: float = 1.0, command_timeout: float = 5.0, client: Any = None,
                 claim_token: int | None = None, claim_identity: ClaimIdentity | None = None):
        if not isinstance(word_order, WordOrder):
            raise ValueError(f"word_order must be WordOrder.BIG or WordOrder.LITTLE, got {word_order!r}")
        if not 0 <= int(register_base) <= 65536 - WINDOW_SIZE:
            raise ValueError(f"register_base must be 0..{65536 - WINDOW_SIZE} (the map's {WINDOW_SIZE} "
                             f"registers follow it), got {register_base!r}")
        self.register_base = int(register_base)
        self.host, self.port, self.device_id = host, int(port), int(device_id)
        self.word_order = word_order
        self.timeout = float(timeout)
        self.heartbeat_period = heartbeat_period
        self.link_timeout = (float(link_timeout) if link_timeout is not None
                             else max(1.0, 5.0 * (heartbeat_period or 0.2)))
        self.ack_timeout = float(ack_timeout)
        self.command_timeout = float(command_timeout)
        self._client = client if client is not None else ModbusTcpClient(
            host, port=self.port, timeout=self.timeout, retries=0, reconnect_delay=0.0)
        self._io_lock = threading.RLock()
        self._cmd_lock = threading.Lock()
        self._xfer_lock = threading.RLock()
        self._xfer_seq = 0
        self._seq = 0
        #: what the robot program reports about the controller's own correction (at connect)
        self.correction_state: CorrectionState | None = None
        self._n_joints = 0
        self.map_version: int | None = None
        self._hb_robot_seen: float | None = None
        self._soft_limits: np.ndarray | None = None
        self._pending: CommandStatus | None = None
        self._link_lost: str | None = None
        self._hb_thread: threading.Thread | None = None
        self._hb_stop = threading.Event()
        self._hb_counter = 0
        self._hb_last_error: BaseException | None = None
        self._uploaded: TablePayload | None = None
        self._upload_failed: str | None = None
        self._readback_ok = False
        self._readback_problem = "the uploaded table was not read back yet: call read_table()"
        self._connected = False
        self.claim_token = new_token() if claim_token is None else int(claim_token)
        self._claim_identity = claim_identity
        self._claimed = False
        self._watchdog_ms = 0

    # -- low level I/O ---------------------------------------------------------------------
    def _call(self, fn: Callable, fc: int, address: int, n_regs: int, **kw) -> Any:
        with self._io_lock:
            try:
                rr = fn(address, device_id=self.device_id, **kw)
            except ConnectionException as exc:
                raise ControllerConnectionError(
                    f"no connection to the controller at {self.host}:{self.port} ({exc}): check the "
                    f"network and that the robot program runs; the station reconnects on its next request") from exc
            except ModbusIOException as exc:
                raise ControllerConnectionError(
                    f"no valid response from {self.host}:{self.port} within {self.timeout} s for function "
                    f"{fc} at register {address} ({exc}); requests are never repeated automatically: "
                    f"check the controller") from exc
            except ModbusException as exc:
                raise ControllerConnectionError(
                    f"Modbus failure talking to {self.host}:{self.port}: {exc}") from exc
            except OSError as exc:
                raise ControllerConnectionError(
                    f"socket error talking to {self.host}:{self.port}: {exc}; check the network") from exc
        # pymodbus matches a response to its request by transaction id only and hands back
        # whatever function it carries: a read answered with FC 4, or an exception response
        # for another function, must not be taken for the answer.
        error = rr.isError()
        got = getattr(rr, "function_code", None)  # every pymodbus PDU has it
        if got is not None and int(got) != (fc | 0x80 if error else fc):
            raise ModbusResponseError(fc, int(got), address, n_regs)
        if error:
            code = getattr(rr, "exception_code", 0)
            if code == 2:  # every register of map 2 is in the window: the window is wrong
                raise RegisterWindowError(code, fc, address, n_regs, self.register_base, WINDOW_SIZE)
            raise ModbusExceptionError(code, fc, address, n_regs)
        return rr

    def _read(self, address: int, count: int) -> list[int]:
        """``count`` registers from window offset ``address`` (FC 3)."""
        out: list[int] = []
        step = 124  # even, <= 125
        first = self.register_base + address
        for a in range(first, first + count, step):
            n = min(step, first + count - a)
            rr = self._call(self._client.read_holding_registers, 3, a, n, count=n)
            regs = list(rr.registers)
            if len(regs) != n:
                raise RegisterDecodeError(f"asked for {n} registers at {a}, controller returned {len(regs)}")
            out += regs
        return out

    def _write(self, address: int, values: Sequence[int]) -> None:
        """``values`` from window offset ``address`` (FC 16)."""
        values = list(values)
        step = 122  # even, <= 123
        first = self.register_base + address
        for i in range(0, len(values), step):
            chunk = values[i:i + step]
            self._call(self._client.write_registers, 16, first + i, len(chunk), values=chunk)

    def _read_entry(self, name: str):
        r = REG[name]
        return decode(r, self._read(r.address, r.n_registers), self.word_order)

    # -- connection ------------------------------------------------------------------------
    def connect(self) -> "ModbusController":
        """Open the connection, check the map version, read g and the soft limits, resync the
        sequence number, and start the heartbeat thread. Clears a latched link loss."""
        self._stop_heartbeat()
        with self._io_lock:
            try:
                ok = self._client.connect()
            except OSError as exc:
                raise ControllerConnectionError(f"cannot connect to {self.host}:{self.port}: {exc}") from exc
        if not ok:
            raise ControllerConnectionError(
                f"cannot connect to the controller at {self.host}:{self.port}: check that it is "
                f"powered, the IP address and port, and that the robot program is running")
        try:
            ident = self._read(0, _HALF)
        except RegisterWindowError as exc:
            raise RegisterWindowError(exc.code, exc.function_code, exc.address, exc.count, self.register_base,
                                      WINDOW_SIZE, " on the first read") from exc

        def field(name: str) -> Any:
            r = REG[name]
            return decode(r, ident[r.address:r.end], self.word_order)

        version = field("map_version")
        if version not in SUPPORTED_MAP_VERSIONS:
            raise MapVersionError(version, SUPPORTED_MAP_VERSIONS, self.register_base)
        self.map_version = int(version)  # for the record (a report names it)
        try:
            self._read(_HALF, WINDOW_SIZE - _HALF)
        except RegisterWindowError as exc:
            raise RegisterWindowError(exc.code, exc.function_code, exc.address, exc.count, self.register_base,
                                      WINDOW_SIZE, ": the controller's window is smaller than the map") from exc
        self._check_word_order(int(field("order_check")))
        g = field("n_joints")
        if not 1 <= g <= MAX_JOINTS:
            raise ControllerError(f"controller reports {g} joints; supported are 1..{MAX_JOINTS}")
        self._n_joints = int(g)
        state = int(field("correction_state"))
        self.correction_state = (CorrectionState(state) if state in CorrectionState._value2member_map_
                                 else CorrectionState.UNKNOWN)
        self._watchdog_ms = int(field("watchdog_ms"))
        # the program sees the PC's heartbeat as live while hb_pc changes: go on from the value it holds,
        # or a station started again after one that died right after its first heartbeat writes that
        # same value, which the program cannot tell from silence (and never grants the claim)
        self._hb_counter = int(field("hb_pc"))
        self.claim(int(field("claim_owner")))  # before any transfer request: the holder's run goes on undisturbed
        self._xfer_seq = int(self._read_entry("xfer_ack"))  # the program answers the next number
        self._soft_limits = self._checked_soft_limits(g)
        self._seq = int(self._read_entry("cmd_seq"))
        self._link_lost = None
        self._pending = None
        self._connected = True
        if self.heartbeat_period:
            self._heartbeat_once()  # the controller sees a live PC before the first command
            self._start_heartbeat()
        return self

    def _check_word_order(self, value: int) -> None:
        problem = word_order_problem(value, self.word_order)
        if problem is not None:
            raise problem

    def _checked_soft_limits(self, g: int) -> np.ndarray:
        """Soft limits ``(g, 2)`` from info page 0 (see :func:`checked_soft_limits`)."""
        return checked_soft_limits(self._read_info_raw("soft_limits"), g, self.word_order)

    def controller_correction_state(self) -> CorrectionState:
        """The controller's own kinematic correction, as the robot program reports it in
        ``correction_state`` (read now): NONE, VENDOR (a factory / absolute-accuracy correction
        is on; the station's table would correct on top of it) or UNKNOWN."""
        self._check_link()
        state = int(self._read_entry("correction_state"))
        self.correction_state = (CorrectionState(state) if state in CorrectionState._value2member_map_
                                 else CorrectionState.UNKNOWN)
        return self.correction_state

    def close(self) -> None:
        """Give the controller back, stop the heartbeat and close the socket (pending motions are
        not stopped)."""
        if self._link_lost is None and self._connected:
            self.release()
        self._claimed = False
        self._stop_heartbeat()
        with self._io_lock:
            self._client.close()
        self._connected = False

    def __enter__(self) -> "ModbusController":
        return self.connect()

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def n_joints(self) -> int:
        return self._n_joints

    # -- reading ---------------------------------------------------------------------------
    def status(self) -> ControllerStatus:
        self._check_link()
        return ControllerStatus.from_registers(self._read(_STATUS_FIRST, _STATUS_COUNT))

    def read_joints(self) -> np.ndarray:
        """Actual joint values ``(g,)`` [rad | mm]."""
        self._check_link()
        return np.asarray(self._read_entry("act_joints"))[:self._n_joints].copy()

    def read_cartesian(self) -> np.ndarray:
        """Actual tool pose ``(6,)`` x,y,z,roll,pitch,yaw from the controller's nominal FK, base frame."""
        self._check_link()
        return self._read_info("act_pose")

    def soft_limits(self) -> np.ndarray:
        """Soft limits ``(g, 2)`` [lower, upper] as read at connect()."""
        if self._soft_limits is None:
            raise ControllerConnectionError("not connected: call connect() first")
        return self._soft_limits.copy()

    # -- commands --------------------------------------------------------------------------
    def _next_seq(self) -> int:
        return self._seq % 0xFFFF + 1

    def _send(self, code: Command, *, elbow: int = 0, speed: float = 0.0,
              joints: Sequence[float] | np.ndarray | None = None,
              pose: Sequence[float] | np.ndarray | None = None,
              status_cls: type[CommandStatus] = CommandStatus, target: Any = None) -> CommandStatus:
        """Write the command block in one request, wait for the acknowledgement. Never re-sent."""
        self._check_link()
        if not self._connected:
            raise ControllerConnectionError("not connected: call connect() first")
        with self._cmd_lock:
            seq = self._next_seq()
            o = self.word_order
            regs: list[int] = []
            regs += encode("cmd_code", int(code), o)
            regs += encode("cmd_seq", seq, o)
            regs += encode("cmd_elbow", elbow, o)
            regs += encode("cmd_speed", speed, o)
            tt = np.zeros(MAX_JOINTS)  # one target block: the joints or the pose
            if joints is not None:
                tt[:len(joints)] = joints
            elif pose is not None:
                tt[:6] = np.asarray(pose, dtype=float)
            regs += encode("cmd_target", tt, o)
            regs += encode("cmd_token", self.claim_token, o)
            first = REG["cmd_code"].address
            if not self.heartbeat_period:  # no heartbeat thread: the command beats
                self._heartbeat_once()
            if code is not Command.STOP:  # a STOP goes out whoever holds the controller (it obeys anyone's)
                self.claim()  # still ours; lapsed (no heartbeat for watchdog_ms): asked for again; another's: refused
            self._seq = seq  # consumed even if the write fails: never reuse a number
            try:
                self._write(first, regs)
            except ControllerConnectionError as exc:
                raise ControllerConnectionError(
                    f"{code.name} seq {seq}: the write of the command got no valid response ({exc}); the "
                    f"command was NOT re-sent and may or may not have reached the controller: read "
                    f"the robot's state and check the robot before commanding again") from exc
            deadline = time.monotonic() + self.ack_timeout
            while True:
                st = self.status()
                if st.ack_seq == seq:
                    break
                if time.monotonic() >= deadline:
                    raise HandshakeTimeout(
                        f"{code.name} seq {seq} was not acknowledged within {self.ack_timeout:.3g} s "
                        f"(ack_seq is {st.ack_seq}); the command was NOT re-sent: the operator must check "
                        f"the robot (is the program running, is it moving?) before commanding again")
                time.sleep(self.poll_interval)
            return status_cls(self, seq, code, target)

    def _check_no_pending_motion(self) -> None:
        p = self._pending
        if p is not None and not p._done:
            if not p.done:
                raise ControllerError(
                    f"motion seq {p.seq} still in progress: wait for its status or call stop() first")

    def move_joints(self, q: Sequence[float] | np.ndarray, speed: float = 0.5) -> MotionStatus:
        """Joint move (not corrected by a correction table). Returns an acknowledged status."""
        target = np.asarray(q, dtype=float).ravel()
        if target.size != self._n_joints:
            raise ValueError(f"controller has {self._n_joints} joints, got {target.size} values")
        if not np.all(np.isfinite(target)):
            raise ValueError("joint targets contain NaN or infinity")
        self._check_speed(speed)
        self._check_no_pending_motion()
        st = self._send(Command.MOVE_JOINTS, speed=speed, joints=target, status_cls=MotionStatus, target=target)
        self._pending = st
        return st  # type: ignore[return-value]

    def move_cartesian(self, pose6: Sequence[float] | np.ndarray, elbow: int = 1, speed: float = 0.5) -> MotionStatus:
        """Cartesian move to ``pose6`` = x,y,z,roll,pitch,yaw [mm, rad] in the robot base frame,
        with elbow configuration ``+1`` (phi2 > 0) or ``-1``. Corrected by the active table."""
        pose = np.asarray(pose6, dtype=float).ravel()
        if pose.size != 6 or not np.all(np.isfinite(pose)):
            raise ValueError(f"pose must be 6 finite values x,y,z,roll,pitch,yaw, got {pose6!r}")
        if elbow not in (1, -1):
            raise ValueError(f"elbow must be +1 or -1, got {elbow!r}")
        self._check_speed(speed)
        self._check_no_pending_motion()
        st = self._send(Command.MOVE_CARTESIAN, elbow=elbow, speed=speed, pose=pose,
                        status_cls=MotionStatus, target=pose)
        self._pending = st
        return st  # type: ignore[return-value]

    @staticmethod
    def _check_speed(speed: float) -> None:
        if not 0.001 <= speed <= 1.0:
            raise ValueError(f"speed is a fraction of the maximum speed, 0.001..1.0, got {speed}")

    def stop(self, timeout: float | None = None) -> None:
        """Stop any motion (the pending motion then fails with MotionAborted)."""
        self._send(Command.STOP).wait(timeout or self.command_timeout)

    def reset_error(self, timeout: float | None = None) -> None:
        """Clear a latched error (after e-stop / drive fault / watchdog): needs an explicit call."""
        self._send(Command.RESET).wait(timeout or self.command_timeout)
        self._pending = None

    # -- correction table ------------------------------------------------------------------
    def upload_table(self, table: TablePayload) -> None:
        """Send the header page, then every value page (29 values each), each in one request
        that the controller acknowledges after checking its page CRC. A refused page raises
        :class:`TablePageError`: the controller then holds no complete table to stage. A table
        the map cannot carry is refused before anything is sent (:class:`TableError`)."""
        if not (hasattr(table, "axes") and hasattr(table, "values")):
            raise TypeError("upload_table needs a table with axes and values (TablePayload)")
        check_payload(table)
        n_joints = int(table.values.shape[-1])
        if self._n_joints and n_joints != self._n_joints:
            raise TableError(f"table has {n_joints} joint corrections, controller {self._n_joints} joints")
        self._check_link()
        self._uploaded = None
        self._readback_ok = False
        self._readback_problem = "the uploaded table was not read back yet: call read_table()"
        self._upload_failed = "an upload is in progress"
        try:
            self._send_table_pages(header_registers(table, self.word_order), value_pages(table, self.word_order))
        except ControllerError as exc:
            self._upload_failed = f"the last upload failed ({exc})"
            raise
        self._upload_failed = None
        self._uploaded = table

    def read_table(self) -> WireTable:
        """Read the header page and every value page back (each page's CRC checked, then the
        whole table's CRC-32). If a table was uploaded in this session, compare value by value;
        the result gates :meth:`stage_table` and :meth:`activate_table`."""
        self._check_link()
        try:
            header, data = self._read_table_pages()
            h = decode_header(header, self.word_order)
            table = table_from_registers(header, data, self.word_order)
        except ControllerError as exc:
            if self._uploaded is not None:
                self._readback_ok = False
                self._readback_problem = f"read-back failed: {exc}"
            raise
        if self._uploaded is not None:
            diff = payload_difference(self._uploaded, table)
            if diff is None and h["crc"] != table_crc32(self._uploaded):
                diff = f"header CRC {h['crc']:#010x} != uploaded {table_crc32(self._uploaded):#010x}"
            self._readback_ok = diff is None
            self._readback_problem = "" if diff is None else f"read-back differs from upload: {diff}"
        return table

    def verify_table(self) -> WireTable:
        """read_table() and raise :class:`TableVerifyError` if it differs from the upload."""
        if self._uploaded is None:
            raise TableVerifyError("no table uploaded in this session: call upload_table() first")
        try:
            table = self.read_table()
        except TableVerifyError:
            raise
        except TableError as exc:  # a page or the whole table fails its CRC-32: not verified
            raise TableVerifyError(f"read-back failed: {exc}") from exc
        if not self._readback_ok:
            raise TableVerifyError(self._readback_problem + ": upload the table again")
        return table

    def _table_command(self, code: Command, timeout: float | None) -> None:
        self._send(code).wait(timeout or self.command_timeout)

    def stage_table(self, timeout: float | None = None) -> None:
        """Controller checks header, pages and CRC-32 of its stored table and keeps it as the
        staged table. A table uploaded in this session is only staged once it was read back
        identical (:meth:`verify_table`), else :class:`TableVerifyError`."""
        if self._upload_failed is not None:
            raise TableVerifyError(f"staging refused: {self._upload_failed}: upload the table again")
        if self._uploaded is not None and not self._readback_ok:
            raise TableVerifyError(f"staging refused: {self._readback_problem}")
        self._table_command(Command.TABLE_STAGE, timeout)

    def activate_table(self, timeout: float | None = None) -> None:
        """Activate the staged table. Refused (:class:`TableVerifyError`) unless the last upload
        was read back identical and the controller's staged CRC equals the uploaded CRC."""
        if self._uploaded is None:
            raise TableVerifyError("no table uploaded in this session: upload, read back, stage, then activate")
        if not self._readback_ok:
            raise TableVerifyError(f"activation refused: {self._readback_problem}")
        crc = table_crc32(self._uploaded)
        staged = int(self._read_entry("table_staged_crc"))
        st = self.status()
        if not st.table_staged or staged != crc:
            raise TableVerifyError(
                f"activation refused: controller's staged table CRC {staged:#010x} (staged bit "
                f"{int(st.table_staged)}) does not match the uploaded {crc:#010x}: call stage_table()")
        self._table_command(Command.TABLE_ACTIVATE, timeout)
        active = int(self._read_entry("table_active_crc"))
        if active != crc:
            raise TableVerifyError(
                f"controller reports active CRC {active:#010x} after activation, expected {crc:#010x}: "
                f"roll back with rollback_table() and check the controller program")

    def deactivate_table(self, timeout: float | None = None) -> None:
        """Stop applying corrections (the active table is kept as the previous one)."""
        self._table_command(Command.TABLE_DEACTIVATE, timeout)

    def rollback_table(self, timeout: float | None = None) -> None:
        """Make the previous table active again."""
        self._table_command(Command.TABLE_ROLLBACK, timeout)

    def discard_previous_table(self, timeout: float | None = None) -> None:
        """Forget the previous table: a later roll back has nothing to revive."""
        self._table_command(Command.TABLE_DISCARD_PREVIOUS, timeout)

    def table_crcs(self) -> dict[str, int]:
        """CRC-32 of the staged, active and previous tables on the controller (0 = none)."""
        return {k: int(self._read_entry(f"table_{k}_crc")) for k in ("staged", "active", "previous")}

    # -- error mapping ---------------------------------------------------------------------
    def _error_for(self, st: ControllerStatus, seq: int, command: Command, target: Any) -> ControllerError:
        return error_for(st, seq, command, target, self._soft_limits)
