"""Register map 3 of the robot-controller link (Modbus TCP, holding registers only).

This module is the single source of truth for the wire protocol between the station PC and the
robot-controller program. The driver (:mod:`drivers.controller`), the simulated controller
(:mod:`simulators.controller_server`) and the robot programs follow it; ``docs/protocols.md``
documents it.

Conventions
-----------
* Every register of the map lies in ONE window of :data:`WINDOW_SIZE` (128) consecutive 16-bit
  holding registers. ``Register.address`` is the offset 0..127 inside the window; on the wire
  the address is ``register_base + offset`` (``[devices] controller_register_base``: 0 by
  default, 128 for the general-purpose registers of a Universal Robots controller).
* Function codes: 3 and 4 (read), 6 and 16 (write). Nothing else.
* 32-bit values (``u32``, ``i32``) span two consecutive registers. The order of the two words is
  configurable (:class:`WordOrder`); within a word the bytes are big-endian as Modbus prescribes.
  Lengths and angles are **scaled two's-complement integers** (``value = raw * scale``), never
  IEEE-754 floats: a robot program (URScript, SPEL+) can rebuild an integer from two 16-bit
  words, but not reinterpret them as a float.
* Units inside the protocol are mm and rad (prismatic joints in mm).
* ``access`` is from the PC's point of view: ``"rw"`` the PC writes (and may read back), ``"r"``
  the controller writes and the PC only reads. The simulator refuses PC writes to ``"r"`` entries
  with Modbus exception 2 (illegal data address).
* What does not fit the window travels through the transfer block (offsets 63..127): the
  correction table in pages (:data:`XferOp`), and the info pages (soft limits, actual pose).
* One station per controller (map 3): the claim block (offsets 24..35; ``docs/protocols.md``).
  The program grants ``claim_request`` only while ``claim_owner`` is 0 and ``hb_pc`` is live,
  refuses every command but STOP whose ``cmd_token`` is not the owner's (``NOT_CLAIMED``), and
  frees the claim on :func:`release_code` or when ``hb_pc`` is silent for ``watchdog_ms``.

Nothing in here knows about the station; it must not import ``station``.
"""

from __future__ import annotations

import enum
import struct
import zlib
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .controller_plausibility import implausible_limits

__all__ = [
    "MAP_VERSION",
    "release_code",
    "SUPPORTED_MAP_VERSIONS",
    "WINDOW_SIZE",
    "ORDER_CHECK_VALUE",
    "implausible_limits",
    "MAX_JOINTS",
    "MAX_TABLE_AXES",
    "MAX_TABLE_VALUES",
    "TABLE_FORMAT_VERSION",
    "JOINT_SCALE",
    "TABLE_VALUE_SCALE",
    "TABLE_AXIS_SCALE",
    "PAGE_DATA_REGISTERS",
    "PAGE_VALUES",
    "WordOrder",
    "RegType",
    "Register",
    "REGISTERS",
    "REG",
    "INFO_PAGES",
    "Command",
    "XferOp",
    "CorrectionState",
    "ErrorCode",
    "ERROR_MESSAGES",
    "StatusBit",
    "ControllerError",
    "RegisterDecodeError",
    "encode",
    "decode",
    "encode_i32_array",
    "decode_i32_array",
    "quantize_values",
    "registers_crc32",
    "raw_crc32",
    "decode_i32_raw",
    "TABLE_HEADER",
    "TABLE_HDR",
    "TABLE_HEADER_REGISTERS",
    "registers_per_value",
    "register_span",
    "MODBUS_EXCEPTION_MEANINGS",
    "FUNCTION_CODES",
    "MAX_READ_REGISTERS",
    "MAX_WRITE_REGISTERS",
]

#: Version of this register map, readable at ``map_version``.
MAP_VERSION = 3
#: Map versions the driver can talk to (it refuses a controller that reports another).
SUPPORTED_MAP_VERSIONS: tuple[int, ...] = (3,)
#: Registers of the window the map occupies (offsets 0 .. WINDOW_SIZE-1 from the base).
WINDOW_SIZE = 128
#: What ``order_check`` holds: 1 read in the right word order, 65536 in the wrong one.
ORDER_CHECK_VALUE = 1
#: Joint count the command / response blocks are sized for.
MAX_JOINTS = 6
#: Correction-table axes the header is sized for (x, y, z, yaw of the Cartesian target).
MAX_TABLE_AXES = 4
#: Format version of the correction table written in the table header (2: scaled i32 values).
TABLE_FORMAT_VERSION = 2
#: Capacity of the controller's table store in values.
MAX_TABLE_VALUES = 32000
#: Scale of joints, poses and soft limits: 1e-6 rad or mm per count (range +-2147.48).
JOINT_SCALE = 1e-6
#: Scale of the table values (joint corrections): 1e-8 rad or mm per count (range +-21.47).
TABLE_VALUE_SCALE = 1e-8
#: Scale of the table axes' start and step: 1e-6 mm or rad per count.
TABLE_AXIS_SCALE = 1e-6
#: Data registers of one page (offsets 69..126); a value page holds PAGE_VALUES values.
PAGE_DATA_REGISTERS = 58
PAGE_VALUES = PAGE_DATA_REGISTERS // 2
#: Modbus limits per request (FC 3: 125 registers, FC 16: 123 registers).
MAX_READ_REGISTERS = 125
MAX_WRITE_REGISTERS = 123
#: The only function codes the map uses (read holding / input registers, write one / many).
FUNCTION_CODES: tuple[int, ...] = (3, 4, 6, 16)


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


_STRUCT = {
    RegType.U16: (">H", 1),
    RegType.I16: (">h", 1),
    RegType.U32: (">I", 2),
    RegType.I32: (">i", 2),
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
    """One entry of the map: ``count`` values of ``type`` at window offset ``address``."""

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
        """One past the last register offset."""
        return self.address + self.n_registers


def _r(name, address, type_, count=1, scale=1.0, unit="", access="r", meaning=""):
    return Register(name, address, RegType(type_), count, scale, unit, access, meaning)


_S = JOINT_SCALE
#: The register map: every entry at its offset in the window.
REGISTERS: tuple[Register, ...] = (
    # --- identification and heartbeats ------------------------------------------------------
    _r("hb_pc", 0, "u16", access="rw",
       meaning="PC heartbeat counter; the PC increments it every heartbeat period (wraps 65535->0)"),
    _r("hb_robot", 1, "u16",
       meaning="controller heartbeat counter; the robot program increments it every period"),
    _r("map_version", 2, "u16", meaning="version of this register map (3)"),
    _r("n_joints", 3, "u16", meaning="number of joints g of the robot (<= 6)"),
    _r("watchdog_ms", 4, "u16", unit="ms",
       meaning="controller watchdog: a move is stopped if hb_pc does not change for this long"),
    _r("correction_state", 5, "u16",
       meaning="the controller's own kinematic correction (see CorrectionState): 0 none, 1 vendor "
               "factory / absolute-accuracy correction on, 2 unknown"),
    _r("order_check", 6, "u32",
       meaning="constant 1 in the link's word order (reads 65536 in the other one)"),
    # --- command block (PC -> robot), written in ONE request (FC 16) ------------------------
    _r("cmd_code", 8, "u16", access="rw", meaning="command code (see Command)"),
    _r("cmd_seq", 9, "u16", access="rw",
       meaning="sequence number of the command, 1..65535, previous+1 (wraps to 1)"),
    _r("cmd_elbow", 10, "i16", access="rw",
       meaning="configuration flag for Cartesian moves: +1 elbow with phi2>0, -1 phi2<0"),
    _r("cmd_speed", 11, "u16", scale=0.001, access="rw",
       meaning="speed as a fraction of the maximum joint speeds, raw 1..1000"),
    _r("cmd_target", 12, "i32", count=MAX_JOINTS, scale=_S, unit="rad or mm; mm,rad", access="rw", meaning="the "
       "target: MOVE_JOINTS joints (first g used); MOVE_CARTESIAN the tool pose x,y,z,roll,pitch,yaw in the robot "
       "base frame (map 2 had two blocks; a command uses one)"),
    _r("cmd_token", 24, "u32", access="rw", meaning="the session token of the station that holds the controller "
       "(claim_owner); every command but STOP whose token is not the owner's is refused with NOT_CLAIMED"),
    # --- claim block: one station per controller ----------------------------------------------
    _r("claim_request", 26, "u32", access="rw",
       meaning="a station writes its token to ask for the controller, release_code(token) to give it back"),
    _r("claim_owner", 28, "u32",
       meaning="token of the station that holds the controller, 0 if free; the program grants a request only "
               "while it is 0 and hb_pc is live, and clears it when hb_pc has not changed for watchdog_ms"),
    _r("claim_host", 30, "u32", access="rw",
       meaning="IPv4 address of the holder (as its socket to the controller has it), written once granted"),
    _r("claim_pid", 32, "u32", access="rw", meaning="process id of the holder, written once granted"),
    _r("claim_since", 34, "u32", unit="s", access="rw",
       meaning="when the holder was granted the controller, UTC seconds since 1970, written once granted"),
    # --- response block (robot -> PC) --------------------------------------------------------
    _r("ack_seq", 36, "u16", meaning="sequence number of the last command acknowledged"),
    _r("done_seq", 37, "u16", meaning="sequence number of the last command completed successfully"),
    _r("error_seq", 38, "u16", meaning="sequence number of the last command that ended in error"),
    _r("error_code", 39, "u16", meaning="error code of the last error (see ErrorCode); 0 none or cleared by RESET"),
    _r("status", 40, "u16", meaning="status bits (see StatusBit)"),
    _r("error_joint", 41, "i16",
       meaning="joint (1-based) an error refers to, 0 if none (soft limit, non-finite target, drive fault)"),
    _r("error_bound", 42, "i16",
       meaning="soft-limit side of a SOFT_LIMIT error: -1 lower, +1 upper, 0 n/a"),
    _r("xfer_ack", 43, "u16",
       meaning="xfer_seq of the last transfer request the program has carried out (the page ack)"),
    _r("xfer_error", 44, "u16",
       meaning="result of that request: 0 done, else an ErrorCode (PAGE_CRC_MISMATCH, PAGE_INVALID, ...)"),
    _r("act_joints", 45, "i32", count=MAX_JOINTS, scale=_S, unit="rad or mm",
       meaning="actual joint values (encoders)"),
    _r("table_staged_crc", 57, "u32", meaning="CRC-32 of the staged table (0 if none)"),
    _r("table_active_crc", 59, "u32", meaning="CRC-32 of the active table (0 if none)"),
    _r("table_previous_crc", 61, "u32", meaning="CRC-32 of the table kept for roll back (0 if none)"),
    # --- transfer block (PC -> robot and back), written in ONE request (FC 16) --------------
    _r("xfer_seq", 63, "u16", access="rw",
       meaning="transfer request number, 1..65535, previous+1 (wraps to 1); a new value starts xfer_op"),
    _r("xfer_op", 64, "u16", access="rw", meaning="transfer operation (see XferOp)"),
    _r("page_index", 65, "u16", access="rw",
       meaning="page number: value page k holds values k*29 .. k*29+28; header and info pages by number"),
    _r("page_len", 66, "u16", access="rw", meaning="data registers of the page in use, 0..58"),
    _r("page_crc", 67, "u32", access="rw",
       meaning="CRC-32 over the first page_len data registers, each register high byte first"),
    _r("page_data", 69, "u16", count=PAGE_DATA_REGISTERS, access="rw",
       meaning="the page's data registers (header, values or info as the operation says)"),
)

#: Look-up by name.
REG: dict[str, Register] = {r.name: r for r in REGISTERS}

#: Info pages (XferOp.READ_INFO, page_index = number): their entries at offsets in page_data.
INFO_PAGES: dict[str, tuple[int, Register]] = {
    "soft_limits": (0, _r("soft_limits", 0, "i32", count=2 * MAX_JOINTS, scale=_S, unit="rad or mm",
                          meaning="soft limits per joint: lower_1, upper_1, lower_2, upper_2, ...")),
    "act_pose": (1, _r("act_pose", 0, "i32", count=6, scale=_S, unit="mm,rad",
                       meaning="actual tool pose from the controller's NOMINAL forward kinematics, base frame")),
}

#: The table header: its entries at offsets in page_data of the header page (XferOp.WRITE_HEADER).
TABLE_HEADER: tuple[Register, ...] = (
    _r("table_format", 0, "u16", access="rw", meaning="table format version (2)"),
    _r("table_n_axes", 1, "u16", access="rw", meaning="number of grid axes, 1..4"),
    _r("table_shape", 2, "u16", count=MAX_TABLE_AXES, access="rw", meaning="node count per axis (unused axes 0)"),
    _r("table_start", 6, "i32", count=MAX_TABLE_AXES, scale=TABLE_AXIS_SCALE, unit="mm or rad", access="rw",
       meaning="coordinate of node 0 per axis"),
    _r("table_step", 14, "i32", count=MAX_TABLE_AXES, scale=TABLE_AXIS_SCALE, unit="mm or rad", access="rw",
       meaning="node spacing per axis (> 0)"),
    _r("table_periodic", 22, "u16", access="rw", meaning="bit i set: axis i wraps with period shape[i]*step[i]"),
    _r("table_n_joints", 23, "u16", access="rw", meaning="joint corrections per node (= g)"),
    _r("table_n_configs", 24, "u16", access="rw", meaning="configurations (1, or 2: index 0 elbow=+1, 1 elbow=-1)"),
    _r("table_n_values", 25, "u32", access="rw", meaning="number of values = n_configs * prod(shape) * n_joints"),
    _r("table_crc", 27, "u32", access="rw",
       meaning="CRC-32 (zlib/ISO-HDLC) over the raw values as big-endian 32-bit two's complement bytes"),
    _r("table_value_scale_exp", 29, "i16", access="rw",
       meaning="decimal exponent of the value scale: -8 (1 count = 1e-8 rad or mm)"),
)
TABLE_HDR: dict[str, Register] = {r.name: r for r in TABLE_HEADER}
TABLE_HEADER_REGISTERS = TABLE_HEADER[-1].end


def _check_map() -> None:
    groups = [(REGISTERS, WINDOW_SIZE, "window"), (TABLE_HEADER, PAGE_DATA_REGISTERS, "table header page")]
    groups += [((r,), PAGE_DATA_REGISTERS, f"info page {n}") for n, r in INFO_PAGES.values()]
    for entries, size, what in groups:
        spans = sorted((r.address, r.end, r.name) for r in entries)
        for (_a0, e0, n0), (a1, _e1, n1) in zip(spans, spans[1:]):
            if a1 < e0:
                raise AssertionError(f"register map overlap: {n0} and {n1}")
        if spans[0][0] < 0 or spans[-1][1] > size:
            raise AssertionError(f"register map exceeds the {what} of {size} registers")
    if REG["page_data"].end > WINDOW_SIZE or REG["xfer_seq"].end != REG["xfer_op"].address:
        raise AssertionError("transfer block must be contiguous inside the window")


_check_map()


def release_code(token: int) -> int:
    """What the holder of ``token`` writes to ``claim_request`` to give the controller back: its
    complement ``0xFFFFFFFF - token``, which a robot program without bitwise operators computes too."""
    return 0xFFFFFFFF - int(token)


def register_span(first: str, last: str) -> tuple[int, int]:
    """``(offset, count)`` of the contiguous block from entry ``first`` to entry ``last``."""
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
    #: forget the previous table (the roll-back slot becomes empty); lets the PC put every slot
    #: back as it found it (station conformance) without leaving a table a roll back would revive
    TABLE_DISCARD_PREVIOUS = 14


class XferOp(enum.IntEnum):
    """Operations of the transfer block (``xfer_op``), started by a new ``xfer_seq``.

    WRITE_*: the PC wrote a page (index, length, CRC, data) in the same request; the program
    checks its CRC and length, stores it, and answers in ``xfer_ack``/``xfer_error``. READ_*:
    the program fills page_len, page_crc and page_data with its stored page ``page_index`` (or
    info page ``page_index``), then answers. WRITE_HEADER clears the stored value pages."""

    NONE = 0
    WRITE_HEADER = 1
    WRITE_PAGE = 2
    READ_HEADER = 3
    READ_PAGE = 4
    READ_INFO = 5
    #: the header page / value page ``page_index`` of the table in a slot, regenerated from it:
    #: the PC reads the table that is active (or previous, or staged) before it changes anything,
    #: so that a run or the conformance kit can put exactly that table back
    READ_STAGED_HEADER = 6
    READ_STAGED_PAGE = 7
    READ_ACTIVE_HEADER = 8
    READ_ACTIVE_PAGE = 9
    READ_PREVIOUS_HEADER = 10
    READ_PREVIOUS_PAGE = 11


class CorrectionState(enum.IntEnum):
    """What ``correction_state`` says about the controller's own kinematic correction."""

    NONE = 0  # nominal kinematics only: the station's correction is the only one
    VENDOR = 1  # a vendor factory calibration / absolute-accuracy option is on
    UNKNOWN = 2  # the program cannot tell


class ErrorCode(enum.IntEnum):
    """Error codes reported in ``error_code`` together with ``error_seq`` (and ``xfer_error``)."""

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
    PAGE_CRC_MISMATCH = 15
    PAGE_INVALID = 16
    NOT_CLAIMED = 17
    COLLISION = 18


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
    ErrorCode.TABLE_SHAPE_INVALID: "table header invalid (axes, shape, step, joints, configs, size, "
                                   "a missing page)",
    ErrorCode.TARGET_OUTSIDE_TABLE: "Cartesian target lies outside the active correction table grid",
    ErrorCode.WATCHDOG_TIMEOUT: "PC heartbeat stopped during a move: motion stopped; reset the error",
    ErrorCode.NOT_READY: "controller has a latched error: reset it (RESET) before moving",
    ErrorCode.MOTION_ABORTED: "motion aborted by a STOP command",
    ErrorCode.NO_PREVIOUS_TABLE: "roll back requested but no previous table is kept",
    ErrorCode.PAGE_CRC_MISMATCH: "a table page arrived with data that do not match its page CRC: re-upload",
    ErrorCode.PAGE_INVALID: "a transfer request with an unknown operation, page number or length",
    ErrorCode.NOT_CLAIMED: "the command's cmd_token is not the token of the station that holds the controller "
                           "(claim_owner): no claim, another station holds it, or the claim expired by the watchdog",
    ErrorCode.COLLISION: "the controller's own collision check (a safety option's cell model) finds the target or the "
                         "joint-space path to it colliding: nothing moved; check the plan and the cell's obstacles",
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
    """Engineering value(s) -> register words for entry ``reg`` (a name of :data:`REG`, of
    :data:`TABLE_HDR`, or a :class:`Register`).

    ``values`` is a scalar for ``count == 1`` or a sequence of at most ``count`` values (shorter
    sequences encode a prefix of the entry). Integers are ``round(value / scale)`` and must fit
    the type, else ``ValueError`` (a joint beyond +-2147.48 rad or mm, a NaN).
    """
    if isinstance(reg, str):
        reg = REG[reg] if reg in REG else TABLE_HDR[reg]
    vals = np.atleast_1d(np.asarray(values, dtype=float))
    if vals.ndim != 1 or vals.size > reg.count:
        raise ValueError(f"{reg.name}: expected at most {reg.count} values, got shape {vals.shape}")
    fmt, _n = _STRUCT[reg.type]
    out: list[int] = []
    for v in vals:
        if not np.isfinite(v):
            raise ValueError(f"{reg.name}: non-finite value {v} cannot be sent")
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
    """Register words -> engineering value(s): a number for ``count == 1``, else ndarray.

    Raises :class:`RegisterDecodeError` for a wrong number of words or words outside 0..65535.
    """
    if isinstance(reg, str):
        reg = REG[reg] if reg in REG else TABLE_HDR[reg]
    regs = _check_regs(regs, reg.n_registers, reg.name)
    fmt, n = _STRUCT[reg.type]
    vals = []
    for i in range(reg.count):
        w = regs[i * n:(i + 1) * n]
        b = bytes(((w[0] >> 8) & 0xFF, w[0] & 0xFF)) if n == 1 else _join32(w, order)
        raw = struct.unpack(fmt, b)[0]
        vals.append(int(raw) if reg.scale == 1.0 else raw * reg.scale)
    if reg.count == 1:
        return vals[0]
    return np.asarray(vals, dtype=float)


def _raw_i32(values, scale: float) -> np.ndarray:
    v = np.asarray(values, dtype=np.float64).ravel()
    if not np.all(np.isfinite(v)):
        raise ValueError("non-finite value cannot be sent")
    raw = np.rint(v / scale)
    if raw.size and (raw.min() < -2**31 or raw.max() > 2**31 - 1):
        raise ValueError(f"value beyond +-{(2**31 - 1) * scale:.6g} does not fit a scaled i32 "
                         f"(scale {scale:g})")
    return raw.astype(np.int64)


def quantize_values(values, scale: float = TABLE_VALUE_SCALE) -> np.ndarray:
    """``values`` as float32 on the wire's grid (``raw * scale``), exactly what a read back of
    them decodes to; idempotent."""
    return (_raw_i32(values, scale).astype(np.float64) * scale).astype(np.float32)


def encode_i32_array(values, scale: float, order: WordOrder = WordOrder.BIG) -> list[int]:
    """Flat array -> scaled i32 registers (2 per value), vectorised; ``ValueError`` if a value
    does not fit."""
    w = _raw_i32(values, scale).astype(">i4").view(">u2").reshape(-1, 2).astype(np.int64)
    if order is WordOrder.LITTLE:
        w = w[:, ::-1]
    return w.ravel().tolist()


def _words(regs: Sequence[int], what: str) -> np.ndarray:
    try:
        w = np.asarray(regs, dtype=np.int64)
    except (TypeError, ValueError) as exc:
        raise RegisterDecodeError(f"{what}: register contents are not integers: {exc}") from exc
    if w.ndim != 1:
        raise RegisterDecodeError(f"{what}: expected a flat list of registers")
    if w.size and (w.min() < 0 or w.max() > 0xFFFF):
        raise RegisterDecodeError(f"{what}: register value outside 0..65535")
    return w


def decode_i32_raw(regs: Sequence[int], order: WordOrder = WordOrder.BIG) -> np.ndarray:
    """Registers (2 per value) -> raw int64 counts."""
    w = _words(regs, "i32 array")
    if w.size % 2:
        raise RegisterDecodeError(f"i32 array: expected an even number of registers, got {w.size}")
    w = w.reshape(-1, 2)
    if order is WordOrder.LITTLE:
        w = w[:, ::-1]
    return np.ascontiguousarray(w.astype(">u2")).view(">i4").ravel().astype(np.int64)


def decode_i32_array(regs: Sequence[int], scale: float, order: WordOrder = WordOrder.BIG) -> np.ndarray:
    """Registers (2 per value) -> float32 values ``raw * scale`` (as :func:`quantize_values`)."""
    return (decode_i32_raw(regs, order).astype(np.float64) * scale).astype(np.float32)


def raw_crc32(raw: np.ndarray) -> int:
    """CRC-32 (zlib, ISO-HDLC) of raw counts as big-endian 32-bit two's-complement bytes: the
    whole-table CRC, independent of the link's word order."""
    return zlib.crc32(np.asarray(raw, dtype=np.int64).astype(">i4").tobytes()) & 0xFFFFFFFF


def registers_crc32(regs: Sequence[int]) -> int:
    """CRC-32 (zlib, ISO-HDLC) over registers, each high byte first: the page CRC."""
    return zlib.crc32(_words(regs, "page").astype(">u2").tobytes()) & 0xFFFFFFFF
