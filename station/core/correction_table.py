"""Correction of a calibrated robot by its controller (brief §8): joint-correction tables,
compensated targets, and the verified upload.

The controller keeps its NOMINAL kinematics. For a Cartesian target T (x, y, z, yaw in the robot
base frame) it computes ``q_nom = IK_nominal(T, elbow)`` and adds the multilinear interpolation of
a table of joint corrections::

    Δq(node, elbow) = IK_identified(T_node, elbow) − IK_nominal(T_node, elbow)

(revolute differences wrapped to (−π, π]), so that the real robot — described by the identified
model — reaches what the nominal model promised. The interpolation rule is the controller's
(:meth:`drivers.controller.CorrectionTableData.interpolate`); :func:`interpolate_table` is the
same rule vectorised and is checked against it in the tests.

Everything here is pure numerics except :func:`upload_verified`, which talks to a controller
object (the :class:`drivers.controller.ModbusController` or anything with the same table
methods). Units: mm and rad inside; µm and arc seconds only in reported figures.

Frames: targets are in the robot base frame as the *identified* chain defines it (the chain
without the set-up R: ``forward(..., setup=False)``); the table never uses R. A target given in
the measurement frame is converted with the identified R first (``compensated_targets`` does
that with ``setup=True``).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from drivers.controller import (
    CorrectionTableData,
    TableAxis,
    TableError,
    TableRangeError,
    TableVerifyError,
)
from drivers.controller_map import MAX_TABLE_VALUES
from station.errors import ConfigError, UnreachableError
from station.cell.events import Event, Notice, PhaseChanged
from station.core.kinematics import forward, inverse_kinematics, scara_ik
from station.core.model import RobotModel
from station.core.transforms import invert, pose_to_matrix, rotation_log

__all__ = [
    "ARCSEC",
    "GridSpec",
    "CorrectionTable",
    "InterpolationError",
    "CompensatedTargets",
    "UploadReport",
    "build_correction_table",
    "interpolate_table",
    "interpolation_error",
    "compensated_targets",
    "upload_verified",
    "wrap_angle",
]

ARCSEC = math.pi / (180.0 * 3600.0)
TWO_PI = 2.0 * math.pi
#: relative tolerance for "range is a whole number of steps"
_STEP_TOL = 1e-9
#: an IK solution must reproduce the target position to this [mm] to count as reached
_IK_CHECK_MM = 1e-6


def wrap_angle(a) -> np.ndarray:
    """Angles wrapped to (−π, π]."""
    a = np.asarray(a, dtype=float)
    w = np.mod(a + math.pi, TWO_PI) - math.pi  # [−π, π)
    return np.where(w <= -math.pi, w + TWO_PI, w)


# --------------------------------------------------------------------------------------------
# grid
# --------------------------------------------------------------------------------------------

def _count(name: str, lo: float, hi: float, step: float, unit: str) -> int:
    span = hi - lo
    if span == 0.0:
        return 1
    n = span / step
    k = round(n)
    if k < 1 or abs(n - k) > _STEP_TOL * max(1.0, n):
        divisors = [span / m for m in range(max(1, math.floor(n)), math.floor(n) + 3) if m > 0]
        hint = ", ".join(f"{d:.6g}" for d in divisors[:3])
        raise ConfigError(
            f"grid {name}: the range {lo:.6g}..{hi:.6g} {unit} is not a whole number of "
            f"{step:.6g} {unit} steps ({n:.4g}); choose a step that divides {span:.6g} {unit}, "
            f"e.g. {hint}")
    return k + 1


@dataclass(frozen=True)
class GridSpec:
    """The grid of a correction table over the Cartesian target (robot base frame).

    ``*_range`` = (first node, last node) [mm]; the range must be a whole number of ``*_step``
    [mm] (a range of zero length gives one node: the table is then constant along that axis).
    ``yaw_range`` / ``yaw_step`` [rad]: with ``yaw_periodic`` (default) the range must be one full
    turn and a whole number of steps; node ``count`` is node 0 again. ``elbows``: ``(1, -1)``
    (configuration 0 = elbow +1, 1 = elbow −1, the controller's order) or ``(1,)``.

    The default grid, x∈[350, 650], y∈[−250, 250], z∈[250, 450] mm with 11 × 15 × 2 × 12
    nodes per elbow (31 680 values with 4 joints), keeps the interpolation bound at ≈ 3–4 µm
    over the whole grid for the reference cell's parameter errors (0.04 mm, 2.5′). The full
    reference workspace up to x = 750 mm (:meth:`full_workspace`) reaches a wrist radius of
    ~797 mm (reach 800 mm): near the stretched arm the correction curves so strongly that a few
    µm there need ≤ 10 mm steps, far beyond 32 000 values (figures in ``docs/correction.md``;
    :meth:`CorrectionTable.bound_at` gives the bound per target). The controller refuses
    Cartesian targets outside the grid of an active table.
    """

    x_range: tuple[float, float] = (350.0, 650.0)
    y_range: tuple[float, float] = (-250.0, 250.0)
    z_range: tuple[float, float] = (250.0, 450.0)
    x_step: float = 30.0
    y_step: float = 500.0 / 14
    z_step: float = 200.0
    yaw_range: tuple[float, float] = (-math.pi, math.pi)
    yaw_step: float = TWO_PI / 12
    yaw_periodic: bool = True
    elbows: tuple[int, ...] = (1, -1)

    def __post_init__(self) -> None:
        for name in ("x", "y", "z", "yaw"):
            r = getattr(self, f"{name}_range")
            try:
                lo, hi = (float(v) for v in r)
            except (TypeError, ValueError):
                raise ConfigError(f"grid {name}_range must be two numbers (first, last node), got {r!r}") from None
            step = getattr(self, f"{name}_step")
            if not (math.isfinite(lo) and math.isfinite(hi)):
                raise ConfigError(f"grid {name}_range must be finite, got {r!r}")
            if hi < lo:
                raise ConfigError(f"grid {name}_range must be (low, high), got {r!r}")
            if not (isinstance(step, (int, float)) and math.isfinite(step) and step > 0):
                raise ConfigError(f"grid {name}_step must be a finite number > 0, got {step!r}")
            object.__setattr__(self, f"{name}_range", (lo, hi))
            object.__setattr__(self, f"{name}_step", float(step))
        if self.yaw_periodic:
            lo, hi = self.yaw_range
            if abs((hi - lo) - TWO_PI) > 1e-9:
                raise ConfigError(
                    f"a periodic yaw axis must span one full turn (2π rad), got "
                    f"{hi - lo:.9g} rad; use yaw_range=(-pi, pi) or yaw_periodic=False")
        elbows = tuple(int(e) for e in self.elbows)
        if elbows not in ((1, -1), (1,)):
            raise ConfigError(
                f"grid elbows must be (1, -1) or (1,), got {self.elbows!r}: the controller "
                f"reads configuration 0 as elbow +1 and applies a one-configuration table to "
                f"every move")
        object.__setattr__(self, "elbows", elbows)
        self.axes()  # validates the step divisions

    @classmethod
    def full_workspace(cls, **kw) -> "GridSpec":
        """The whole reference workspace x∈[350, 750], y∈[−250, 250], z∈[250, 450] mm,
        11 × 15 × 2 × 12 nodes per elbow (31 680 values): covers every target there, but the
        bound reaches ~100–260 µm in the corners at radius 760–790 mm (≈ 7–11 µm for
        radius ≤ 700 mm); check :meth:`CorrectionTable.bound_at` for the targets you use."""
        base = dict(x_range=(350.0, 750.0), x_step=40.0)
        base.update(kw)
        return cls(**base)

    # -- derived ---------------------------------------------------------------------------
    def _counts(self) -> tuple[int, int, int, int]:
        nx = _count("x", *self.x_range, self.x_step, "mm")
        ny = _count("y", *self.y_range, self.y_step, "mm")
        nz = _count("z", *self.z_range, self.z_step, "mm")
        if self.yaw_periodic:
            n = TWO_PI / self.yaw_step
            k = round(n)
            if k < 2 or abs(n - k) > _STEP_TOL * n:
                raise ConfigError(
                    f"grid yaw_step {self.yaw_step:.9g} rad does not divide a full turn "
                    f"({n:.4g} steps); use 2π/N, e.g. {TWO_PI / max(2, math.floor(n)):.9g} or "
                    f"{TWO_PI / max(2, math.ceil(n)):.9g}")
            nyaw = k
        else:
            nyaw = _count("yaw", *self.yaw_range, self.yaw_step, "rad")
        return nx, ny, nz, nyaw

    def axes(self) -> tuple[TableAxis, ...]:
        """The controller's table axes x, y, z, yaw (start and step rounded to float32)."""
        nx, ny, nz, nyaw = self._counts()
        return (
            TableAxis(self.x_range[0], self.x_step, nx),
            TableAxis(self.y_range[0], self.y_step, ny),
            TableAxis(self.z_range[0], self.z_step, nz),
            TableAxis(self.yaw_range[0], self.yaw_step, nyaw, periodic=self.yaw_periodic),
        )

    @property
    def shape(self) -> tuple[int, int, int, int]:
        return self._counts()

    @property
    def n_nodes(self) -> int:
        """Nodes per elbow configuration."""
        return int(np.prod(self.shape))

    def n_values(self, n_joints: int = 4) -> int:
        """Values the table holds: configurations × nodes × joints."""
        return len(self.elbows) * self.n_nodes * n_joints

    def check_capacity(self, n_joints: int = 4, capacity: int = MAX_TABLE_VALUES) -> None:
        n = self.n_values(n_joints)
        if n > capacity:
            raise ConfigError(
                f"correction grid {'×'.join(map(str, self.shape))} × {len(self.elbows)} elbows × "
                f"{n_joints} joints = {n} values exceeds the controller's {capacity}: use "
                f"larger steps or a smaller range")


# --------------------------------------------------------------------------------------------
# interpolation (the controller's rule, vectorised)
# --------------------------------------------------------------------------------------------

def _cell_coords(axes: tuple[TableAxis, ...], points: np.ndarray):
    """Per axis: lower node index i0 ``(m,)``, upper node index i1 and weight t, exactly as
    :meth:`CorrectionTableData.interpolate`. Raises :class:`TableRangeError` outside."""
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
    targets in the base frame): the controller's multilinear rule, vectorised, in float64."""
    p = np.atleast_2d(np.asarray(points, dtype=float))
    n = len(data.axes)
    if p.shape[1] < n:
        raise TableError(f"interpolation needs {n} coordinates per point, got {p.shape[1]}")
    if not 0 <= config < data.n_configs:
        raise TableError(f"configuration {config} not in table (n_configs={data.n_configs})")
    cc = _cell_coords(data.axes, p)
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


# --------------------------------------------------------------------------------------------
# inverse kinematics with per-target reachability
# --------------------------------------------------------------------------------------------

def _targets(points: np.ndarray) -> np.ndarray:
    """(m, 4) x, y, z, yaw -> (m, 4, 4) base-frame targets with roll = pitch = 0."""
    pose = np.zeros((points.shape[0], 6))
    pose[:, :3] = points[:, :3]
    pose[:, 5] = points[:, 3]
    return pose_to_matrix(pose)


def _ik_masked(model: RobotModel, params: np.ndarray, T: np.ndarray, elbow: int):
    """SCARA IK per target: ``(q (m, g) with NaN where unreachable, ok (m,) bool)``.

    Joint limits are NOT applied (a table value beyond a limit is the smooth continuation the
    interpolation needs; the controller checks the limits of what it commands). A target counts
    as unreachable where the closed form has no solution or Newton does not reproduce it."""
    m = T.shape[0]
    q = np.full((m, model.n_joints), np.nan)
    ok = np.zeros(m, dtype=bool)

    def solve(idx: np.ndarray) -> None:
        if idx.size == 0:
            return
        try:
            with np.errstate(all="ignore"):
                qq = scara_ik(model, T[idx], elbow=elbow, params=params, setup=False,
                              check_limits=False)
        except (UnreachableError, np.linalg.LinAlgError):
            if idx.size == 1:
                return
            mid = idx.size // 2
            solve(idx[:mid])
            solve(idx[mid:])
            return
        good = np.all(np.isfinite(qq), axis=1)
        if np.any(good):
            Tq = forward(model, qq[good], params, setup=False)
            good[good] = np.linalg.norm(Tq[:, :3, 3] - T[idx[good], :3, 3], axis=1) < _IK_CHECK_MM
        q[idx[good]] = qq[good]
        ok[idx[good]] = True

    solve(np.flatnonzero(_planar_reachable(params, T)))
    return q, ok


def _planar_reachable(params: np.ndarray, T: np.ndarray, margin: float = 1e-9) -> np.ndarray:
    """Pre-filter: the wrist point lies inside the annulus of the two arms (ideal SCARA
    geometry read from the parameters as :func:`scara_ik` does), so that one unreachable target
    does not fail a whole vectorised call. Cheap; borderline cases are settled by the IK."""
    P = np.asarray(params, dtype=float).reshape(-1, 6)
    psi = np.arctan2(T[:, 1, 0], T[:, 0, 0])
    c3, s3 = np.cos(P[3, 5]), np.sin(P[3, 5])
    a2 = P[2, :2]
    a3 = P[3, :2] + np.array([c3 * P[4, 0] - s3 * P[4, 1], s3 * P[4, 0] + c3 * P[4, 1]])
    k = P[5, :2]
    ck, sk = np.cos(psi - P[5, 5]), np.sin(psi - P[5, 5])
    wx = T[:, 0, 3] - P[1, 0] - (ck * k[0] - sk * k[1])
    wy = T[:, 1, 3] - P[1, 1] - (sk * k[0] + ck * k[1])
    L1, L2 = np.hypot(*a2), np.hypot(*a3)
    c_beta = (wx**2 + wy**2 - L1**2 - L2**2) / (2 * L1 * L2)
    return np.abs(c_beta) <= 1.0 - margin


def _is_scara(model: RobotModel) -> bool:
    return model.joint_types == ("revolute", "revolute", "prismatic", "revolute")


def _delta(model: RobotModel, q_id: np.ndarray, q_nom: np.ndarray) -> np.ndarray:
    d = q_id - q_nom
    rev = np.array([t == "revolute" for t in model.joint_types])
    d[..., rev] = wrap_angle(d[..., rev])
    return d


# --------------------------------------------------------------------------------------------
# the table
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class InterpolationError:
    """Pose error that the table's interpolation leaves, over ``n_points`` targets.

    Position [µm]: distance between the position the identified robot reaches with
    ``q_nom + interpolated Δq`` and the target. Orientation [″]: angle between the orientation it
    reaches and the one the exact correction (``IK_identified``) reaches — for a SCARA this is
    the yaw error; roll and pitch follow from the axis tilts and no joint correction changes
    them (``uncorrectable_tilt_arcsec`` reports their size for information).
    ``worst``: (x, y, z, yaw, elbow) of the largest position error.
    """

    max_position_um: float
    rms_position_um: float
    max_orientation_arcsec: float
    rms_orientation_arcsec: float
    n_points: int
    worst: tuple[float, ...] = ()
    uncorrectable_tilt_arcsec: float = 0.0


@dataclass(frozen=True, eq=False)
class CorrectionTable:
    """A built correction table and what is known about it.

    ``data``: what the controller receives. ``reachable``: ``(n_configs, *grid_shape)`` bool,
    nodes where both models have an IK solution; the others (``unreachable_nodes`` of them) carry
    the value of the nearest reachable node (index distance). ``interpolation_bound_um`` /
    ``_arcsec``: bound of the interpolation error over all cells whose corners are all reachable
    (see :func:`build_correction_table`). ``max_correction``: ``(n_joints,)`` largest |Δq| per
    joint over reachable nodes [rad | mm]. ``check``: the sampled check the bound includes.
    """

    data: CorrectionTableData
    grid: GridSpec
    reachable: np.ndarray
    unreachable_nodes: int
    interpolation_bound_um: float
    interpolation_bound_arcsec: float
    max_correction: np.ndarray
    edge_bound_um: float = math.nan
    edge_bound_arcsec: float = math.nan
    check: InterpolationError | None = None
    elbows: tuple[int, ...] = (1, -1)
    cell_bound_um: np.ndarray | None = None
    cell_bound_arcsec: np.ndarray | None = None

    @property
    def n_values(self) -> int:
        return self.data.n_values

    def bound_at(self, points, elbow: int = 1) -> np.ndarray:
        """Interpolation bound [µm] of the cell of each target ``(m, 4)`` (x, y, z, yaw):
        the per-cell edge bound (NaN for a cell with an unreachable corner). Raises
        :class:`TableRangeError` for a target outside the grid."""
        if self.cell_bound_um is None:
            raise ValueError("this table carries no per-cell bound")
        p = np.atleast_2d(np.asarray(points, dtype=float))
        c = self.elbows.index(int(elbow)) if int(elbow) in self.elbows else 0
        cc = _cell_coords(self.data.axes, p)
        return self.cell_bound_um[c][tuple(i0 for i0, _, _ in cc)]

    def summary(self) -> dict:
        """Figures for reports (JSON-friendly)."""
        return {
            "grid_shape": list(self.data.grid_shape),
            "n_configs": self.data.n_configs,
            "n_values": self.n_values,
            "crc32": f"{self.data.crc32():#010x}",
            "unreachable_nodes": self.unreachable_nodes,
            "interpolation_bound_um": self.interpolation_bound_um,
            "interpolation_bound_arcsec": self.interpolation_bound_arcsec,
            "max_correction": [float(v) for v in self.max_correction],
        }


def _node_points(axes: tuple[TableAxis, ...]) -> np.ndarray:
    grids = np.meshgrid(*[a.nodes for a in axes], indexing="ij")
    return np.stack([g.ravel() for g in grids], axis=-1)


def _fill_nearest(values: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """Give unreachable nodes the value of the nearest reachable node (grid-index distance)."""
    from scipy.ndimage import distance_transform_edt

    if ok.all():
        return values
    _, idx = distance_transform_edt(~ok, return_indices=True)
    return values[tuple(idx)]


def _pose_errors(nominal: RobotModel, identified: np.ndarray, points: np.ndarray, elbow: int,
                 corr: np.ndarray, q_nom: np.ndarray, q_id: np.ndarray):
    """Position [µm] and orientation [″] errors of q_nom + corr on the identified robot."""
    T = _targets(points)
    T_reach = forward(nominal, q_nom + corr, identified, setup=False)
    T_exact = forward(nominal, q_id, identified, setup=False)
    pos = np.linalg.norm(T_reach[:, :3, 3] - T[:, :3, 3], axis=1) * 1000.0
    dR = T_reach[:, :3, :3] @ np.swapaxes(T_exact[:, :3, :3], -1, -2)
    ori = np.linalg.norm(rotation_log(dR), axis=1) / ARCSEC
    tilt_R = T_exact[:, :3, :3] @ np.swapaxes(T[:, :3, :3], -1, -2)
    tilt = np.linalg.norm(rotation_log(tilt_R)[:, :2], axis=1) / ARCSEC
    return pos, ori, tilt


def _cells_shape(axes) -> tuple[int, ...]:
    return tuple(a.count if a.periodic else max(a.count - 1, 1) for a in axes)


def _reduce_to_cells(E: np.ndarray, axes, skip: int | None) -> np.ndarray:
    """Max over the nodes of each cell along every axis except ``skip`` (E: (cfg, *shape))."""
    for j, a in enumerate(axes):
        if j == skip or a.count == 1:
            continue
        ax = j + 1
        if a.periodic:
            E = np.maximum(E, np.roll(E, -1, axis=ax))
        else:
            n = E.shape[ax]
            E = np.maximum(E.take(range(0, n - 1), axis=ax), E.take(range(1, n), axis=ax))
    return E


def _edge_bound(data: CorrectionTableData, nominal: RobotModel, identified: np.ndarray,
                elbows: tuple[int, ...], reachable: np.ndarray):
    """Per cell, the sum over axes of the largest error at the midpoints of the cell's edges
    along that axis; the maximum over all fully reachable cells. Multilinear interpolation is
    the tensor product of 1-D linear interpolations, so its error is at most the sum of the 1-D
    errors, and each 1-D error is largest at an edge midpoint where the correction is locally
    quadratic (fine grids)."""
    axes = data.axes
    shape = data.grid_shape
    cells = _cells_shape(axes)
    cell_ok = _reduce_to_cells(~reachable, axes, None)  # any unreachable corner
    cell_ok = ~cell_ok.astype(bool)
    Bp = np.zeros((len(elbows),) + cells)
    Bo = np.zeros((len(elbows),) + cells)
    nodes = [a.nodes for a in axes]
    for k, a in enumerate(axes):
        if a.count == 1:
            continue
        n_edges = a.count if a.periodic else a.count - 1
        coords = list(nodes)
        coords[k] = a.start + a.step * (np.arange(n_edges) + 0.5)
        grids = np.meshgrid(*coords, indexing="ij")
        pts = np.stack([g.ravel() for g in grids], axis=-1)
        eshape = tuple(n_edges if j == k else shape[j] for j in range(len(axes)))
        Ep = np.full((len(elbows),) + eshape, np.nan)
        Eo = np.full((len(elbows),) + eshape, np.nan)
        for c, elbow in enumerate(elbows):
            T = _targets(pts)
            q_nom, ok1 = _ik_masked(nominal, nominal.nominal, T, elbow)
            q_id, ok2 = _ik_masked(nominal, identified, T, elbow)
            ok = ok1 & ok2
            corr = interpolate_table(data, pts[ok], c)
            pos, ori, _ = _pose_errors(nominal, identified, pts[ok], elbow, corr, q_nom[ok], q_id[ok])
            ep = np.full(len(pts), np.nan)
            eo = np.full(len(pts), np.nan)
            ep[ok], eo[ok] = pos, ori
            Ep[c], Eo[c] = ep.reshape(eshape), eo.reshape(eshape)
        Bp += _reduce_to_cells(Ep, axes, k)
        Bo += _reduce_to_cells(Eo, axes, k)
    Bp[~cell_ok] = np.nan
    Bo[~cell_ok] = np.nan
    bp, bo = Bp[np.isfinite(Bp)], Bo[np.isfinite(Bo)]
    return (float(bp.max()) if bp.size else math.nan, float(bo.max()) if bo.size else math.nan,
            Bp, Bo)


def build_correction_table(nominal: RobotModel, identified_params, grid: GridSpec | None = None,
                           *, n_check: int = 4000, seed: int = 0) -> CorrectionTable:
    """Joint-correction table for a SCARA: Δq = IK_identified − IK_nominal at every node.

    ``nominal``: the model the controller uses (its ``nominal`` parameters); ``identified_params``:
    ``(n_params,)`` identified parameters of the same model [mm, rad] (the set-up R is not used).
    Nodes where either model has no IK solution get the nearest reachable node's value and are
    counted in ``unreachable_nodes``; the interpolation bound covers the cells whose corners are
    all reachable (a target in a cell touching an unreachable node is not covered by it).

    The reported bound is the larger of (a) the per-cell sum of edge-midpoint errors (see
    :func:`_edge_bound`) and (b) the largest error of :func:`interpolation_error` at all cell
    centres and ``n_check`` random points (seeded by ``seed``).
    Raises :class:`ConfigError` for a non-SCARA model, a table over capacity, or a grid with no
    reachable node.
    """
    grid = GridSpec() if grid is None else grid
    if not _is_scara(nominal):
        raise ConfigError(
            f"robot {nominal.name!r} is not a SCARA (R R P R): a correction grid over x, y, z, yaw "
            f"does not describe it; use compensated_targets() for this robot")
    identified = np.asarray(identified_params, dtype=float)
    if identified.shape != nominal.nominal.shape or not np.all(np.isfinite(identified)):
        raise ConfigError(f"identified parameters must be a finite vector of {nominal.n_params} values")
    g = nominal.n_joints
    grid.check_capacity(g)
    axes = grid.axes()
    shape = tuple(a.count for a in axes)
    pts = _node_points(axes)
    T = _targets(pts)
    n_cfg = len(grid.elbows)
    values = np.zeros((n_cfg,) + shape + (g,))
    reachable = np.zeros((n_cfg,) + shape, dtype=bool)
    for c, elbow in enumerate(grid.elbows):
        q_nom, ok1 = _ik_masked(nominal, nominal.nominal, T, elbow)
        q_id, ok2 = _ik_masked(nominal, identified, T, elbow)
        ok = (ok1 & ok2).reshape(shape)
        if not ok.any():
            raise ConfigError(
                f"no node of the correction grid is reachable with elbow {elbow:+d}: check the "
                f"grid ranges (base frame, mm) against the robot's reach")
        d = np.where((ok1 & ok2)[:, None], _delta(nominal, q_id, q_nom), 0.0).reshape(shape + (g,))
        values[c] = _fill_nearest(d, ok)
        reachable[c] = ok
    data = CorrectionTableData(axes, values.astype(np.float32))
    max_corr = np.max(np.abs(values[reachable]), axis=0)
    reachable.setflags(write=False)
    eb_um, eb_as, cb_um, cb_as = _edge_bound(data, nominal, identified, grid.elbows, reachable)
    pre = CorrectionTable(data, grid, reachable, int((~reachable).sum()), math.nan, math.nan,
                          max_corr, elbows=grid.elbows)
    chk = interpolation_error(pre, nominal, identified, n_samples=n_check,
                              rng=np.random.default_rng(seed))
    bound_um = float(np.nanmax([eb_um, chk.max_position_um]))
    bound_as = float(np.nanmax([eb_as, chk.max_orientation_arcsec]))
    cb_um.setflags(write=False)
    cb_as.setflags(write=False)
    return CorrectionTable(data, grid, reachable, int((~reachable).sum()), bound_um, bound_as,
                           max_corr, eb_um, eb_as, chk, grid.elbows, cb_um, cb_as)


def _cell_points_ok(table: CorrectionTable, points: np.ndarray, config: int) -> np.ndarray:
    """(m,) bool: every corner of the point's cell is reachable."""
    cc = _cell_coords(table.data.axes, points)
    ok = np.ones(points.shape[0], dtype=bool)
    n = len(cc)
    R = table.reachable[config]
    for corner in range(1 << n):
        idx = tuple(cc[k][1] if (corner >> k) & 1 else cc[k][0] for k in range(n))
        ok &= R[idx]
    return ok


def interpolation_error(table: CorrectionTable, nominal: RobotModel, identified_params,
                        n_samples: int = 2000, rng: np.random.Generator | None = None,
                        cell_centres: bool = True) -> InterpolationError:
    """Pose error the table leaves on the identified robot.

    Targets: ``n_samples`` uniform random points inside the grid (spread over the elbow
    configurations) and, with ``cell_centres``, the centre of every cell; only targets whose
    cell corners are all reachable and that both models reach. For each: the controller's
    ``q_nom + interpolated Δq``, the pose the identified robot reaches with it, compared with the
    target (position) and with the exactly corrected pose (orientation); see
    :class:`InterpolationError`.
    """
    rng = np.random.default_rng() if rng is None else rng
    identified = np.asarray(identified_params, dtype=float)
    axes = table.data.axes
    elbows = table.elbows
    lo = np.array([a.start for a in axes])
    span = np.array([a.step * (a.count if a.periodic else a.count - 1) for a in axes])
    cells = _cells_shape(axes)
    centre_axes = [a.start + a.step * (np.arange(cells[k]) + (0.0 if a.count == 1 else 0.5))
                   for k, a in enumerate(axes)]
    centres = np.stack([g.ravel() for g in np.meshgrid(*centre_axes, indexing="ij")], axis=-1)
    pos_all, ori_all, tilt_all, worst = [], [], [], ()
    worst_val = -1.0
    per_cfg = [n_samples // len(elbows) + (1 if c < n_samples % len(elbows) else 0)
               for c in range(len(elbows))]
    for c, elbow in enumerate(elbows):
        pts = lo + rng.random((per_cfg[c], len(axes))) * span
        if cell_centres:
            pts = np.concatenate([pts, centres])
        if pts.shape[0] == 0:
            continue
        ok = _cell_points_ok(table, pts, c)
        T = _targets(pts)
        q_nom, ok1 = _ik_masked(nominal, nominal.nominal, T, elbow)
        q_id, ok2 = _ik_masked(nominal, identified, T, elbow)
        ok &= ok1 & ok2
        if not ok.any():
            continue
        corr = interpolate_table(table.data, pts[ok], c)
        pos, ori, tilt = _pose_errors(nominal, identified, pts[ok], elbow, corr, q_nom[ok], q_id[ok])
        pos_all.append(pos)
        ori_all.append(ori)
        tilt_all.append(tilt)
        j = int(np.argmax(pos))
        if pos[j] > worst_val:
            worst_val = float(pos[j])
            worst = tuple(float(v) for v in pts[ok][j]) + (float(elbow),)
    if not pos_all:
        return InterpolationError(math.nan, math.nan, math.nan, math.nan, 0)
    pos, ori, tilt = np.concatenate(pos_all), np.concatenate(ori_all), np.concatenate(tilt_all)
    return InterpolationError(
        max_position_um=float(pos.max()), rms_position_um=float(np.sqrt(np.mean(pos**2))),
        max_orientation_arcsec=float(ori.max()), rms_orientation_arcsec=float(np.sqrt(np.mean(ori**2))),
        n_points=int(pos.size), worst=worst, uncorrectable_tilt_arcsec=float(tilt.max()),
    )


# --------------------------------------------------------------------------------------------
# compensated targets (robots without a grid)
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class CompensatedTargets:
    """``joints`` ``(n, g)``: joints that put the identified robot on the targets.
    ``commands`` ``(n, 4, 4)``: Cartesian targets (controller base frame) to give the NOMINAL
    controller so that it commands those joints: ``FK_nominal(joints)``.
    ``residual_um`` ``(n,)``: position the identified robot misses the target by with
    ``joints`` (≈ 0; for chains with fewer than six joints the orientation it cannot reach is
    ignored, and for a SCARA roll and pitch are).
    """

    joints: np.ndarray
    commands: np.ndarray
    residual_um: np.ndarray


def compensated_targets(nominal: RobotModel, identified_params, targets, q0,
                        setup: bool = False) -> CompensatedTargets:
    """Compensated Cartesian targets for a controller that keeps its nominal model.

    ``targets`` ``(n, 4, 4)``: where the tool shall be, in the robot base frame (or, with
    ``setup=True``, in the measurement frame; the identified set-up R converts them).
    ``q0`` ``(n, g)``: start joints choosing the configuration (for a SCARA the elbow is the
    sign of q0's second joint and the closed-form IK is used; other robots go through
    :func:`station.core.kinematics.inverse_kinematics` on the identified model).
    The controller, given ``commands`` and the same configuration, solves its nominal IK to
    exactly ``joints``, so the real robot ends where intended. Raises
    :class:`UnreachableError` where the identified robot cannot reach a target.
    """
    identified = np.asarray(identified_params, dtype=float)
    if identified.shape != nominal.nominal.shape:
        raise ConfigError(f"identified parameters must be a vector of {nominal.n_params} values")
    Tt = np.asarray(targets, dtype=float).reshape(-1, 4, 4)
    q0 = np.asarray(q0, dtype=float).reshape(Tt.shape[0], nominal.n_joints)
    if setup:
        Tt = invert(pose_to_matrix(identified[0:6]))[None] @ Tt
    if _is_scara(nominal):
        joints = np.empty_like(q0)
        elbow = np.where(q0[:, 1] >= 0.0, 1, -1)
        for e in (1, -1):
            sel = elbow == e
            if sel.any():
                joints[sel] = scara_ik(nominal, Tt[sel], elbow=e, params=identified, setup=False)
    else:
        joints = inverse_kinematics(nominal, Tt, q0, params=identified, setup=False)
    reached = forward(nominal, joints, identified, setup=False)
    residual = np.linalg.norm(reached[:, :3, 3] - Tt[:, :3, 3], axis=1) * 1000.0
    commands = forward(nominal, joints, nominal.nominal, setup=False)
    return CompensatedTargets(joints, commands, residual)


# --------------------------------------------------------------------------------------------
# verified upload
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class UploadReport:
    """Outcome of :func:`upload_verified` (times in seconds)."""

    crc32: int
    n_values: int
    upload_s: float
    readback_s: float
    stage_s: float
    activate_s: float
    total_s: float
    staged_crc32: int | None = None
    active_crc32: int | None = None
    previous_crc32: int | None = None
    notes: tuple[str, ...] = field(default=())


def _crcs(controller: Any) -> dict[str, int] | None:
    fn = getattr(controller, "table_crcs", None)
    if fn is None:
        return None
    try:
        return {k: int(v) for k, v in fn().items()}
    except Exception:  # noqa: BLE001 - a state read must not mask the real error
        return None


def upload_verified(controller: Any, table: CorrectionTableData,
                    on_event: Callable[[Event], None] | None = None) -> UploadReport:
    """Upload ``table``, read every value back, compare, stage, activate; roll back on failure.

    Sequence: ``upload_table`` → ``read_table`` → value-by-value and CRC comparison (any
    difference raises :class:`TableVerifyError` naming the first differing value; nothing is
    staged or activated) → ``stage_table`` → staged CRC check where the controller reports it
    (``table_crcs``) → ``activate_table`` → active CRC check. If activation fails, the
    previous table is made active again with ``rollback_table`` unless the controller reports
    that its active table did not change, and the original error is re-raised (a failed roll
    back is added to it as a note). A table that was not read back identical is never
    activated.
    """
    def emit(ev: Event) -> None:
        if on_event is not None:
            on_event(ev)

    if not isinstance(table, CorrectionTableData):
        raise TypeError("upload_verified needs a drivers.controller.CorrectionTableData (table.data)")
    crc = table.crc32()
    t_start = time.perf_counter()
    emit(PhaseChanged("upload", f"{table.n_values} values, CRC-32 {crc:#010x}"))

    t0 = time.perf_counter()
    controller.upload_table(table)
    t_up = time.perf_counter() - t0
    emit(Notice("info", f"table uploaded ({table.n_values} values) in {t_up:.2f} s; reading back"))

    t0 = time.perf_counter()
    back = controller.read_table()
    t_rb = time.perf_counter() - t0
    if not isinstance(back, CorrectionTableData):
        raise TableVerifyError("read_table() returned no table: not activated; upload again")
    diff = table.first_difference(back)
    if diff is None and back.crc32() != crc:  # pragma: no cover - implied by the value check
        diff = f"CRC-32 {back.crc32():#010x} != uploaded {crc:#010x}"
    if diff is not None:
        msg = (f"correction table read back from the controller differs from the upload: {diff}; "
               f"the table was NOT activated: upload it again and check the link / word order")
        emit(Notice("warning", msg))
        raise TableVerifyError(msg)
    emit(Notice("info", f"read back {back.n_values} values identical, CRC-32 {crc:#010x}"))

    t0 = time.perf_counter()
    controller.stage_table()
    t_st = time.perf_counter() - t0
    before = _crcs(controller)
    if before is not None and before.get("staged") != crc:
        msg = (f"controller's staged table CRC-32 {before.get('staged', 0):#010x} is not the "
               f"uploaded {crc:#010x}: NOT activated; upload again")
        emit(Notice("warning", msg))
        raise TableVerifyError(msg)

    t0 = time.perf_counter()
    try:
        controller.activate_table()
        after = _crcs(controller)
        if after is not None and after.get("active") != crc:
            raise TableVerifyError(
                f"controller reports active table CRC-32 {after.get('active', 0):#010x} after "
                f"activation, expected {crc:#010x}")
    except BaseException as exc:
        now = _crcs(controller)
        unchanged = (before is not None and now is not None
                     and now.get("active") == before.get("active") and now.get("active") != crc)
        if unchanged:
            note = "activation failed; the controller's previous table is still active (no roll back needed)"
            emit(Notice("warning", f"{note}: {exc}"))
        else:
            emit(Notice("warning", f"activation failed ({exc}); rolling back to the previous table"))
            try:
                controller.rollback_table()
                note = "rolled back to the previous table"
            except Exception as rb_exc:  # noqa: BLE001
                note = (f"roll back failed too ({rb_exc}); deactivate the table on the "
                        f"controller before moving")
            emit(Notice("warning", note))
        if hasattr(exc, "add_note"):
            exc.add_note(note)
        raise
    t_act = time.perf_counter() - t0
    final = _crcs(controller) or {}
    total = time.perf_counter() - t_start
    emit(Notice("info", f"correction table active, CRC-32 {crc:#010x} ({total:.2f} s)"))
    return UploadReport(crc, table.n_values, t_up, t_rb, t_st, t_act, total,
                        staged_crc32=None if before is None else before.get("staged"),
                        active_crc32=final.get("active"), previous_crc32=final.get("previous"))
