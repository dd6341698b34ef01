"""Driver for the robot controller over Modbus TCP (pymodbus synchronous client).

The wire protocol is defined in :mod:`drivers.controller_map` and documented in
``docs/protocols.md``. Summary of the handshake: the PC writes the whole command block (target,
command code, sequence number) in ONE request; the robot program acknowledges (``ack_seq``),
moves, and reports ``done_seq`` or ``error_seq`` + ``error_code`` with the same number.

Safety rules implemented here:

* A command is never re-sent automatically: the pymodbus client runs with ``retries=0`` and a
  missing acknowledgement raises :class:`HandshakeTimeout` instead of retrying.
* Slow actions return a :class:`MotionStatus`; waiting needs an explicit timeout.
* A heartbeat thread writes ``hb_pc`` and checks that ``hb_robot`` advances; when it stops for
  longer than ``link_timeout`` the link is declared lost and every later call (and every pending
  motion) raises :class:`ControllerLinkLost` until :meth:`ModbusController.connect` is called
  again.
* A correction table is only activated after it was uploaded, read back and compared value by
  value, staged, and the controller's staged CRC-32 equals the uploaded one.

This module knows nothing of the station (no ``station`` import). Units: mm and rad.
"""

from __future__ import annotations

import logging
import threading
import time
import zlib
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import numpy as np
from pymodbus.client import ModbusTcpClient
from pymodbus.exceptions import ConnectionException, ModbusException, ModbusIOException

from .controller_map import (
    ERROR_MESSAGES,
    MAP_VERSION,
    MAX_JOINTS,
    MAX_TABLE_AXES,
    MAX_TABLE_VALUES,
    MODBUS_EXCEPTION_MEANINGS,
    REG,
    TABLE_DATA_ADDRESS,
    TABLE_FORMAT_VERSION,
    Command,
    ControllerError,
    ErrorCode,
    RegisterDecodeError,
    StatusBit,
    WordOrder,
    decode,
    decode_f32_array,
    encode,
    encode_f32_array,
    register_span,
)

__all__ = [
    "ModbusController",
    "ControllerStatus",
    "MotionStatus",
    "CommandStatus",
    "TableAxis",
    "CorrectionTableData",
    "ControllerError",
    "RegisterDecodeError",
    "ModbusExceptionError",
    "ControllerConnectionError",
    "ControllerLinkLost",
    "CommandRejected",
    "MotionRejected",
    "MotionAborted",
    "EmergencyStop",
    "DriveFault",
    "SequenceError",
    "HandshakeTimeout",
    "MotionTimeout",
    "TableError",
    "TableVerifyError",
    "TableRangeError",
    "WordOrder",
]

log = logging.getLogger(__name__)

# --------------------------------------------------------------------------------------------
# errors
# --------------------------------------------------------------------------------------------


class ModbusExceptionError(ControllerError):
    """The controller answered a request with a Modbus exception response."""

    def __init__(self, code: int, function_code: int, address: int, count: int):
        self.code = int(code)
        self.function_code = int(function_code)
        self.address = int(address)
        self.count = int(count)
        self.meaning = MODBUS_EXCEPTION_MEANINGS.get(self.code, "unknown exception code")
        super().__init__(
            f"Modbus exception {self.code} ({self.meaning}) for function {self.function_code} at "
            f"register {self.address} (count {self.count}): check the register map version and "
            f"word order configured for this controller; the request may be repeated once the "
            f"cause is fixed"
        )


class ControllerConnectionError(ControllerError):
    """No TCP connection, or no response to a request within the timeout."""


class ControllerLinkLost(ControllerError):
    """The heartbeat stopped (either side). Reconnect with connect() after checking the robot."""


class CommandRejected(ControllerError):
    """The controller refused a command (error reported with the command's sequence number)."""

    def __init__(self, message: str, code: int = 0, seq: int = 0):
        self.code = int(code)
        self.seq = int(seq)
        super().__init__(message)


class MotionRejected(CommandRejected):
    """A motion target was refused: soft limit, unreachable, outside the table, or not ready."""


class MotionAborted(CommandRejected):
    """The motion was aborted by a STOP command."""


class EmergencyStop(CommandRejected):
    """Emergency stop during (or before) the motion."""


class DriveFault(CommandRejected):
    """A drive reported a fault during the motion."""


class SequenceError(CommandRejected):
    """The controller did not accept the sequence number (not previous+1)."""


class HandshakeTimeout(ControllerError):
    """The controller did not acknowledge a command in time. The command was NOT re-sent."""


class MotionTimeout(ControllerError):
    """A motion did not complete within the caller's timeout (it may still be running)."""


class TableError(ControllerError):
    """A correction-table operation failed (invalid table, controller refused it)."""


class TableVerifyError(TableError):
    """A correction table may not be activated: it was not read back identical, or CRCs differ."""


class TableRangeError(TableError):
    """A point lies outside a correction table's grid."""


# --------------------------------------------------------------------------------------------
# status
# --------------------------------------------------------------------------------------------

_STATUS_FIRST, _STATUS_COUNT = register_span("ack_seq", "error_bound")


def _error_message(code: int) -> str:
    try:
        return ERROR_MESSAGES[ErrorCode(code)]
    except ValueError:
        return f"unknown error code {code}: check the controller program's map version"


@dataclass(frozen=True)
class ControllerStatus:
    """Snapshot of the response block."""

    ack_seq: int
    done_seq: int
    error_seq: int
    error_code: int
    bits: int
    error_joint: int
    error_bound: int

    ready: bool = field(init=False)
    moving: bool = field(init=False)
    in_position: bool = field(init=False)
    error: bool = field(init=False)
    estop: bool = field(init=False)
    table_active: bool = field(init=False)
    table_staged: bool = field(init=False)
    table_previous: bool = field(init=False)

    def __post_init__(self) -> None:
        b = StatusBit(self.bits & 0xFF)
        for name, bit in (("ready", StatusBit.READY), ("moving", StatusBit.MOVING),
                          ("in_position", StatusBit.IN_POSITION), ("error", StatusBit.ERROR),
                          ("estop", StatusBit.ESTOP), ("table_active", StatusBit.TABLE_ACTIVE),
                          ("table_staged", StatusBit.TABLE_STAGED),
                          ("table_previous", StatusBit.TABLE_PREVIOUS)):
            object.__setattr__(self, name, bool(b & bit))

    @property
    def error_message(self) -> str:
        return _error_message(self.error_code)

    @classmethod
    def from_registers(cls, regs: Sequence[int]) -> "ControllerStatus":
        """Decode the registers ``ack_seq .. error_bound``; raises :class:`RegisterDecodeError`."""
        if len(regs) != _STATUS_COUNT:
            raise RegisterDecodeError(f"status block: expected {_STATUS_COUNT} registers, got {len(regs)}")
        base = REG["ack_seq"].address

        def field_(name: str) -> Any:
            r = REG[name]
            return decode(r, regs[r.address - base:r.end - base])

        return cls(field_("ack_seq"), field_("done_seq"), field_("error_seq"), field_("error_code"),
                   field_("status"), field_("error_joint"), field_("error_bound"))


# --------------------------------------------------------------------------------------------
# correction table
# --------------------------------------------------------------------------------------------

_HDR_FIRST, _HDR_COUNT = register_span("table_format", "table_crc")


@dataclass(frozen=True)
class TableAxis:
    """One grid axis: nodes at ``start + i*step`` for ``i in range(count)``.

    A periodic axis (yaw) wraps with period ``count*step``: node ``count`` is node 0 again.
    ``start`` and ``step`` are rounded to float32, as they travel as f32.
    """

    start: float
    step: float
    count: int
    periodic: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "start", float(np.float32(self.start)))
        object.__setattr__(self, "step", float(np.float32(self.step)))
        object.__setattr__(self, "count", int(self.count))
        object.__setattr__(self, "periodic", bool(self.periodic))
        if not (np.isfinite(self.start) and np.isfinite(self.step) and self.step > 0):
            raise TableError(f"table axis needs a finite start and a step > 0, got {self.start}, {self.step}")
        if not 1 <= self.count <= 65535:
            raise TableError(f"table axis node count must be 1..65535, got {self.count}")

    @property
    def nodes(self) -> np.ndarray:
        return self.start + self.step * np.arange(self.count)


@dataclass(frozen=True, eq=False)
class CorrectionTableData:
    """Joint corrections on a grid over (up to) x, y, z, yaw of the Cartesian target.

    ``values``: float32 array of shape ``(n_configs, *grid_shape, n_joints)``; configuration 0
    is elbow=+1, 1 is elbow=-1. The controller adds the multilinear interpolation of the values
    to the joints its nominal inverse kinematics computes (see :meth:`interpolate`).
    """

    axes: tuple[TableAxis, ...]
    values: np.ndarray

    def __post_init__(self) -> None:
        axes = tuple(self.axes)
        if not 1 <= len(axes) <= MAX_TABLE_AXES:
            raise TableError(f"a correction table needs 1..{MAX_TABLE_AXES} axes, got {len(axes)}")
        for a in axes:
            if not isinstance(a, TableAxis):
                raise TableError(f"table axes must be TableAxis objects, got {type(a).__name__}")
        v = np.array(self.values, dtype=np.float32, copy=True)
        shape = tuple(a.count for a in axes)
        if v.ndim != len(axes) + 2 or v.shape[1:-1] != shape:
            raise TableError(
                f"table values must have shape (n_configs, {', '.join(map(str, shape))}, n_joints), "
                f"got {v.shape}")
        if not 1 <= v.shape[0] <= 2:
            raise TableError(f"n_configs must be 1 or 2, got {v.shape[0]}")
        if not 1 <= v.shape[-1] <= MAX_JOINTS:
            raise TableError(f"n_joints must be 1..{MAX_JOINTS}, got {v.shape[-1]}")
        if v.size > MAX_TABLE_VALUES:
            raise TableError(f"table has {v.size} values; the controller holds at most {MAX_TABLE_VALUES}: "
                             f"use a coarser grid")
        if not np.all(np.isfinite(v)):
            raise TableError("table values contain NaN or infinity")
        v.setflags(write=False)
        object.__setattr__(self, "axes", axes)
        object.__setattr__(self, "values", v)

    # -- properties ------------------------------------------------------------------------
    @property
    def n_configs(self) -> int:
        return int(self.values.shape[0])

    @property
    def n_joints(self) -> int:
        return int(self.values.shape[-1])

    @property
    def grid_shape(self) -> tuple[int, ...]:
        return tuple(a.count for a in self.axes)

    @property
    def n_values(self) -> int:
        return int(self.values.size)

    def crc32(self) -> int:
        """CRC-32 (zlib, ISO-HDLC polynomial) of the values as big-endian f32 bytes, C order."""
        return zlib.crc32(self.values.astype(">f4").tobytes()) & 0xFFFFFFFF

    def same_as(self, other: "CorrectionTableData") -> bool:
        """Bit-exact equality of axes and values."""
        return (self.axes == other.axes and self.values.shape == other.values.shape
                and bool(np.array_equal(self.values.view(np.uint32), other.values.view(np.uint32))))

    def first_difference(self, other: "CorrectionTableData") -> str | None:
        """Human-readable description of the first difference, or None if identical."""
        if self.axes != other.axes:
            return f"axes differ: {self.axes} vs {other.axes}"
        if self.values.shape != other.values.shape:
            return f"shapes differ: {self.values.shape} vs {other.values.shape}"
        a, b = self.values.ravel(), other.values.ravel()
        bad = np.nonzero(a.view(np.uint32) != b.view(np.uint32))[0]
        if bad.size:
            i = int(bad[0])
            return (f"{bad.size} value(s) differ, first at flat index {i} "
                    f"(uploaded {a[i]!r}, read back {b[i]!r})")
        return None

    # -- encoding --------------------------------------------------------------------------
    def header_registers(self, order: WordOrder = WordOrder.BIG) -> list[int]:
        """Registers ``table_format .. table_crc`` (one contiguous write)."""
        n = len(self.axes)
        pad = MAX_TABLE_AXES - n
        periodic = sum(1 << i for i, a in enumerate(self.axes) if a.periodic)
        regs: list[int] = []
        regs += encode("table_format", TABLE_FORMAT_VERSION, order)
        regs += encode("table_n_axes", n, order)
        regs += encode("table_shape", [a.count for a in self.axes] + [0] * pad, order)
        regs += encode("table_start", [a.start for a in self.axes] + [0.0] * pad, order)
        regs += encode("table_step", [a.step for a in self.axes] + [0.0] * pad, order)
        regs += encode("table_periodic", periodic, order)
        regs += encode("table_n_joints", self.n_joints, order)
        regs += encode("table_n_configs", self.n_configs, order)
        regs += encode("table_n_values", self.n_values, order)
        regs += encode("table_crc", self.crc32(), order)
        assert len(regs) == _HDR_COUNT
        return regs

    def data_registers(self, order: WordOrder = WordOrder.BIG) -> list[int]:
        return encode_f32_array(self.values.ravel(), order)

    @staticmethod
    def decode_header(regs: Sequence[int], order: WordOrder = WordOrder.BIG) -> dict:
        """Header registers -> dict(axes, n_joints, n_configs, n_values, crc, format).

        Raises :class:`TableError` (or :class:`RegisterDecodeError`) for an invalid header.
        """
        if len(regs) != _HDR_COUNT:
            raise RegisterDecodeError(f"table header: expected {_HDR_COUNT} registers, got {len(regs)}")

        def f(name: str):
            r = REG[name]
            return decode(r, regs[r.address - _HDR_FIRST:r.end - _HDR_FIRST], order)

        fmt = f("table_format")
        if fmt != TABLE_FORMAT_VERSION:
            raise TableError(f"table format version {fmt} is not {TABLE_FORMAT_VERSION}: "
                             f"the controller holds no table in this format")
        n_axes = f("table_n_axes")
        if not 1 <= n_axes <= MAX_TABLE_AXES:
            raise TableError(f"table header: n_axes {n_axes} not in 1..{MAX_TABLE_AXES}")
        shape, start, step, periodic = f("table_shape"), f("table_start"), f("table_step"), f("table_periodic")
        axes = tuple(TableAxis(float(start[i]), float(step[i]), int(shape[i]), bool(periodic >> i & 1))
                     for i in range(n_axes))
        n_joints, n_configs, n_values = f("table_n_joints"), f("table_n_configs"), f("table_n_values")
        expected = n_configs * int(np.prod([a.count for a in axes])) * n_joints
        if n_values != expected or not 1 <= n_configs <= 2 or not 1 <= n_joints <= MAX_JOINTS:
            raise TableError(f"table header inconsistent: n_values {n_values}, n_configs {n_configs}, "
                             f"n_joints {n_joints}, shape {[a.count for a in axes]}")
        if n_values > MAX_TABLE_VALUES:
            raise TableError(f"table header: n_values {n_values} exceeds capacity {MAX_TABLE_VALUES}")
        return dict(axes=axes, n_joints=n_joints, n_configs=n_configs, n_values=n_values,
                    crc=f("table_crc"), format=fmt)

    @classmethod
    def from_registers(cls, header: Sequence[int], data: Sequence[int],
                       order: WordOrder = WordOrder.BIG) -> "CorrectionTableData":
        h = cls.decode_header(header, order)
        if len(data) != 2 * h["n_values"]:
            raise RegisterDecodeError(f"table data: expected {2 * h['n_values']} registers, got {len(data)}")
        vals = decode_f32_array(data, order)
        shape = (h["n_configs"], *[a.count for a in h["axes"]], h["n_joints"])
        return cls(h["axes"], vals.reshape(shape))

    # -- the interpolation rule (docs/protocols.md) ----------------------------------------
    def interpolate(self, point: Sequence[float], config: int = 0) -> np.ndarray:
        """Multilinear interpolation of the joint corrections at ``point`` (one coordinate per
        axis: x, y, z, yaw of the target in the base frame, first ``n_axes`` of them).

        Per axis: ``u = (v - start) / step``. Periodic axes: ``u`` is taken modulo ``count`` and
        node ``count-1`` interpolates towards node 0. Non-periodic axes with ``count == 1`` are
        constant (any coordinate); otherwise ``0 <= u <= count-1`` is required (tolerance
        ``1e-6`` node) or :class:`TableRangeError` is raised. ``i0 = min(floor(u), count-2)``,
        ``t = u - i0``; the result is the sum over the 2^n corners of the product of weights
        ``(1-t)`` / ``t`` times the node values, computed in float64.
        """
        p = np.asarray(point, dtype=float).ravel()
        if p.size < len(self.axes):
            raise TableError(f"interpolation needs {len(self.axes)} coordinates, got {p.size}")
        if not 0 <= config < self.n_configs:
            raise TableError(f"configuration {config} not in table (n_configs={self.n_configs})")
        idx: list[tuple[int, int]] = []
        ts: list[float] = []
        for k, a in enumerate(self.axes):
            u = (p[k] - a.start) / a.step
            if a.periodic:
                u = u % a.count
                i0 = int(np.floor(u))
                i0 = min(i0, a.count - 1)
                t = u - i0
                idx.append((i0, (i0 + 1) % a.count))
            elif a.count == 1:
                idx.append((0, 0))
                t = 0.0
            else:
                if not -1e-6 <= u <= a.count - 1 + 1e-6:
                    raise TableRangeError(
                        f"coordinate {k} = {p[k]:.6g} outside the table axis "
                        f"[{a.start:.6g}, {a.start + a.step * (a.count - 1):.6g}]")
                u = min(max(u, 0.0), a.count - 1.0)
                i0 = min(int(np.floor(u)), a.count - 2)
                t = u - i0
                idx.append((i0, i0 + 1))
            ts.append(float(t))
        out = np.zeros(self.n_joints)
        vals = self.values[config]
        n = len(self.axes)
        for corner in range(1 << n):
            w = 1.0
            node = []
            for k in range(n):
                hi = (corner >> k) & 1
                w *= ts[k] if hi else 1.0 - ts[k]
                node.append(idx[k][hi])
            if w != 0.0:
                out += w * vals[tuple(node)].astype(float)
        return out


# --------------------------------------------------------------------------------------------
# status objects for slow actions
# --------------------------------------------------------------------------------------------


class CommandStatus:
    """Status of one acknowledged command (ophyd ``StatusBase`` style).

    Resolves when ``done_seq`` equals its sequence number (success) or ``error_seq`` does
    (failure, typed error). Polling happens in :meth:`wait`, :attr:`done` and :meth:`exception`.
    """

    def __init__(self, controller: "ModbusController", seq: int, command: Command, target: Any = None):
        self.controller = controller
        self.seq = int(seq)
        self.command = command
        self.target = target
        self._done = False
        self._exc: BaseException | None = None
        self._lock = threading.Lock()

    def _poll(self) -> None:
        with self._lock:
            if self._done:
                return
            self.controller._check_link()
            st = self.controller.status()
            if st.done_seq == self.seq:
                self._done = True
            elif st.error_seq == self.seq:
                self._exc = self.controller._error_for(st, self.seq, self.command, self.target)
                self._done = True

    @property
    def done(self) -> bool:
        """True once resolved (success or failure); polls the controller once if still pending."""
        self._poll()
        return self._done

    @property
    def success(self) -> bool:
        return self.done and self._exc is None

    def exception(self) -> BaseException | None:
        """The typed error if the command failed, else None (polls once if pending)."""
        self._poll()
        return self._exc

    def wait(self, timeout: float) -> None:
        """Block until resolved; raise the command's typed error, or :class:`MotionTimeout`."""
        if timeout is None or not timeout > 0:
            raise ValueError("wait() needs a positive timeout in seconds")
        deadline = time.monotonic() + timeout
        while True:
            self._poll()
            if self._done:
                if self._exc is not None:
                    raise self._exc
                return
            if time.monotonic() >= deadline:
                raise MotionTimeout(
                    f"{self.command.name} seq {self.seq} not finished within {timeout:.3g} s; the robot "
                    f"may still be moving: wait again, or call stop() and check the robot")
            time.sleep(self.controller.poll_interval)

    def __repr__(self) -> str:
        state = "pending" if not self._done else ("failed" if self._exc else "done")
        return f"<{type(self).__name__} {self.command.name} seq={self.seq} {state}>"


class MotionStatus(CommandStatus):
    """Status of a motion command."""


# --------------------------------------------------------------------------------------------
# the driver
# --------------------------------------------------------------------------------------------


class ModbusController:
    """Robot controller on Modbus TCP.

    ``client`` may inject a pymodbus-compatible client (tests); otherwise a
    ``ModbusTcpClient(host, port=port, timeout=timeout, retries=0)`` is created.
    """

    poll_interval = 0.002

    def __init__(self, host: str, port: int, device_id: int = 1,
                 word_order: WordOrder = WordOrder.BIG, timeout: float = 1.0,
                 heartbeat_period: float | None = 0.2, link_timeout: float | None = None,
                 ack_timeout: float = 1.0, command_timeout: float = 5.0, client: Any = None):
        if not isinstance(word_order, WordOrder):
            raise ValueError(f"word_order must be WordOrder.BIG or WordOrder.LITTLE, got {word_order!r}")
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
        self._seq = 0
        self._n_joints = 0
        self._soft_limits: np.ndarray | None = None
        self._pending: CommandStatus | None = None
        self._link_lost: str | None = None
        self._hb_thread: threading.Thread | None = None
        self._hb_stop = threading.Event()
        self._hb_counter = 0
        self._hb_last_error: BaseException | None = None
        self._uploaded: CorrectionTableData | None = None
        self._readback_ok = False
        self._readback_problem = "the uploaded table was not read back yet: call read_table()"
        self._connected = False

    # -- low level I/O ---------------------------------------------------------------------
    def _call(self, fn: Callable, fc: int, address: int, n_regs: int, **kw) -> Any:
        with self._io_lock:
            try:
                rr = fn(address, device_id=self.device_id, **kw)
            except ConnectionException as exc:
                raise ControllerConnectionError(
                    f"no connection to the controller at {self.host}:{self.port} ({exc}): check the "
                    f"network and that the robot program runs; the next call reconnects") from exc
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
        if rr.isError():
            raise ModbusExceptionError(getattr(rr, "exception_code", 0), fc, address, n_regs)
        return rr

    def _read(self, address: int, count: int) -> list[int]:
        out: list[int] = []
        step = 124  # even, <= 125
        for a in range(address, address + count, step):
            n = min(step, address + count - a)
            rr = self._call(self._client.read_holding_registers, 3, a, n, count=n)
            regs = list(rr.registers)
            if len(regs) != n:
                raise RegisterDecodeError(f"asked for {n} registers at {a}, controller returned {len(regs)}")
            out += regs
        return out

    def _write(self, address: int, values: Sequence[int]) -> None:
        values = list(values)
        step = 122  # even, <= 123
        for i in range(0, len(values), step):
            chunk = values[i:i + step]
            self._call(self._client.write_registers, 16, address + i, len(chunk), values=chunk)

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
        version = self._read_entry("map_version")
        if version != MAP_VERSION:
            raise ControllerError(
                f"controller register map version {version}, driver expects {MAP_VERSION}: update the "
                f"robot program or the driver so that both use the same map")
        g = self._read_entry("n_joints")
        if not 1 <= g <= MAX_JOINTS:
            raise ControllerError(f"controller reports {g} joints; supported are 1..{MAX_JOINTS}")
        self._n_joints = int(g)
        lim = self._read_entry("soft_limits")
        self._soft_limits = np.asarray(lim[:2 * g], dtype=float).reshape(g, 2)
        self._seq = int(self._read_entry("cmd_seq"))
        self._link_lost = None
        self._pending = None
        self._connected = True
        if self.heartbeat_period:
            self._heartbeat_once()  # the controller sees a live PC before the first command
            self._start_heartbeat()
        return self

    def close(self) -> None:
        """Stop the heartbeat and close the socket (pending motions are not stopped)."""
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

    # -- heartbeat -------------------------------------------------------------------------
    def _start_heartbeat(self) -> None:
        self._hb_stop.clear()
        self._hb_thread = threading.Thread(target=self._heartbeat_loop, name="controller-heartbeat",
                                           daemon=True)
        self._hb_thread.start()

    def _stop_heartbeat(self) -> None:
        self._hb_stop.set()
        t = self._hb_thread
        if t is not None and t is not threading.current_thread():
            t.join(timeout=max(2.0, 2 * self.timeout))
        self._hb_thread = None

    def _heartbeat_loop(self) -> None:
        last_robot: int | None = None
        last_change = time.monotonic()
        period = float(self.heartbeat_period or 0.2)
        while not self._hb_stop.wait(period):
            try:
                hb = self._heartbeat_once()
                if hb != last_robot:
                    last_robot = hb
                    last_change = time.monotonic()
            except ControllerError as exc:
                # Recorded, reported as the cause if the link is declared lost.
                self._hb_last_error = exc
                log.warning("heartbeat exchange failed: %s", exc)
            silent = time.monotonic() - last_change
            if silent > self.link_timeout:
                cause = f" (last error: {self._hb_last_error})" if self._hb_last_error else ""
                self._link_lost = (
                    f"controller heartbeat did not advance for {silent:.2f} s (limit "
                    f"{self.link_timeout:.2f} s){cause}: the robot program or the link is down; check "
                    f"the robot, then call connect() again")
                log.error(self._link_lost)
                return

    def _heartbeat_once(self) -> int:
        """Advance and write the PC heartbeat; return the robot heartbeat."""
        self._hb_counter = (self._hb_counter + 1) & 0xFFFF
        self._write(REG["hb_pc"].address, [self._hb_counter])
        return int(self._read(REG["hb_robot"].address, 1)[0])

    @property
    def link_lost(self) -> str | None:
        """Reason the link was declared lost, or None."""
        return self._link_lost

    def _check_link(self) -> None:
        if self._link_lost is not None:
            raise ControllerLinkLost(self._link_lost)

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
        return np.asarray(self._read_entry("act_pose"), dtype=float)

    def soft_limits(self) -> np.ndarray:
        """Soft limits ``(g, 2)`` [lower, upper] as read at connect()."""
        if self._soft_limits is None:
            raise ControllerConnectionError("not connected: call connect() first")
        return self._soft_limits.copy()

    # -- commands --------------------------------------------------------------------------
    def _next_seq(self) -> int:
        return self._seq % 0xFFFF + 1

    def _send(self, code: Command, *, elbow: int = 0, speed: float = 0.0,
              joints: Sequence[float] | None = None, pose: Sequence[float] | None = None,
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
            jj = np.zeros(MAX_JOINTS)
            if joints is not None:
                jj[:len(joints)] = joints
            pp = np.zeros(6) if pose is None else np.asarray(pose, dtype=float)
            regs += encode("cmd_joints", jj, o)
            regs += encode("cmd_pose", pp, o)
            first = REG["cmd_code"].address
            self._seq = seq  # consumed even if the write fails: never reuse a number
            try:
                self._write(first, regs)
            except ControllerConnectionError as exc:
                raise ControllerConnectionError(
                    f"{code.name} seq {seq}: the write of the command got no valid response ({exc}); the "
                    f"command was NOT re-sent and may or may not have reached the controller: read "
                    f"status() and check the robot before commanding again") from exc
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

    def move_joints(self, q: Sequence[float], speed: float = 0.5) -> MotionStatus:
        """Joint move (not corrected by a correction table). Returns an acknowledged status."""
        q = np.asarray(q, dtype=float).ravel()
        if q.size != self._n_joints:
            raise ValueError(f"controller has {self._n_joints} joints, got {q.size} values")
        if not np.all(np.isfinite(q)):
            raise ValueError("joint targets contain NaN or infinity")
        self._check_speed(speed)
        self._check_no_pending_motion()
        st = self._send(Command.MOVE_JOINTS, speed=speed, joints=q, status_cls=MotionStatus, target=q)
        self._pending = st
        return st  # type: ignore[return-value]

    def move_cartesian(self, pose6: Sequence[float], elbow: int = 1, speed: float = 0.5) -> MotionStatus:
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
    def upload_table(self, table: CorrectionTableData) -> None:
        """Write header and values into the controller's staging area (chunked writes)."""
        if not isinstance(table, CorrectionTableData):
            raise TypeError("upload_table needs a CorrectionTableData")
        if self._n_joints and table.n_joints != self._n_joints:
            raise TableError(f"table has {table.n_joints} joint corrections, controller {self._n_joints} joints")
        self._check_link()
        self._uploaded = None
        self._readback_ok = False
        self._readback_problem = "the uploaded table was not read back yet: call read_table()"
        self._write(_HDR_FIRST, table.header_registers(self.word_order))
        self._write(TABLE_DATA_ADDRESS, table.data_registers(self.word_order))
        self._uploaded = table

    def read_table(self) -> CorrectionTableData:
        """Read header and values back from the staging area. If a table was uploaded in this
        session, compare value by value; the result gates :meth:`activate_table`."""
        self._check_link()
        header = self._read(_HDR_FIRST, _HDR_COUNT)
        try:
            h = CorrectionTableData.decode_header(header, self.word_order)
            data = self._read(TABLE_DATA_ADDRESS, 2 * h["n_values"])
            table = CorrectionTableData.from_registers(header, data, self.word_order)
        except ControllerError as exc:
            if self._uploaded is not None:
                self._readback_ok = False
                self._readback_problem = f"read-back failed: {exc}"
            raise
        if self._uploaded is not None:
            diff = self._uploaded.first_difference(table)
            if diff is None and h["crc"] != self._uploaded.crc32():
                diff = f"header CRC {h['crc']:#010x} != uploaded {self._uploaded.crc32():#010x}"
            self._readback_ok = diff is None
            self._readback_problem = "" if diff is None else f"read-back differs from upload: {diff}"
        return table

    def verify_table(self) -> CorrectionTableData:
        """read_table() and raise :class:`TableVerifyError` if it differs from the upload."""
        if self._uploaded is None:
            raise TableVerifyError("no table uploaded in this session: call upload_table() first")
        table = self.read_table()
        if not self._readback_ok:
            raise TableVerifyError(self._readback_problem + ": upload the table again")
        return table

    def _table_command(self, code: Command, timeout: float | None) -> None:
        self._send(code).wait(timeout or self.command_timeout)

    def stage_table(self, timeout: float | None = None) -> None:
        """Controller checks header and CRC of the staging area and keeps it as staged table."""
        self._table_command(Command.TABLE_STAGE, timeout)

    def activate_table(self, timeout: float | None = None) -> None:
        """Activate the staged table. Refused (:class:`TableVerifyError`) unless the last upload
        was read back identical and the controller's staged CRC equals the uploaded CRC."""
        if self._uploaded is None:
            raise TableVerifyError("no table uploaded in this session: upload, read back, stage, then activate")
        if not self._readback_ok:
            raise TableVerifyError(f"activation refused: {self._readback_problem}")
        crc = self._uploaded.crc32()
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

    def table_crcs(self) -> dict[str, int]:
        """CRC-32 of the staged, active and previous tables on the controller (0 = none)."""
        return {k: int(self._read_entry(f"table_{k}_crc")) for k in ("staged", "active", "previous")}

    # -- error mapping ---------------------------------------------------------------------
    def _error_for(self, st: ControllerStatus, seq: int, command: Command, target: Any) -> ControllerError:
        code = st.error_code
        msg = f"{command.name} seq {seq}: {_error_message(code)}"
        try:
            ec = ErrorCode(code)
        except ValueError:
            return CommandRejected(msg, code, seq)
        if ec is ErrorCode.SOFT_LIMIT:
            j = st.error_joint
            side = {-1: "lower", 1: "upper"}.get(st.error_bound, "a")
            detail = f"joint {j} violates its {side} soft limit"
            if self._soft_limits is not None and 1 <= j <= len(self._soft_limits) and st.error_bound in (-1, 1):
                lim = self._soft_limits[j - 1, 0 if st.error_bound < 0 else 1]
                detail += f" {lim:.6g}"
                if command is Command.MOVE_JOINTS and target is not None and j <= len(target):
                    detail += f" (target {float(target[j - 1]):.6g})"
            return MotionRejected(f"{command.name} seq {seq}: {detail}: choose a target inside the limits",
                                  code, seq)
        if ec in (ErrorCode.UNREACHABLE, ErrorCode.TARGET_OUTSIDE_TABLE, ErrorCode.NOT_READY,
                  ErrorCode.BAD_COMMAND):
            return MotionRejected(msg, code, seq)
        if ec is ErrorCode.ESTOP:
            return EmergencyStop(msg, code, seq)
        if ec is ErrorCode.DRIVE_FAULT:
            return DriveFault(f"{msg} (axis {st.error_joint})", code, seq)
        if ec is ErrorCode.MOTION_ABORTED:
            return MotionAborted(msg, code, seq)
        if ec is ErrorCode.SEQUENCE_ERROR:
            return SequenceError(msg + "; reconnect (connect()) to resynchronise", code, seq)
        if ec is ErrorCode.WATCHDOG_TIMEOUT:
            return ControllerLinkLost(msg)
        if ec in (ErrorCode.TABLE_CRC_MISMATCH, ErrorCode.TABLE_NOT_STAGED, ErrorCode.TABLE_SHAPE_INVALID,
                  ErrorCode.NO_PREVIOUS_TABLE):
            return TableError(msg)
        return CommandRejected(msg, code, seq)
