"""The correction table on the wire: header page, value pages, their encoding and the table errors.

The table travels through the controller's transfer block in pages (:mod:`drivers.controller_map`,
documented in ``docs/protocols.md``, section "Correction table"): a header page, then the values
as scaled 32-bit integers, 29 per page. This module encodes any table shaped like
:class:`TablePayload` (axes with ``start``/``step``/``count``/``periodic``, values
``(n_configs, *grid_shape, n_joints)``) and decodes what a controller holds into a
:class:`WireTable`. What a table *means* (its grid, the interpolation rule, how it is built) is
numerics and lives in the station's core (``station.core.table.values``); the driver knows nothing
of the station, so the payload is a Protocol the station's table satisfies without inheriting.
Only numpy and the register map are imported here (no pymodbus or pyserial).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, Sequence

import numpy as np

from .controller_map import (
    MAX_JOINTS,
    MAX_TABLE_AXES,
    MAX_TABLE_VALUES,
    PAGE_VALUES,
    TABLE_FORMAT_VERSION,
    TABLE_HDR,
    TABLE_HEADER_REGISTERS,
    TABLE_VALUE_SCALE,
    ControllerError,
    RegisterDecodeError,
    WordOrder,
    decode,
    decode_i32_array,
    decode_i32_raw,
    encode,
    encode_i32_array,
    raw_crc32,
)

__all__ = ["MAX_TABLE_VALUES", "TablePayload", "WireAxis", "WireTable", "TableError", "TableVerifyError",
           "TablePageError", "n_value_pages", "check_payload", "header_registers", "data_registers", "value_pages",
           "decode_header", "table_from_registers", "table_crc32", "payload_difference"]

# --------------------------------------------------------------------------------------------
# errors
# --------------------------------------------------------------------------------------------


class TableError(ControllerError):
    """A correction-table operation failed (invalid table, controller refused it)."""


class TableVerifyError(TableError):
    """A correction table may not be activated: it was not read back identical, or CRCs differ."""


class TablePageError(TableError):
    """A page of the table transfer was refused by the controller or read back wrong; nothing
    was staged from it."""


def n_value_pages(n_values: int) -> int:
    """Value pages of a table of ``n_values`` values (29 values a page)."""
    return -(-int(n_values) // PAGE_VALUES)


# --------------------------------------------------------------------------------------------
# the payload: what the driver sends (any table of this shape) and what it reads back
# --------------------------------------------------------------------------------------------

class AxisPayload(Protocol):
    @property
    def start(self) -> float: ...
    @property
    def step(self) -> float: ...
    @property
    def count(self) -> int: ...
    @property
    def periodic(self) -> bool: ...


class TablePayload(Protocol):
    """A table to send: up to four axes and values ``(n_configs, *grid_shape, n_joints)``, each
    value a multiple of ``TABLE_VALUE_SCALE`` (1e-8), each axis start and step of
    ``TABLE_AXIS_SCALE`` (1e-6)."""

    @property
    def axes(self) -> Sequence[AxisPayload]: ...
    @property
    def values(self) -> np.ndarray: ...


@dataclass(frozen=True)
class WireAxis:
    """One axis as the header page states it (mm or rad)."""

    start: float
    step: float
    count: int
    periodic: bool = False

    def __post_init__(self) -> None:
        if not (np.isfinite(self.start) and np.isfinite(self.step) and self.step > 0):
            raise TableError(f"table axis needs a finite start and a step > 0, got {self.start}, {self.step}")
        if not 1 <= self.count <= 65535:
            raise TableError(f"table axis node count must be 1..65535, got {self.count}")


@dataclass(frozen=True, eq=False)
class WireTable:
    """A table as a controller holds it: header axes and the decoded values (float32)."""

    axes: tuple[WireAxis, ...]
    values: np.ndarray

    @property
    def n_configs(self) -> int:
        return int(self.values.shape[0])

    @property
    def n_joints(self) -> int:
        return int(self.values.shape[-1])

    @property
    def n_values(self) -> int:
        return int(self.values.size)

    @property
    def grid_shape(self) -> tuple[int, ...]:
        return tuple(a.count for a in self.axes)

    def crc32(self) -> int:
        return table_crc32(self)

    def same_as(self, other: TablePayload) -> bool:
        """Bit-exact equality of axes and values with a table of any class."""
        return payload_difference(self, other) is None

    def first_difference(self, other: TablePayload) -> str | None:
        return payload_difference(self, other)


def _axis_key(a: AxisPayload) -> tuple[float, float, int, bool]:
    return (float(a.start), float(a.step), int(a.count), bool(a.periodic))


def _raw(table: TablePayload) -> np.ndarray:
    return np.rint(np.asarray(table.values, dtype=np.float64).ravel() / TABLE_VALUE_SCALE).astype(np.int64)


def table_crc32(table: TablePayload) -> int:
    """CRC-32 (zlib, ISO-HDLC polynomial) of the values' counts as big-endian 32-bit two's
    complement bytes, C order: the header's ``table_crc``."""
    return raw_crc32(_raw(table))


def check_payload(table: TablePayload) -> None:
    """Refuse (:class:`TableError`) a table the register map cannot carry: axes, joints,
    configurations, or more values than the controller holds."""
    axes, v = tuple(table.axes), np.asarray(table.values)
    if not 1 <= len(axes) <= MAX_TABLE_AXES:
        raise TableError(f"a correction table needs 1..{MAX_TABLE_AXES} axes, got {len(axes)}")
    if v.ndim != len(axes) + 2 or v.shape[1:-1] != tuple(int(a.count) for a in axes):
        raise TableError(f"table values of shape {v.shape} do not match its axes")
    if not 1 <= v.shape[0] <= 2:
        raise TableError(f"n_configs must be 1 or 2, got {v.shape[0]}")
    if not 1 <= v.shape[-1] <= MAX_JOINTS:
        raise TableError(f"n_joints must be 1..{MAX_JOINTS}, got {v.shape[-1]}")
    if v.size > MAX_TABLE_VALUES:
        raise TableError(f"table has {v.size} values; the controller holds at most {MAX_TABLE_VALUES}: "
                         f"use a coarser grid")


def payload_difference(sent: TablePayload, got: TablePayload) -> str | None:
    """The first difference between two tables, bit for bit, as text; None when identical."""
    a_axes, b_axes = [_axis_key(a) for a in sent.axes], [_axis_key(a) for a in got.axes]
    if a_axes != b_axes:
        return f"axes differ: {a_axes} vs {b_axes}"
    a, b = np.asarray(sent.values, dtype=np.float32), np.asarray(got.values, dtype=np.float32)
    if a.shape != b.shape:
        return f"shapes differ: {a.shape} vs {b.shape}"
    a, b = a.ravel(), b.ravel()
    bad = np.nonzero(a.view(np.uint32) != b.view(np.uint32))[0]
    if bad.size:
        i = int(bad[0])
        return f"{bad.size} value(s) differ, first at flat index {i} (uploaded {a[i]!r}, read back {b[i]!r})"
    return None


# --------------------------------------------------------------------------------------------
# encoding and decoding (docs/protocols.md, "Correction table")
# --------------------------------------------------------------------------------------------

def header_registers(table: TablePayload, order: WordOrder = WordOrder.BIG) -> list[int]:
    """The header page's data registers (``TABLE_HEADER``, 30 registers)."""
    check_payload(table)
    axes, v = tuple(table.axes), np.asarray(table.values)
    n = len(axes)
    pad = MAX_TABLE_AXES - n
    periodic = sum(1 << i for i, a in enumerate(axes) if a.periodic)
    regs: list[int] = []
    regs += encode("table_format", TABLE_FORMAT_VERSION, order)
    regs += encode("table_n_axes", n, order)
    regs += encode("table_shape", [int(a.count) for a in axes] + [0] * pad, order)
    regs += encode("table_start", [float(a.start) for a in axes] + [0.0] * pad, order)
    regs += encode("table_step", [float(a.step) for a in axes] + [0.0] * pad, order)
    regs += encode("table_periodic", periodic, order)
    regs += encode("table_n_joints", int(v.shape[-1]), order)
    regs += encode("table_n_configs", int(v.shape[0]), order)
    regs += encode("table_n_values", int(v.size), order)
    regs += encode("table_crc", table_crc32(table), order)
    regs += encode("table_value_scale_exp", -8, order)
    assert len(regs) == TABLE_HEADER_REGISTERS
    return regs


def data_registers(table: TablePayload, order: WordOrder = WordOrder.BIG) -> list[int]:
    """All values as scaled i32 registers (2 per value), C order."""
    return encode_i32_array(np.asarray(table.values).ravel(), TABLE_VALUE_SCALE, order)


def value_pages(table: TablePayload, order: WordOrder = WordOrder.BIG) -> list[list[int]]:
    """The data registers of value page 0, 1, ... (29 values, 58 registers each; the last
    one shorter)."""
    regs = data_registers(table, order)
    step = 2 * PAGE_VALUES
    return [regs[i:i + step] for i in range(0, len(regs), step)]


def decode_header(regs: Sequence[int], order: WordOrder = WordOrder.BIG) -> dict:
    """Header page registers -> dict(axes, n_joints, n_configs, n_values, crc, format).

    Raises :class:`TableError` (or :class:`RegisterDecodeError`) for an invalid header.
    """
    if len(regs) < TABLE_HEADER_REGISTERS:
        raise RegisterDecodeError(f"table header: expected {TABLE_HEADER_REGISTERS} registers, got {len(regs)}")

    def f(name: str):
        r = TABLE_HDR[name]
        return decode(r, regs[r.address:r.end], order)

    fmt = f("table_format")
    if fmt != TABLE_FORMAT_VERSION:
        raise TableError(f"table format version {fmt} is not {TABLE_FORMAT_VERSION}: "
                         f"the controller holds no table in this format")
    if f("table_value_scale_exp") != -8:
        raise TableError(f"table value scale exponent {f('table_value_scale_exp')} is not -8")
    n_axes = f("table_n_axes")
    if not 1 <= n_axes <= MAX_TABLE_AXES:
        raise TableError(f"table header: n_axes {n_axes} not in 1..{MAX_TABLE_AXES}")
    shape, start, step, periodic = f("table_shape"), f("table_start"), f("table_step"), f("table_periodic")
    axes = tuple(WireAxis(float(start[i]), float(step[i]), int(shape[i]), bool(periodic >> i & 1))
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


def table_from_registers(header: Sequence[int], data: Sequence[int],
                         order: WordOrder = WordOrder.BIG) -> WireTable:
    """Header page and all value registers -> table. Raises :class:`TableError` when the
    values' CRC-32 is not the header's."""
    h = decode_header(header, order)
    if len(data) != 2 * h["n_values"]:
        raise RegisterDecodeError(f"table data: expected {2 * h['n_values']} registers, got {len(data)}")
    crc = raw_crc32(decode_i32_raw(data, order))
    if crc != h["crc"]:
        raise TableError(f"the table's values have CRC-32 {crc:#010x}, its header says {h['crc']:#010x}")
    vals = decode_i32_array(data, TABLE_VALUE_SCALE, order).astype(np.float32)
    vals.setflags(write=False)
    shape = (h["n_configs"], *[a.count for a in h["axes"]], h["n_joints"])
    return WireTable(h["axes"], vals.reshape(shape))
