"""Register map of the robot-controller link (Modbus TCP, holding registers only).

This module is the single source of truth for the wire protocol between the station PC and the
robot-controller program. The driver (:mod:`drivers.controller`) and the simulated controller
(:mod:`simulators.controller_server`) both import it; ``docs/protocols.md`` documents it.

Conventions
-----------
* Every address is a 0-based holding-register address as sent on the wire (function codes 3, 6
  and 16).
* 32-bit values (``u32``, ``i32``, ``f32``) span two consecutive registers. The order of the two
  16-bit words is **not** standardised, so it is configurable (:class:`WordOrder`); within a word
  the bytes are big-endian as Modbus prescribes.
* Units inside the protocol are mm and rad (prismatic joints in mm). ``scale`` converts a raw
  integer to the engineering value: ``value = raw * scale``.
* ``access`` is from the PC's point of view: ``"rw"`` the PC writes (and may read back), ``"r"``
  the controller writes and the PC only reads. The simulator refuses PC writes to ``"r"`` entries
  with Modbus exception 2 (illegal data address).

Nothing in here knows about the station; it must not import ``station``.
"""

from __future__ import annotations

import enum
import struct
from dataclasses import dataclass
from typing import Iterable, Sequence

import numpy as np

__all__ = [
    "MAP_VERSION",
    "SUPPORTED_MAP_VERSIONS",
    "implausible_limits",
    "MAX_JOINTS",
    "MAX_TABLE_AXES",
    "MAX_TABLE_VALUES",
    "TABLE_FORMAT_VERSION",
    "WordOrder",
    "RegType",
    "Register",
    "REGISTERS",
    "REG",
    "Command",
    "ErrorCode",
    "ERROR_MESSAGES",
    "StatusBit",
    "ControllerError",
    "RegisterDecodeError",
    "encode",
    "decode",
    "encode_f32_array",
    "decode_f32_array",
    "registers_per_value",
    "register_span",
    "MODBUS_EXCEPTION_MEANINGS",
    "TABLE_HEADER_FIRST",
    "TABLE_HEADER_LAST",
    "TABLE_DATA_ADDRESS",
    "MAX_READ_REGISTERS",
    "MAX_WRITE_REGISTERS",
]

#: Version of this register map, readable at ``map_version``.
MAP_VERSION = 1
#: Map versions the driver can talk to (it refuses a controller that reports another).
SUPPORTED_MAP_VERSIONS: tuple[int, ...] = (MAP_VERSION,)
#: Joint count the command / response blocks are sized for.
MAX_JOINTS = 6
#: Correction-table axes the header is sized for (x, y, z, yaw of the Cartesian target).
MAX_TABLE_AXES = 4
#: Format version of the correction table written to ``table_format``.
TABLE_FORMAT_VERSION = 1
#: First register of the flat correction-table data area (f32 values, 2 registers each).
TABLE_DATA_ADDRESS = 1000
#: Capacity of the data area in f32 values (addresses 1000 .. 1000 + 2*MAX_TABLE_VALUES - 1).
MAX_TABLE_VALUES = 32000
#: Modbus limits per request (FC 3: 125 registers, FC 16: 123 registers).
MAX_READ_REGISTERS = 125
MAX_WRITE_REGISTERS = 123


class WordOrder(enum.Enum):
    """Order of the two 16-bit words of a 32-bit value.

    ``BIG``: most significant word first (register n holds bits 31..16, "ABCD").
    ``LITTLE``: least significant word first (register n holds bits 15..0, "CDAB").
    """

    BIG = "big"
    LITTLE = "little"


class RegType(enum.Enum):
    U16 = "u16"
    I16 = "i16"
    U32 = "u32"
    I32 = "i32"
    F32 = "f32"


_STRUCT = {
    RegType.U16: (">H", 1),
    RegType.I16: (">h", 1),
    RegType.U32: (">I", 2),
    RegType.I32: (">i", 2),
    RegType.F32: (">f", 2),
}


def registers_per_value(t: RegType) -> int:
    """Registers one value of type ``t`` occupies."""
    return _STRUCT[t][1]


class ControllerError(Exception):
    """Base of every error of the robot-controller driver (re-exported by drivers.controller)."""


class RegisterDecodeError(ControllerError, ValueError):
    """Register contents that cannot be decoded (wrong count, out-of-range word).

    Raised by every decoder here. It means the controller sent something that does not fit the
    register map: check the word order setting and the controller program's map version.
    """


@dataclass(frozen=True)
class Register:
    """One entry of the map: ``count`` values of ``type`` starting at ``address``."""

    name: str
    address: int
    type: RegType
    count: int
    scale: float
    unit: str
    access: str  # "rw" (PC writes) or "r" (controller writes, PC reads)
    meaning: str

    @property
    def n_registers(self) -> int:
        return self.count * registers_per_value(self.type)

    @property
    def end(self) -> int:
        """One past the last register address."""
        return self.address + self.n_registers


def _r(name, address, type_, count=1, scale=1.0, unit="", access="r", meaning=""):
    return Register(name, address, RegType(type_), count, scale, unit, access, meaning)


#: The register map. Addresses not listed are invalid (exception 2 on access).
REGISTERS: tuple[Register, ...] = (
    # --- identification and heartbeats ------------------------------------------------------
    _r("hb_pc", 0, "u16", access="rw",
       meaning="PC heartbeat counter; the PC increments it every heartbeat period (wraps 65535->0)"),
    _r("hb_robot", 1, "u16",
       meaning="controller heartbeat counter; the robot program increments it every period"),
    _r("map_version", 2, "u16", meaning="version of this register map (1)"),
    _r("n_joints", 3, "u16", meaning="number of joints g of the robot (<= 6)"),
    _r("watchdog_ms", 4, "u16", unit="ms",
       meaning="controller watchdog: a move is stopped if hb_pc does not change for this long"),
    # --- command block (PC -> robot), written in ONE request (FC 16) ------------------------
    _r("cmd_code", 10, "u16", access="rw", meaning="command code (see Command)"),
    _r("cmd_seq", 11, "u16", access="rw",
       meaning="sequence number of the command, 1..65535, previous+1 (wraps to 1)"),
    _r("cmd_elbow", 12, "i16", access="rw",
       meaning="configuration flag for Cartesian moves: +1 elbow with phi2>0, -1 phi2<0"),
    _r("cmd_speed", 13, "u16", scale=0.001, access="rw",
       meaning="speed as a fraction of the maximum joint speeds, raw 1..1000"),
    _r("cmd_joints", 14, "f32", count=MAX_JOINTS, unit="rad or mm", access="rw",
       meaning="target joints for MOVE_JOINTS (first g used)"),
    _r("cmd_pose", 26, "f32", count=6, unit="mm,rad", access="rw",
       meaning="target tool pose x,y,z,roll,pitch,yaw in the robot base frame for MOVE_CARTESIAN"),
    # --- response block (robot -> PC) --------------------------------------------------------
    _r("ack_seq", 40, "u16", meaning="sequence number of the last command acknowledged"),
    _r("done_seq", 41, "u16", meaning="sequence number of the last command completed successfully"),
    _r("error_seq", 42, "u16", meaning="sequence number of the last command that ended in error"),
    _r("error_code", 43, "u16", meaning="error code of the last error (see ErrorCode); 0 none or cleared by RESET"),
    _r("status", 44, "u16", meaning="status bits (see StatusBit)"),
    _r("error_joint", 45, "i16",
       meaning="joint (1-based) an error refers to, 0 if none (soft limit, non-finite target, drive fault)"),
    _r("error_bound", 46, "i16",
       meaning="soft-limit side of a SOFT_LIMIT error: -1 lower, +1 upper, 0 n/a"),
    _r("act_joints", 48, "f32", count=MAX_JOINTS, unit="rad or mm",
       meaning="actual joint values (encoders)"),
    _r("act_pose", 60, "f32", count=6, unit="mm,rad",
       meaning="actual tool pose from the controller's NOMINAL forward kinematics, base frame"),
    _r("soft_limits", 72, "f32", count=2 * MAX_JOINTS, unit="rad or mm",
       meaning="soft limits per joint: lower_1, upper_1, lower_2, upper_2, ..."),
    # --- correction table: staging header (PC writes) ---------------------------------------
    _r("table_format", 100, "u16", access="rw", meaning="table format version (1)"),
    _r("table_n_axes", 101, "u16", access="rw", meaning="number of grid axes, 1..4"),
    _r("table_shape", 102, "u16", count=MAX_TABLE_AXES, access="rw",
       meaning="node count per axis (unused axes 0)"),
    _r("table_start", 106, "f32", count=MAX_TABLE_AXES, unit="mm or rad", access="rw",
       meaning="coordinate of node 0 per axis"),
    _r("table_step", 114, "f32", count=MAX_TABLE_AXES, unit="mm or rad", access="rw",
       meaning="node spacing per axis (> 0)"),
    _r("table_periodic", 122, "u16", access="rw",
       meaning="bit i set: axis i wraps with period shape[i]*step[i]"),
    _r("table_n_joints", 123, "u16", access="rw", meaning="joint corrections per node (= g)"),
    _r("table_n_configs", 124, "u16", access="rw",
       meaning="configurations (1, or 2: index 0 elbow=+1, 1 elbow=-1)"),
    _r("table_n_values", 125, "u32", access="rw",
       meaning="number of f32 values = n_configs * prod(shape) * n_joints"),
    _r("table_crc", 127, "u32", access="rw",
       meaning="CRC-32 (zlib/ISO-HDLC) over the values as big-endian IEEE-754 f32 bytes"),
    # --- correction table: controller side (read only) --------------------------------------
    _r("table_staged_crc", 130, "u32", meaning="CRC-32 of the staged table (0 if none)"),
    _r("table_active_crc", 132, "u32", meaning="CRC-32 of the active table (0 if none)"),
    _r("table_previous_crc", 134, "u32", meaning="CRC-32 of the table kept for roll back (0 if none)"),
    # --- correction table data (PC writes, flat area) ---------------------------------------
    _r("table_data", TABLE_DATA_ADDRESS, "f32", count=MAX_TABLE_VALUES, unit="rad or mm", access="rw",
       meaning="table values, C order (config, axis 0, ..., axis n-1, joint)"),
)

#: Look-up by name.
REG: dict[str, Register] = {r.name: r for r in REGISTERS}

TABLE_HEADER_FIRST = REG["table_format"].address
TABLE_HEADER_LAST = REG["table_crc"].end  # one past


def _check_map() -> None:
    spans = sorted((r.address, r.end, r.name) for r in REGISTERS)
    for (_a0, e0, n0), (a1, _e1, n1) in zip(spans, spans[1:]):
        if a1 < e0:
            raise AssertionError(f"register map overlap: {n0} and {n1}")
    if spans[-1][1] > 65536:
        raise AssertionError("register map exceeds the 16-bit address space")


_check_map()


def register_span(first: str, last: str) -> tuple[int, int]:
    """``(address, count)`` of the contiguous block from entry ``first`` to entry ``last``."""
    a = REG[first].address
    return a, REG[last].end - a


class Command(enum.IntEnum):
    """Command codes written to ``cmd_code``."""

    NONE = 0
    MOVE_JOINTS = 1
    MOVE_CARTESIAN = 2
    STOP = 3
    RESET = 4
    TABLE_STAGE = 10
    TABLE_ACTIVATE = 11
    TABLE_DEACTIVATE = 12
    TABLE_ROLLBACK = 13


class ErrorCode(enum.IntEnum):
    """Error codes reported in ``error_code`` together with ``error_seq``."""

    NONE = 0
    SOFT_LIMIT = 1
    UNREACHABLE = 2
    ESTOP = 3
    DRIVE_FAULT = 4
    BAD_COMMAND = 5
    SEQUENCE_ERROR = 6
    TABLE_CRC_MISMATCH = 7
    TABLE_NOT_STAGED = 8
    TABLE_SHAPE_INVALID = 9
    TARGET_OUTSIDE_TABLE = 10
    WATCHDOG_TIMEOUT = 11
    NOT_READY = 12
    MOTION_ABORTED = 13
    NO_PREVIOUS_TABLE = 14


ERROR_MESSAGES: dict[ErrorCode, str] = {
    ErrorCode.NONE: "no error",
    ErrorCode.SOFT_LIMIT: "target violates a soft limit (error_joint / error_bound say which)",
    ErrorCode.UNREACHABLE: "Cartesian target not reachable with the requested elbow configuration",
    ErrorCode.ESTOP: "emergency stop: release the e-stop, check the cell, then reset the error",
    ErrorCode.DRIVE_FAULT: "drive fault (error_joint says which axis): check the drive, then reset",
    ErrorCode.BAD_COMMAND: "unknown command code or invalid argument (speed, elbow, a target that "
                           "is not a finite number - error_joint says which joint -, or busy)",
    ErrorCode.SEQUENCE_ERROR: "sequence number is not previous+1; resynchronise from ack_seq",
    ErrorCode.TABLE_CRC_MISMATCH: "staged table values do not match the header CRC-32: re-upload",
    ErrorCode.TABLE_NOT_STAGED: "no staged table: upload and stage (TABLE_STAGE) before activating",
    ErrorCode.TABLE_SHAPE_INVALID: "table header invalid (axes, shape, step, joints, configs, size)",
    ErrorCode.TARGET_OUTSIDE_TABLE: "Cartesian target lies outside the active correction table grid",
    ErrorCode.WATCHDOG_TIMEOUT: "PC heartbeat stopped during a move: motion stopped; reset the error",
    ErrorCode.NOT_READY: "controller has a latched error: reset it (RESET) before moving",
    ErrorCode.MOTION_ABORTED: "motion aborted by a STOP command",
    ErrorCode.NO_PREVIOUS_TABLE: "roll back requested but no previous table is kept",
}


class StatusBit(enum.IntFlag):
    """Bits of the ``status`` register."""

    READY = 1 << 0
    MOVING = 1 << 1
    IN_POSITION = 1 << 2
    ERROR = 1 << 3
    ESTOP = 1 << 4
    TABLE_ACTIVE = 1 << 5
    TABLE_STAGED = 1 << 6
    TABLE_PREVIOUS = 1 << 7


#: Meanings of Modbus exception codes (Modbus Application Protocol v1.1b3, section 7).
MODBUS_EXCEPTION_MEANINGS: dict[int, str] = {
    1: "illegal function (the controller does not support this function code)",
    2: "illegal data address (register not in the controller's map, or read-only)",
    3: "illegal data value (value or register count not accepted)",
    4: "server device failure (the controller program failed while handling the request)",
    5: "acknowledge (long operation accepted, poll for completion)",
    6: "server device busy (retry later)",
    7: "negative acknowledge",
    8: "memory parity error",
    10: "gateway path unavailable",
    11: "gateway target device failed to respond",
}


# --------------------------------------------------------------------------------------------
# encoding / decoding
# --------------------------------------------------------------------------------------------


def _split32(b: bytes, order: WordOrder) -> list[int]:
    hi = (b[0] << 8) | b[1]
    lo = (b[2] << 8) | b[3]
    return [hi, lo] if order is WordOrder.BIG else [lo, hi]


def _join32(regs: Sequence[int], order: WordOrder) -> bytes:
    hi, lo = (regs[0], regs[1]) if order is WordOrder.BIG else (regs[1], regs[0])
    return bytes(((hi >> 8) & 0xFF, hi & 0xFF, (lo >> 8) & 0xFF, lo & 0xFF))


def _check_regs(regs: Sequence[int], n: int, what: str) -> list[int]:
    try:
        regs = [int(r) for r in regs]
    except (TypeError, ValueError) as exc:
        raise RegisterDecodeError(f"{what}: register contents are not integers: {exc}") from exc
    if len(regs) != n:
        raise RegisterDecodeError(f"{what}: expected {n} registers, got {len(regs)}")
    for r in regs:
        if not 0 <= r <= 0xFFFF:
            raise RegisterDecodeError(f"{what}: register value {r} outside 0..65535")
    return regs


def encode(reg: Register | str, values, order: WordOrder = WordOrder.BIG) -> list[int]:
    """Engineering value(s) -> register words for entry ``reg``.

    ``values`` is a scalar for ``count == 1`` or a sequence of at most ``count`` values (shorter
    sequences encode a prefix of the entry). Integers are ``round(value / scale)`` and must fit
    the type, else ``ValueError``.
    """
    if isinstance(reg, str):
        reg = REG[reg]
    vals = np.atleast_1d(np.asarray(values, dtype=float))
    if vals.ndim != 1 or vals.size > reg.count:
        raise ValueError(f"{reg.name}: expected at most {reg.count} values, got shape {vals.shape}")
    fmt, _n = _STRUCT[reg.type]
    out: list[int] = []
    for v in vals:
        if reg.type is RegType.F32:
            if not np.isfinite(v):
                raise ValueError(f"{reg.name}: non-finite value {v} cannot be sent")
            b = struct.pack(fmt, float(v))
        else:
            raw = int(round(float(v) / reg.scale))
            try:
                b = struct.pack(fmt, raw)
            except struct.error as exc:
                raise ValueError(f"{reg.name}: value {v} (raw {raw}) does not fit {reg.type.value}") from exc
        if len(b) == 2:
            out.append((b[0] << 8) | b[1])
        else:
            out.extend(_split32(b, order))
    return out


def decode(reg: Register | str, regs: Sequence[int], order: WordOrder = WordOrder.BIG):
    """Register words -> engineering value(s): a float/int for ``count == 1``, else ndarray.

    Raises :class:`RegisterDecodeError` for a wrong number of words or words outside 0..65535.
    """
    if isinstance(reg, str):
        reg = REG[reg]
    regs = _check_regs(regs, reg.n_registers, reg.name)
    fmt, n = _STRUCT[reg.type]
    vals = []
    for i in range(reg.count):
        w = regs[i * n:(i + 1) * n]
        b = bytes(((w[0] >> 8) & 0xFF, w[0] & 0xFF)) if n == 1 else _join32(w, order)
        raw = struct.unpack(fmt, b)[0]
        if reg.type is RegType.F32:
            vals.append(float(raw))
        elif reg.scale == 1.0:
            vals.append(int(raw))
        else:
            vals.append(raw * reg.scale)
    if reg.count == 1:
        return vals[0]
    return np.asarray(vals, dtype=float)


def encode_f32_array(values: Iterable[float] | np.ndarray, order: WordOrder = WordOrder.BIG) -> list[int]:
    """Flat f32 array -> registers (2 per value), vectorised."""
    a = np.ascontiguousarray(np.asarray(values, dtype=">f4").ravel())
    if not np.all(np.isfinite(a)):
        raise ValueError("non-finite value in f32 array cannot be sent")
    w = a.view(">u2").reshape(-1, 2).astype(np.int64)
    if order is WordOrder.LITTLE:
        w = w[:, ::-1]
    return w.ravel().tolist()


def decode_f32_array(regs: Sequence[int], order: WordOrder = WordOrder.BIG) -> np.ndarray:
    """Registers (2 per value) -> float32 array."""
    try:
        w = np.asarray(regs, dtype=np.int64)
    except (TypeError, ValueError) as exc:
        raise RegisterDecodeError(f"f32 array: register contents are not integers: {exc}") from exc
    if w.ndim != 1 or w.size % 2:
        raise RegisterDecodeError(f"f32 array: expected an even number of registers, got {w.size}")
    if w.size and (w.min() < 0 or w.max() > 0xFFFF):
        raise RegisterDecodeError("f32 array: register value outside 0..65535")
    w = w.reshape(-1, 2)
    if order is WordOrder.LITTLE:
        w = w[:, ::-1]
    return np.ascontiguousarray(w.astype(">u2")).view(">f4").ravel().astype(np.float32)


#: Largest magnitude a plausible soft limit has (mm or rad); the smallest non-zero one.
PLAUSIBLE_LIMIT_MAX = 1e5
PLAUSIBLE_LIMIT_MIN = 1e-6


def implausible_limits(soft_limits: Sequence[float] | np.ndarray, n_joints: int) -> str | None:
    """Why the decoded ``soft_limits`` (lower_1, upper_1, ...) cannot be a robot's soft limits,
    or None if they can: every value finite, zero or of magnitude within
    [1e-6, 1e5] (mm or rad), and lower < upper for each of the ``n_joints`` joints.

    A 32-bit value read with the wrong word order almost never passes (its halves swap: 1.0
    becomes 2.3e-41, -2.0 becomes 6.9e-41), which is how the driver tells a word-order mismatch
    from a real limit (see ``docs/protocols.md``, "Data types and word order")."""
    v = np.asarray(soft_limits, dtype=float)[:2 * n_joints]
    if v.size != 2 * n_joints:
        return f"expected {2 * n_joints} values, got {v.size}"
    for i, x in enumerate(v):
        name = f"{'lower' if i % 2 == 0 else 'upper'}_{i // 2 + 1}"
        if not np.isfinite(x):
            return f"{name} = {x}"
        if x != 0.0 and not PLAUSIBLE_LIMIT_MIN <= abs(x) <= PLAUSIBLE_LIMIT_MAX:
            return f"{name} = {x:.6g}"
    for j in range(n_joints):
        if not v[2 * j] < v[2 * j + 1]:
            return f"joint {j + 1}: lower {v[2 * j]:.6g} is not below upper {v[2 * j + 1]:.6g}"
    return None
