"""Joint-correction tables for a SCARA (brief §8): build one from an identified model, and
bound the error its interpolation leaves.

The controller keeps its NOMINAL kinematics. For a Cartesian target T (x, y, z, yaw in the robot
base frame) it computes ``q_nom = IK_nominal(T, elbow)`` and adds the multilinear interpolation of
a table of joint corrections::

    Δq(node, elbow) = IK_identified(T_node, elbow) − IK_nominal(T_node, elbow)

(revolute differences wrapped to (−π, π]), so that the real robot — described by the identified
model — reaches what the nominal model promised.

With error terms beyond geometry (issue 30, docs/error-terms.md: joint compliance, gear
harmonics) the identified robot stands at ``q + δ(q)`` when it is commanded ``q`` (δ evaluated at
the commanded joints, as :mod:`station.core.terms.error_model` fits it). A node's value is then
``q_cmd − IK_nominal(T_node)`` with ``q_cmd`` the joints at which the identified model *with its
terms* reaches the node: ``FK_identified(q_cmd + δ(q_cmd)) = T_node``, the fixed point
``q_cmd = IK_identified(T_node) − δ(q_cmd)`` (:func:`station.core.terms.compensation.commanded_joints`).
The interpolation bound is evaluated on the same robot: the pose reached at
``q + δ(q)``, ``q = q_nom + interpolated Δq``. The grid and the interpolation rule are in
:mod:`station.core.table.grid`; robots without a table use :mod:`station.core.kinematics.compensation`;
the verified upload is the cell's (:mod:`station.cell.correction.upload`). Pure numerics: mm and rad
inside, µm and arc seconds only in reported figures.

Frames: targets are in the robot base frame as the *identified* chain defines it (the chain
without the set-up R: ``forward(..., setup=False)``); the table never uses R.
"""

from __future__ import annotations

import hashlib
import math
import threading
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from station.core.kinematics.forward import forward, scara_ik
from station.core.kinematics.model import RobotModel
from station.core.kinematics.transforms import pose_to_matrix, rotation_log
from station.core.table.grid import GridSpec
from station.core.table.values import CorrectionTableData, TableAxis, cell_coords, interpolate_table
from station.core.terms.compensation import JointDelta, commanded_joints
from station.core.units import ARCSEC, wrap_angle
from station.errors import ConfigError, UnreachableError

__all__ = [
    "CorrectionTable",
    "InterpolationCheck",
    "build_correction_table",
    "interpolation_error",
    "node_joints",
]

#: an IK solution must reproduce the target position to this [mm] to count as reached
_IK_CHECK_MM = 1e-6
#: IK results kept (the largest, a curvature lattice's ~17 500 targets, ~0.6 MB each)
_IK_CACHE_SIZE = 48
_IK_CACHE: OrderedDict[bytes, tuple[np.ndarray, np.ndarray]] = OrderedDict()
_IK_LOCK = threading.Lock()


def _targets(points: np.ndarray) -> np.ndarray:
    """(m, 4) x, y, z, yaw -> (m, 4, 4) base-frame targets with roll = pitch = 0."""
    pose = np.zeros((points.shape[0], 6))
    pose[:, :3] = points[:, :3]
    pose[:, 5] = points[:, 3]
    return pose_to_matrix(pose)


def _ik_key(model: RobotModel, params: np.ndarray, T: np.ndarray, elbow: int) -> bytes:
    """Digest of everything :func:`_solve_masked` reads: the chain's structure, the parameters,
    the targets and the elbow (not the limits: they are not applied)."""
    h = hashlib.blake2b(digest_size=32)
    h.update(repr((model.transforms, int(elbow), T.shape, params.shape)).encode())
    h.update(np.ascontiguousarray(params, dtype=float).tobytes())
    h.update(np.ascontiguousarray(T, dtype=float).tobytes())
    return h.digest()


def _ik_masked(model: RobotModel, params: np.ndarray, T: np.ndarray, elbow: int):
    """SCARA IK per target: ``(q (m, g) with NaN where unreachable, ok (m,) bool)``.

    Joint limits are NOT applied (a table value beyond a limit is the smooth continuation the
    interpolation needs; the controller checks the limits of what it commands). A target counts
    as unreachable where the closed form has no solution or Newton does not reproduce it.

    Results are kept for the last :data:`_IK_CACHE_SIZE` inputs: a design builds the table of
    every sampled robot on one grid, and each build solved the nominal model at the same nodes,
    edge midpoints and seeded check points again (identical inputs: the key is their digest)."""
    key = _ik_key(model, params, T, elbow)
    with _IK_LOCK:
        hit = _IK_CACHE.get(key)
        if hit is not None:
            _IK_CACHE.move_to_end(key)
    if hit is None:
        hit = _solve_masked(model, params, T, elbow)
        for a in hit:
            a.setflags(write=False)
        with _IK_LOCK:
            _IK_CACHE[key] = hit
            while len(_IK_CACHE) > _IK_CACHE_SIZE:
                _IK_CACHE.popitem(last=False)
    return hit[0].copy(), hit[1].copy()


def _solve_masked(model: RobotModel, params: np.ndarray, T: np.ndarray, elbow: int):
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


def node_joints(model: RobotModel, params, T: np.ndarray, elbow: int, delta: JointDelta | None = None):
    """The joints to command so that the robot ``params`` (``(n_params,)`` [mm, rad]) with the
    joint errors ``delta`` reaches each target ``T`` ``(m, 4, 4)`` (base frame, x, y, z, yaw):
    ``(q (m, g) [rad | mm] with NaN where unreachable, ok (m,) bool)``. Without ``delta``, the
    IK of ``params``; with it, the fixed point ``q = IK(T) − δ(q)`` (a row whose fixed point does
    not converge counts as unreachable)."""
    p = np.asarray(params, dtype=float)
    q, ok = _ik_masked(model, p, np.asarray(T, dtype=float).reshape(-1, 4, 4), elbow)
    if delta is None or not ok.any():
        return q, ok
    qc, conv = commanded_joints(q[ok], delta)
    q[ok] = qc
    q[np.flatnonzero(ok)[~conv]] = np.nan
    ok[np.flatnonzero(ok)[~conv]] = False
    return q, ok


def _stands(q: np.ndarray, delta: JointDelta | None) -> np.ndarray:
    """Where a robot commanded ``q`` ``(m, g)`` stands: ``q + δ(q)`` (``q`` without terms)."""
    return q if delta is None or not q.size else q + delta(q)


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


def _delta(model: RobotModel, q_id: np.ndarray, q_nom: np.ndarray) -> np.ndarray:
    d = q_id - q_nom
    rev = np.array([t == "revolute" for t in model.joint_types])
    d[..., rev] = wrap_angle(d[..., rev])
    return d


# --------------------------------------------------------------------------------------------
# the table
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class InterpolationCheck:
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
    ``delta``: the error terms' joint error ``q ↦ δ(q)`` the nodes were solved with (None: the
    geometric model; see :func:`build_correction_table`).
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
    check: InterpolationCheck | None = None
    elbows: tuple[int, ...] = (1, -1)
    cell_bound_um: np.ndarray | None = None
    cell_bound_arcsec: np.ndarray | None = None
    delta: JointDelta | None = None

    @property
    def with_terms(self) -> bool:
        """The nodes carry error terms beyond geometry (``delta``)."""
        return self.delta is not None

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
        cc = cell_coords(self.data.axes, p)
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
                 corr: np.ndarray, q_nom: np.ndarray, q_id: np.ndarray, delta: JointDelta | None = None):
    """Position [µm] and orientation [″] errors of q_nom + corr on the identified robot (standing
    at ``q + δ(q)`` with terms); ``q_id``: its geometry's IK of the targets (where it must stand)."""
    T = _targets(points)
    T_reach = forward(nominal, _stands(q_nom + corr, delta), identified, setup=False)
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
                elbows: tuple[int, ...], reachable: np.ndarray, delta: JointDelta | None = None):
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
            pos, ori, _ = _pose_errors(nominal, identified, pts[ok], elbow, corr, q_nom[ok], q_id[ok], delta)
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
                           *, n_check: int = 4000, seed: int = 0, capacity: int | None = None,
                           delta: JointDelta | None = None) -> CorrectionTable:
    """Joint-correction table for a SCARA: Δq = IK_identified − IK_nominal at every node.

    ``nominal``: the model the controller uses (its ``nominal`` parameters); ``identified_params``:
    ``(n_params,)`` identified parameters of the same model [mm, rad] (the set-up R is not used).
    ``delta``: the identified error terms' joint error ``q ↦ δ(q)`` ``(n, g)`` → ``(n, g)``
    [rad | mm] at the commanded joints (None: geometric); the nodes are then the joints at which
    the robot with its terms reaches them (:func:`node_joints`), and the bound is evaluated on that
    robot (see the module).
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
    if not nominal.is_scara:
        raise ConfigError(
            f"robot {nominal.name!r} is not a SCARA (R R P R): a correction grid over x, y, z, yaw "
            f"does not describe it; use compensated_targets() for this robot")
    identified = np.asarray(identified_params, dtype=float)
    if identified.shape != nominal.nominal.shape or not np.all(np.isfinite(identified)):
        raise ConfigError(f"identified parameters must be a finite vector of {nominal.n_params} values")
    g = nominal.n_joints
    if capacity is not None:  # the controller's limit: the caller knows its controller
        grid.check_capacity(g, capacity)
    axes = grid.axes()
    shape = tuple(a.count for a in axes)
    pts = _node_points(axes)
    T = _targets(pts)
    n_cfg = len(grid.elbows)
    values = np.zeros((n_cfg,) + shape + (g,))
    reachable = np.zeros((n_cfg,) + shape, dtype=bool)
    for c, elbow in enumerate(grid.elbows):
        q_nom, ok1 = _ik_masked(nominal, nominal.nominal, T, elbow)
        q_cmd, ok2 = node_joints(nominal, identified, T, elbow, delta)
        ok = (ok1 & ok2).reshape(shape)
        if not ok.any():
            raise ConfigError(
                f"no node of the correction grid is reachable with elbow {elbow:+d}: check the "
                f"grid ranges (base frame, mm) against the robot's reach")
        d = np.where((ok1 & ok2)[:, None], _delta(nominal, q_cmd, q_nom), 0.0).reshape(shape + (g,))
        values[c] = _fill_nearest(d, ok)
        reachable[c] = ok
    data = CorrectionTableData(axes, values.astype(np.float32))
    max_corr = np.max(np.abs(values[reachable]), axis=0)
    reachable.setflags(write=False)
    eb_um, eb_as, cb_um, cb_as = _edge_bound(data, nominal, identified, grid.elbows, reachable, delta)
    pre = CorrectionTable(data, grid, reachable, int((~reachable).sum()), math.nan, math.nan,
                          max_corr, elbows=grid.elbows, delta=delta)
    chk = interpolation_error(pre, nominal, identified, n_samples=n_check,
                              rng=np.random.default_rng(seed))
    bound_um = float(np.nanmax([eb_um, chk.max_position_um]))
    bound_as = float(np.nanmax([eb_as, chk.max_orientation_arcsec]))
    cb_um.setflags(write=False)
    cb_as.setflags(write=False)
    return CorrectionTable(data, grid, reachable, int((~reachable).sum()), bound_um, bound_as,
                           max_corr, eb_um, eb_as, chk, grid.elbows, cb_um, cb_as, delta)


def _cell_points_ok(table: CorrectionTable, points: np.ndarray, config: int) -> np.ndarray:
    """(m,) bool: every corner of the point's cell is reachable."""
    cc = cell_coords(table.data.axes, points)
    ok = np.ones(points.shape[0], dtype=bool)
    n = len(cc)
    R = table.reachable[config]
    for corner in range(1 << n):
        idx = tuple(cc[k][1] if (corner >> k) & 1 else cc[k][0] for k in range(n))
        ok &= R[idx]
    return ok


def interpolation_error(table: CorrectionTable, nominal: RobotModel, identified_params,
                        n_samples: int = 2000, rng: np.random.Generator | None = None,
                        cell_centres: bool = True, delta: JointDelta | None = None) -> InterpolationCheck:
    """Pose error the table leaves on the identified robot.

    Targets: ``n_samples`` uniform random points inside the grid (spread over the elbow
    configurations) and, with ``cell_centres``, the centre of every cell; only targets whose
    cell corners are all reachable and that both models reach. For each: the controller's
    ``q_nom + interpolated Δq``, the pose the identified robot reaches with it, compared with the
    target (position) and with the exactly corrected pose (orientation); see
    :class:`InterpolationCheck`. ``delta``: the robot's joint errors beyond geometry (default the
    table's own, :attr:`CorrectionTable.delta`): it stands at ``q + δ(q)``.
    """
    rng = np.random.default_rng() if rng is None else rng
    delta = table.delta if delta is None else delta
    identified = np.asarray(identified_params, dtype=float)
    axes = table.data.axes
    elbows = table.elbows
    lo = np.array([a.start for a in axes])
    span = np.array([a.step * (a.count if a.periodic else a.count - 1) for a in axes])
    cells = _cells_shape(axes)
    centre_axes = [a.start + a.step * (np.arange(cells[k]) + (0.0 if a.count == 1 else 0.5))
                   for k, a in enumerate(axes)]
    centres = np.stack([g.ravel() for g in np.meshgrid(*centre_axes, indexing="ij")], axis=-1)
    pos_all: list[np.ndarray] = []
    ori_all: list[np.ndarray] = []
    tilt_all: list[np.ndarray] = []
    worst: tuple[float, ...] = ()
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
        pos, ori, tilt = _pose_errors(nominal, identified, pts[ok], elbow, corr, q_nom[ok], q_id[ok], delta)
        pos_all.append(pos)
        ori_all.append(ori)
        tilt_all.append(tilt)
        j = int(np.argmax(pos))
        if pos[j] > worst_val:
            worst_val = float(pos[j])
            worst = tuple(float(v) for v in pts[ok][j]) + (float(elbow),)
    if not pos_all:
        return InterpolationCheck(math.nan, math.nan, math.nan, math.nan, 0)
    pos, ori, tilt = np.concatenate(pos_all), np.concatenate(ori_all), np.concatenate(tilt_all)
    return InterpolationCheck(
        max_position_um=float(pos.max()), rms_position_um=float(np.sqrt(np.mean(pos**2))),
        max_orientation_arcsec=float(ori.max()), rms_orientation_arcsec=float(np.sqrt(np.mean(ori**2))),
        n_points=int(pos.size), worst=worst, uncorrectable_tilt_arcsec=float(tilt.max()),
    )
