"""The robot program's side of register map 3, written from ``docs/protocols.md``, not from the driver.

The simulated controller plays the robot program (URScript, SPEL+). It shares the map's
declarative TABLE with the driver (:data:`drivers.controller_map.REG`, ``TABLE_HDR``: offsets,
types, counts, scales, units, sources) but none of the driver's CODE: what a word means, how a
32-bit value is split, how a table header and its values are read, how the CRC-32 covers them
and how the table is interpolated are written here again from the document, the way the robot
programs do it - integers rebuilt from two 16-bit words, never ``struct``. A slip that driver and
simulator shared would otherwise pass every end-to-end test (issue 33, item 7); the two are held
to each other by round trips in ``tests/simulators/test_program_words.py``.

References (``docs/protocols.md``):

* "Data types and word order": ``u16`` / ``i16`` one register, big-endian bytes (Modbus
  Application Protocol V1.1b3, section 4.2: "a big-Endian representation is used for addresses
  and data items"), ``i16`` two's complement; ``u32`` / ``i32`` two registers, word order BIG
  ("ABCD": register n the high word) or LITTLE ("CDAB"); an integer is ``hi * 65536 + lo``,
  minus 2^32 when >= 2^31; scaled values are ``raw * scale``.
* "Correction table": the header page (30 registers), the values (scaled i32, 1e-8, C order
  ``value[config][i0]..[i_{n-1}][joint]``, 29 to a page), the whole-table CRC-32 (zlib /
  ISO-HDLC over the raw values as big-endian 32-bit two's complement bytes, independent of the
  word order), the page CRC (over the data registers, each high byte first) and the
  interpolation rule.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from drivers.controller_map import MAX_JOINTS, MAX_TABLE_VALUES, TABLE_HDR, WordOrder

__all__ = ["put_value", "get_value", "words_from_counts", "counts_from_words", "crc32_of_counts",
           "crc32_of_registers", "ProgramAxis", "ProgramTable", "read_header", "header_page",
           "value_page_words", "OutsideTable", "VALUE_SCALE", "AXIS_SCALE", "PAGE_VALUE_COUNT",
           "HEADER_REGISTER_COUNT"]

# "Correction table" (docs/protocols.md): 1 count = 1e-8 rad or mm for values, 1e-6 for axes;
# 29 values (58 registers) to a page; the header page holds 30 registers; format version 2
VALUE_SCALE = 1e-8
AXIS_SCALE = 1e-6
PAGE_VALUE_COUNT = 29
HEADER_REGISTER_COUNT = 30
TABLE_FORMAT = 2
VALUE_SCALE_EXPONENT = -8
#: a node outside the table by less than this (in nodes) still counts as inside (the rule, step 1)
NODE_TOLERANCE = 1e-6

_WIDTH = {"u16": 1, "i16": 1, "u32": 2, "i32": 2}
_SIGNED = {"u16": False, "i16": True, "u32": False, "i32": True}


def _kind(reg) -> str:
    return str(getattr(reg.type, "value", reg.type))


def _int_of(words: Sequence[int], kind: str, order: WordOrder) -> int:
    """One integer from its 1 or 2 words (each 0..65535: a program that handed on a UR's signed
    register value unconverted has a bug, and fails here rather than move somewhere else)."""
    if any(not 0 <= int(w) <= 0xFFFF for w in words):
        raise ValueError(f"register words {list(words)} are not 16-bit words 0..65535")
    if _WIDTH[kind] == 1:
        n, bits = int(words[0]), 16
    else:
        hi, lo = (words[0], words[1]) if order is WordOrder.BIG else (words[1], words[0])
        n, bits = int(hi) * 65536 + int(lo), 32
    if _SIGNED[kind] and n >= 1 << (bits - 1):
        n -= 1 << bits
    return n


def _words_of(n: int, kind: str, order: WordOrder) -> list[int]:
    bits = 16 * _WIDTH[kind]
    lo_bound, hi_bound = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if _SIGNED[kind] else (0, (1 << bits) - 1)
    if not lo_bound <= n <= hi_bound:
        raise ValueError(f"{n} does not fit {kind}")
    u = n % (1 << bits)  # two's complement
    if bits == 16:
        return [u]
    hi, lo = u // 65536, u % 65536
    return [hi, lo] if order is WordOrder.BIG else [lo, hi]


def put_value(regs: list[int], reg, value, order: WordOrder, base: int = 0) -> None:
    """Write engineering ``value`` (a number, or up to ``count`` numbers) of entry ``reg`` into
    the register image ``regs`` at ``base + reg.address``: ``raw = round(value / scale)``."""
    kind = _kind(reg)
    vals = np.atleast_1d(np.asarray(value, dtype=float)).ravel()
    if vals.size > reg.count:
        raise ValueError(f"{reg.name}: {vals.size} values for {reg.count}")
    at = base + reg.address
    for v in vals:
        if not math.isfinite(float(v)):
            raise ValueError(f"{reg.name}: {v} is not finite")
        words = _words_of(int(round(float(v) / reg.scale)), kind, order)
        regs[at:at + len(words)] = words
        at += len(words)


def get_value(regs: Sequence[int], reg, order: WordOrder, base: int = 0):
    """Entry ``reg`` read from the register image: an int (scale 1) or float per value; a list
    when ``count > 1``."""
    kind, width = _kind(reg), _WIDTH[_kind(reg)]
    out = []
    for i in range(reg.count):
        at = base + reg.address + i * width
        n = _int_of(regs[at:at + width], kind, order)
        out.append(n if reg.scale == 1 else n * reg.scale)
    return out[0] if reg.count == 1 else out


def counts_from_words(words: Sequence[int], order: WordOrder) -> np.ndarray:
    """Scaled-i32 registers (2 per value) -> raw counts (int64)."""
    if len(words) % 2:
        raise ValueError(f"{len(words)} registers do not hold whole i32 values")
    w = np.asarray(words, dtype=np.int64).reshape(-1, 2)
    if w.size and (w.min() < 0 or w.max() > 0xFFFF):
        raise ValueError("register words outside 0..65535")
    hi, lo = (w[:, 0], w[:, 1]) if order is WordOrder.BIG else (w[:, 1], w[:, 0])
    n = hi * 65536 + lo
    return np.where(n >= 1 << 31, n - (1 << 32), n)


def words_from_counts(counts, order: WordOrder) -> list[int]:
    """Raw counts -> scaled-i32 registers (2 per value)."""
    n = np.asarray(counts, dtype=np.int64).ravel()
    if n.size and (n.min() < -(1 << 31) or n.max() > (1 << 31) - 1):
        raise ValueError("a count does not fit i32")
    u = n % (1 << 32)
    hi, lo = u // 65536, u % 65536
    pair = np.stack([hi, lo] if order is WordOrder.BIG else [lo, hi], axis=1)
    return [int(x) for x in pair.ravel()]


def crc32_of_counts(counts) -> int:
    """The whole-table CRC-32: zlib / ISO-HDLC over the counts as big-endian 32-bit two's
    complement bytes, C order (independent of the link's word order)."""
    # the same bytes as int.to_bytes(4, "big") of each count mod 2**32, written by numpy in one go
    # (the per-count Python join was ~1.5 s of the simulated controller's CPU in one calibration)
    data = (np.asarray(counts, dtype=np.int64).ravel() % (1 << 32)).astype(">u4").tobytes()
    return zlib.crc32(data) & 0xFFFFFFFF


def crc32_of_registers(words: Sequence[int]) -> int:
    """The page CRC-32: zlib / ISO-HDLC over the registers, each high byte first."""
    return zlib.crc32(b"".join(int(w).to_bytes(2, "big") for w in words)) & 0xFFFFFFFF


@dataclass(frozen=True)
class ProgramAxis:
    """One grid axis as the program holds it: counts of 1e-6 for start and step."""

    start_counts: int
    step_counts: int
    count: int
    periodic: bool

    @property
    def start(self) -> float:
        return self.start_counts * AXIS_SCALE

    @property
    def step(self) -> float:
        return self.step_counts * AXIS_SCALE


class OutsideTable(ValueError):
    """The target is outside a non-periodic axis: the move is refused (``TARGET_OUTSIDE_TABLE``)."""


@dataclass(frozen=True)
class ProgramTable:
    """A correction table as the robot program keeps it: its axes and its raw value counts
    ``(n_configs, *shape, n_joints)``."""

    axes: tuple[ProgramAxis, ...]
    counts: np.ndarray

    @property
    def values(self) -> np.ndarray:
        """Values as the driver holds them (float32 of ``counts * 1e-8``), for comparisons."""
        return (self.counts.astype(np.float64) * VALUE_SCALE).astype(np.float32)

    @property
    def n_configs(self) -> int:
        return int(self.counts.shape[0])

    def crc32(self) -> int:
        return crc32_of_counts(self.counts)

    def same_as(self, other) -> bool:
        """Bit-exact equality with a table of any class (``axes`` with start, step, count,
        periodic; ``values`` float32)."""
        mine = [(a.start, a.step, a.count, a.periodic) for a in self.axes]
        theirs = [(float(a.start), float(a.step), int(a.count), bool(a.periodic)) for a in other.axes]
        ov = np.asarray(other.values, dtype=np.float32)
        return mine == theirs and ov.shape == self.counts.shape and bool(np.all(
            self.values.view(np.uint32) == ov.view(np.uint32)))

    def correction(self, point: Sequence[float], config: int) -> np.ndarray:
        """The interpolation rule of docs/protocols.md ("Correction table"), steps 1-2: the joint
        corrections at the target coordinates ``point`` (x, y, z, yaw; the first n_axes)."""
        corners: list[tuple[int, int]] = []
        weights: list[float] = []
        for k, a in enumerate(self.axes):
            u = (float(point[k]) - a.start) / a.step
            if a.periodic:
                u = u - a.count * math.floor(u / a.count)  # u mod shape, in [0, shape)
                i0 = min(int(math.floor(u)), a.count - 1)
                corners.append((i0, (i0 + 1) % a.count))
                weights.append(u - i0)
            elif a.count == 1:
                corners.append((0, 0))
                weights.append(0.0)
            else:
                if u < -NODE_TOLERANCE or u > a.count - 1 + NODE_TOLERANCE:
                    raise OutsideTable(f"axis {k}: {point[k]!r} is {u:.6f} nodes, outside 0 .. {a.count - 1}")
                u = min(max(u, 0.0), a.count - 1.0)
                i0 = min(int(math.floor(u)), a.count - 2)
                corners.append((i0, i0 + 1))
                weights.append(u - i0)
        block = self.counts[config].astype(np.float64) * VALUE_SCALE
        dq = np.zeros(block.shape[-1])
        for corner in range(1 << len(self.axes)):
            w, index = 1.0, []
            for k in range(len(self.axes)):
                bit = corner >> k & 1
                w *= weights[k] if bit else 1.0 - weights[k]
                index.append(corners[k][bit])
            if w:
                dq += w * block[tuple(index)]
        return dq


def read_header(page: Sequence[int], order: WordOrder) -> dict | None:
    """The stored header page -> its fields, or None when TABLE_STAGE must refuse it
    (``TABLE_SHAPE_INVALID``: format, scale, axes, steps, sizes)."""
    if len(page) != HEADER_REGISTER_COUNT:
        return None

    def f(name: str):
        return get_value(page, TABLE_HDR[name], order)

    if f("table_format") != TABLE_FORMAT or f("table_value_scale_exp") != VALUE_SCALE_EXPONENT:
        return None
    n_axes = f("table_n_axes")
    if not 1 <= n_axes <= 4:
        return None
    # start and step as counts (scale 1e-6): the program keeps integers
    s0, d0 = TABLE_HDR["table_start"].address, TABLE_HDR["table_step"].address
    start = [_int_of(page[s0 + 2 * i:s0 + 2 * i + 2], "i32", order) for i in range(4)]
    step = [_int_of(page[d0 + 2 * i:d0 + 2 * i + 2], "i32", order) for i in range(4)]
    shape, periodic = f("table_shape"), f("table_periodic")
    axes = tuple(ProgramAxis(start[i], step[i], int(shape[i]), bool(periodic >> i & 1)) for i in range(n_axes))
    if any(a.count < 1 or a.step_counts <= 0 for a in axes):
        return None
    n_joints, n_configs, n_values = f("table_n_joints"), f("table_n_configs"), f("table_n_values")
    nodes = math.prod(a.count for a in axes)
    if not (1 <= n_joints <= MAX_JOINTS and 1 <= n_configs <= 2 and n_values == n_configs * nodes * n_joints
            and n_values <= MAX_TABLE_VALUES):
        return None
    return {"axes": axes, "n_joints": n_joints, "n_configs": n_configs, "n_values": n_values,
            "crc": f("table_crc")}


def header_page(table: ProgramTable, order: WordOrder) -> list[int]:
    """The header page regenerated from a kept table (the slot reads)."""
    page = [0] * HEADER_REGISTER_COUNT
    n = len(table.axes)

    def put(name: str, value) -> None:
        put_value(page, TABLE_HDR[name], value, order)

    put("table_format", TABLE_FORMAT)
    put("table_n_axes", n)
    put("table_shape", [a.count for a in table.axes] + [0] * (4 - n))
    s0, d0 = TABLE_HDR["table_start"].address, TABLE_HDR["table_step"].address
    for i, a in enumerate(table.axes):
        page[s0 + 2 * i:s0 + 2 * i + 2] = _words_of(a.start_counts, "i32", order)
        page[d0 + 2 * i:d0 + 2 * i + 2] = _words_of(a.step_counts, "i32", order)
    put("table_periodic", sum(1 << i for i, a in enumerate(table.axes) if a.periodic))
    put("table_n_joints", table.counts.shape[-1])
    put("table_n_configs", table.counts.shape[0])
    put("table_n_values", table.counts.size)
    put("table_crc", table.crc32())
    put("table_value_scale_exp", VALUE_SCALE_EXPONENT)
    return page


def value_page_words(table: ProgramTable, order: WordOrder) -> list[list[int]]:
    """The value pages regenerated from a kept table: 29 values (58 registers) each, C order."""
    words = words_from_counts(table.counts.ravel(), order)
    step = 2 * PAGE_VALUE_COUNT
    return [words[i:i + step] for i in range(0, len(words), step)]
