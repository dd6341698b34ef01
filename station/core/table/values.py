"""A correction table's numerics: its grid axes, its values and the interpolation rule.

A table holds joint corrections on a grid over (up to) x, y, z, yaw of the Cartesian target in
the robot base frame. This module is pure numerics; the register encoding, pages and CRCs that
carry a table to a controller are the driver's (:mod:`drivers.correction_table`), which takes
any object shaped like :class:`CorrectionTableData` (its ``TablePayload`` Protocol), so the core
imports no driver and the driver imports nothing of the station.

Resolution. A table is held exactly as it is represented on a controller: values on a 1e-8 grid
as float32 (rad or mm, at most ±21.47), axis starts and steps on a 1e-6 grid (mm or rad). The two
resolutions are the table format's (``docs/protocols.md``, "Correction table"); the register map
(:mod:`drivers.controller_map`, ``TABLE_VALUE_SCALE``/``TABLE_AXIS_SCALE``) states the same
numbers for the wire and ``tests/core/test_correction_table.py`` checks that they agree. Holding
them here means a table read back from a controller compares bit for bit with the one built.

Shapes: ``values`` is ``(n_configs, *grid_shape, n_joints)``; configuration 0 is elbow +1, 1 is
elbow −1.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass
from typing import Protocol, Sequence

import numpy as np

__all__ = ["VALUE_RESOLUTION", "AXIS_RESOLUTION", "MAX_AXES", "TableError", "TableRangeError", "TableAxis",
           "CorrectionTableData", "AxisLike", "TableLike", "cell_coords", "interpolate_table"]

#: the value grid [rad or mm] and the axis grid [mm or rad] of the table format
VALUE_RESOLUTION = 1e-8
AXIS_RESOLUTION = 1e-6
#: the rule's coordinates: x, y, z, yaw
MAX_AXES = 4
_I32 = 2**31


class TableError(ValueError):
    """A correction table is invalid (shape, values), or cannot be evaluated where asked."""


class TableRangeError(TableError):
    """A point lies outside a correction table's grid."""


class AxisLike(Protocol):
    """What a grid axis offers: nodes at ``start + i*step``, ``i < count``."""

    @property
    def start(self) -> float: ...
    @property
    def step(self) -> float: ...
    @property
    def count(self) -> int: ...
    @property
    def periodic(self) -> bool: ...


class TableLike(Protocol):
    """What a table offers: its axes and its values ``(n_configs, *grid_shape, n_joints)``."""

    @property
    def axes(self) -> Sequence[AxisLike]: ...
    @property
    def values(self) -> np.ndarray: ...


def _on_axis_grid(v: float) -> float:
    return float(round(float(v) / AXIS_RESOLUTION) * AXIS_RESOLUTION)


def quantize_values(values) -> np.ndarray:
    """``values`` (flattened) as float32 on the 1e-8 grid (``count * 1e-8``), exactly what a
    controller returns of them; idempotent. ``ValueError`` when a value does not fit 32 bits."""
    v = np.asarray(values, dtype=np.float64).ravel()
    if not np.all(np.isfinite(v)):
        raise ValueError("non-finite value cannot be sent")
    raw = np.rint(v / VALUE_RESOLUTION)
    if raw.size and (raw.min() < -_I32 or raw.max() > _I32 - 1):
        raise ValueError(f"value beyond +-{(_I32 - 1) * VALUE_RESOLUTION:.6g} does not fit a scaled i32 "
                         f"(scale {VALUE_RESOLUTION:g})")
    return (raw.astype(np.int64).astype(np.float64) * VALUE_RESOLUTION).astype(np.float32)


def axis_key(a: AxisLike) -> tuple[float, float, int, bool]:
    """An axis as plain numbers, for comparing axes of any class."""
    return (float(a.start), float(a.step), int(a.count), bool(a.periodic))


@dataclass(frozen=True)
class TableAxis:
    """One grid axis: nodes at ``start + i*step`` for ``i in range(count)``.

    A periodic axis (yaw) wraps with period ``count*step``: node ``count`` is node 0 again.
    ``start`` and ``step`` are rounded to the 1e-6 grid (mm or rad).
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

    ``values``: float32 array ``(n_configs, *grid_shape, n_joints)`` on the 1e-8 grid (rad or
    mm). The controller adds the multilinear interpolation of the values (:meth:`interpolate`)
    to the joints its nominal inverse kinematics computes. How many values a controller holds is
    the controller's limit, checked where the table is sent (and designed against, with the
    capacity passed in); it is not a property of the numbers.
    """

    axes: tuple[TableAxis, ...]
    values: np.ndarray

    def __post_init__(self) -> None:
        axes = tuple(self.axes)
        if not 1 <= len(axes) <= MAX_AXES:
            raise TableError(f"a correction table needs 1..{MAX_AXES} axes, got {len(axes)}")
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
        if v.shape[-1] < 1:
            raise TableError(f"n_joints must be at least 1, got {v.shape[-1]}")
        if not np.all(np.isfinite(v)):
            raise TableError("table values contain NaN or infinity")
        try:
            v = quantize_values(v).reshape(v.shape)
        except ValueError as exc:
            raise TableError(f"table values: {exc}: a correction this large is not a calibration") from exc
        v.setflags(write=False)
        object.__setattr__(self, "axes", axes)
        object.__setattr__(self, "values", v)

    @classmethod
    def from_table(cls, table: TableLike) -> "CorrectionTableData":
        """Any table (a controller's read-back, say) as this class, bit for bit."""
        return cls(tuple(TableAxis(*axis_key(a)) for a in table.axes), np.asarray(table.values))

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
        """The values as integer counts of 1e-8 (int64, C order)."""
        return np.rint(self.values.ravel().astype(np.float64) / VALUE_RESOLUTION).astype(np.int64)

    def crc32(self) -> int:
        """CRC-32 (zlib, ISO-HDLC polynomial) of the counts as big-endian 32-bit two's
        complement bytes, C order: the table's identity in reports and on the controller."""
        return zlib.crc32(self.raw_values().astype(">i4").tobytes()) & 0xFFFFFFFF

    def same_as(self, other: TableLike) -> bool:
        """Bit-exact equality of axes and values (with a table of any class)."""
        return self.first_difference(other) is None

    def first_difference(self, other: TableLike) -> str | None:
        """Human-readable description of the first difference, or None if identical."""
        mine, theirs = [axis_key(a) for a in self.axes], [axis_key(a) for a in other.axes]
        if mine != theirs:
            return f"axes differ: {mine} vs {theirs}"
        ov = np.asarray(other.values, dtype=np.float32)
        if self.values.shape != ov.shape:
            return f"shapes differ: {self.values.shape} vs {ov.shape}"
        a, b = self.values.ravel(), ov.ravel()
        bad = np.nonzero(a.view(np.uint32) != b.view(np.uint32))[0]
        if bad.size:
            i = int(bad[0])
            return (f"{bad.size} value(s) differ, first at flat index {i} "
                    f"(uploaded {a[i]!r}, read back {b[i]!r})")
        return None

    # -- the interpolation rule (docs/protocols.md) ----------------------------------------
    def interpolate(self, point: Sequence[float] | np.ndarray, config: int = 0) -> np.ndarray:
        """The joint corrections ``(n_joints,)`` at one ``point`` (x, y, z, yaw of the target in
        the base frame, first ``n_axes`` of them): :func:`interpolate_table` at one point."""
        return interpolate_table(self, np.asarray(point, dtype=float).ravel()[None], config)[0]


# --------------------------------------------------------------------------------------------
# interpolation (the controller's rule, vectorised)
# --------------------------------------------------------------------------------------------

def cell_coords(axes: tuple[TableAxis, ...], points: np.ndarray):
    """Per axis: lower node index i0 ``(m,)``, upper node index i1 and weight t of the controller's
    rule (docs/protocols.md) at ``points`` ``(m, n_axes)``. Periodic axes: ``u`` is taken modulo
    ``count`` and node ``count-1`` interpolates towards node 0. Non-periodic axes with
    ``count == 1`` are constant (any coordinate); otherwise ``0 <= u <= count-1`` is required
    (tolerance ``1e-6`` node) or :class:`TableRangeError` is raised. ``i0 = min(floor(u),
    count-2)``, ``t = u - i0``."""
    out = []
    for k, a in enumerate(axes):
        u = (points[:, k] - a.start) / a.step
        if a.periodic:
            u = np.mod(u, a.count)
            i0 = np.minimum(np.floor(u).astype(np.int64), a.count - 1)
            t = u - i0
            i1 = (i0 + 1) % a.count
        elif a.count == 1:
            i0 = np.zeros(len(u), dtype=np.int64)
            i1 = i0
            t = np.zeros(len(u))
        else:
            bad = (u < -1e-6) | (u > a.count - 1 + 1e-6)
            if np.any(bad):
                j = int(np.argmax(bad))
                raise TableRangeError(
                    f"coordinate {k} = {points[j, k]:.6g} outside the table axis "
                    f"[{a.start:.6g}, {a.start + a.step * (a.count - 1):.6g}]")
            u = np.clip(u, 0.0, a.count - 1.0)
            i0 = np.minimum(np.floor(u).astype(np.int64), a.count - 2)
            t = u - i0
            i1 = i0 + 1
        out.append((i0, i1, t))
    return out


def interpolate_table(data: CorrectionTableData, points, config: int = 0) -> np.ndarray:
    """Joint corrections ``(m, n_joints)`` at ``points`` ``(m, n_axes)`` (x, y, z, yaw of the
    targets in the base frame, first ``n_axes`` of them): the controller's multilinear rule, the
    sum over the 2^n corners of the product of weights ``(1-t)`` / ``t`` times the node values,
    in float64. The only implementation of the rule in the station; the simulated controller
    has its own, written from docs/protocols.md (simulators/program_words.py)."""
    p = np.atleast_2d(np.asarray(points, dtype=float))
    n = len(data.axes)
    if p.shape[1] < n:
        raise TableError(f"interpolation needs {n} coordinates per point, got {p.shape[1]}")
    if not 0 <= config < data.n_configs:
        raise TableError(f"configuration {config} not in table (n_configs={data.n_configs})")
    cc = cell_coords(data.axes, p)
    vals = data.values[config].astype(float)
    out = np.zeros((p.shape[0], data.n_joints))
    for corner in range(1 << n):
        w = np.ones(p.shape[0])
        idx = []
        for k in range(n):
            i0, i1, t = cc[k]
            hi = (corner >> k) & 1
            w = w * (t if hi else 1.0 - t)
            idx.append(i1 if hi else i0)
        out += w[:, None] * vals[tuple(idx)]
    return out
