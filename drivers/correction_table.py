"""Correction-table data: grid axes, values, register encoding and the interpolation rule.

The table travels through the controller's transfer block in pages (:mod:`drivers.controller_map`,
documented in ``docs/protocols.md``, section "Correction table"): a header page, then the values
as scaled 32-bit integers, 29 per page. The driver uploads it, the simulator decodes and applies
it, and the station builds it. Values and axes are held exactly as they travel (values on the
1e-8 grid as float32, axes on the 1e-6 grid), so a read back compares bit for bit. Only numpy and the register map are imported here, so
that the station can build and check tables without pymodbus or pyserial installed.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .controller_map import (
    MAX_JOINTS,
    MAX_TABLE_AXES,
    MAX_TABLE_VALUES,
    PAGE_VALUES,
    TABLE_AXIS_SCALE,
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
    quantize_values,
    raw_crc32,
)

__all__ = ["MAX_TABLE_VALUES", "TableAxis", "CorrectionTableData", "TableError", "TableVerifyError",
           "TableRangeError", "TablePageError", "n_value_pages"]

# --------------------------------------------------------------------------------------------
# errors
# --------------------------------------------------------------------------------------------


class TableError(ControllerError):
    """A correction-table operation failed (invalid table, controller refused it)."""


class TableVerifyError(TableError):
    """A correction table may not be activated: it was not read back identical, or CRCs differ."""


class TableRangeError(TableError):
    """A point lies outside a correction table's grid."""


class TablePageError(TableError):
    """A page of the table transfer was refused by the controller or read back wrong; nothing
    was staged from it."""


def n_value_pages(n_values: int) -> int:
    """Value pages of a table of ``n_values`` values (29 values a page)."""
    return -(-int(n_values) // PAGE_VALUES)


def _on_axis_grid(v: float) -> float:
    # the same expression as decode(): raw * scale
    return float(round(float(v) / TABLE_AXIS_SCALE) * TABLE_AXIS_SCALE)


# --------------------------------------------------------------------------------------------
# correction table
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class TableAxis:
    """One grid axis: nodes at ``start + i*step`` for ``i in range(count)``.

    A periodic axis (yaw) wraps with period ``count*step``: node ``count`` is node 0 again.
    ``start`` and ``step`` are rounded to the wire's 1e-6 grid (mm or rad), as they travel as
    scaled 32-bit integers.
    """

    start: float
    step: float
    count: int
    periodic: bool = False

    def __post_init__(self) -> None:
        if not (np.isfinite(self.start) and np.isfinite(self.step)
                and max(abs(self.start), abs(self.step)) < 2000.0):
            raise TableError(f"table axis start and step must be finite and within +-2000 (mm or rad), "
                             f"got {self.start}, {self.step}")
        object.__setattr__(self, "start", _on_axis_grid(self.start))
        object.__setattr__(self, "step", _on_axis_grid(self.step))
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

    ``values``: float32 array of shape ``(n_configs, *grid_shape, n_joints)``, rounded to the
    wire's 1e-8 grid (rad or mm; at most +-21.47); configuration 0 is elbow=+1, 1 is elbow=-1. The controller adds the multilinear interpolation of the values
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
        v = np.array(self.values, dtype=np.float64, copy=True)
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
        try:
            v = quantize_values(v, TABLE_VALUE_SCALE).reshape(v.shape)
        except ValueError as exc:
            raise TableError(f"table values: {exc}: a correction this large is not a calibration") from exc
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

    def raw_values(self) -> np.ndarray:
        """The values as the wire's counts (int64, C order): ``value / 1e-8``."""
        return np.rint(self.values.ravel().astype(np.float64) / TABLE_VALUE_SCALE).astype(np.int64)

    def crc32(self) -> int:
        """CRC-32 (zlib, ISO-HDLC polynomial) of the raw counts as big-endian 32-bit two's
        complement bytes, C order."""
        return raw_crc32(self.raw_values())

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
        """The header page's data registers (``TABLE_HEADER``, 30 registers)."""
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
        regs += encode("table_value_scale_exp", -8, order)
        assert len(regs) == TABLE_HEADER_REGISTERS
        return regs

    def data_registers(self, order: WordOrder = WordOrder.BIG) -> list[int]:
        """All values as scaled i32 registers (2 per value), C order."""
        return encode_i32_array(self.values.ravel(), TABLE_VALUE_SCALE, order)

    def value_pages(self, order: WordOrder = WordOrder.BIG) -> list[list[int]]:
        """The data registers of value page 0, 1, ... (29 values, 58 registers each; the last
        one shorter)."""
        regs = self.data_registers(order)
        step = 2 * PAGE_VALUES
        return [regs[i:i + step] for i in range(0, len(regs), step)]

    @staticmethod
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
        """Header page and all value registers -> table. Raises :class:`TableError` when the
        values' CRC-32 is not the header's."""
        h = cls.decode_header(header, order)
        if len(data) != 2 * h["n_values"]:
            raise RegisterDecodeError(f"table data: expected {2 * h['n_values']} registers, got {len(data)}")
        crc = raw_crc32(decode_i32_raw(data, order))
        if crc != h["crc"]:
            raise TableError(f"the table's values have CRC-32 {crc:#010x}, its header says {h['crc']:#010x}")
        vals = decode_i32_array(data, TABLE_VALUE_SCALE, order)
        shape = (h["n_configs"], *[a.count for a in h["axes"]], h["n_joints"])
        return cls(h["axes"], vals.reshape(shape))

    # -- the interpolation rule (docs/protocols.md) ----------------------------------------
    def interpolate(self, point: Sequence[float] | np.ndarray, config: int = 0) -> np.ndarray:
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

