"""Registration of external measurements to the nominal model, and the data checks before a fit.

A laser tracker or CMM measures in its own frame, which may stand anywhere (turned, tilted,
metres away, upside down). Before identifying, the measured tool positions are aligned with the
nominal model's positions at the same joints (brief §10):

* a **similarity** fit ``m ≈ s·R·b + t`` (rotation by ``scipy.spatial.transform.Rotation
  .align_vectors``, i.e. Kabsch; scale and translation from the centroids, Umeyama) whose scale
  ``s`` exposes a unit mistake: 0.001 means metres written as mm, 1/25.4 inches, 1000 µm;
* a **rigid** fit (``s = 1``) whose transform starts the set-up R of the identification, and
  whose residual tells whether the nominal model can describe the data at all. A residual far
  above what an uncalibrated robot misses by points at a wrong joint order, wrong joint units
  or a wrong robot file; the worst rows are named;
* a **tool/marker offset** fit (:func:`station.core.kinematics.tool_frame.fit_marker_offset`): where the
  rigid fit fails but moving the tool point explains the data, the refusal says it is a marker
  offset, not a unit error, and names ``--tool unknown``; with ``tool_unknown`` the tool point is
  fitted with the frame and starts the identification.

:func:`data_information` measures what the data can support before any fit: distinct
configurations, duplicate rows, the spread of every joint and of the measured points.
Everything here is pure numerics (mm, rad inside).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from station.core.kinematics.forward import forward
from station.core.kinematics.model import RobotModel
from station.core.kinematics.tool_frame import MAX_MARKER_OFFSET_MM, MarkerFit, fit_marker_offset
from station.core.kinematics.transforms import matrix_to_pose
from station.errors import ConfigError, IdentificationError

# Scale of a similarity fit accepted as "the same unit": an uncalibrated robot is off by well
# under 1 % of its reach; 10 % is far outside anything a robot's geometry explains.
SCALE_TOLERANCE = 0.10
# A rigid-fit RMS residual above max(RESIDUAL_NOISE_FACTOR · σ, RESIDUAL_SPREAD_FRACTION · spread)
# is not an uncalibrated robot (1–3 mm on a 1–2 m arm) but a wrong description of the data.
RESIDUAL_NOISE_FACTOR = 30.0
RESIDUAL_SPREAD_FRACTION = 0.01
# Measured coordinates beyond this [mm] are not a robot cell (1e308, overflow, bad export).
MAX_ABS_MM = 1e6

_UNITS = (  # (scale m/b if the data were in this unit but labelled mm, unit, how to label it)
    (1e-3, "m", "x [m]"),
    (1.0 / 25.4, "inch", "convert to mm (×25.4)"),
    (1e3, "µm", "x [um]"),
    (1e-2, "cm", "convert to mm (×10)"),
)


@dataclass(frozen=True)
class Registration:
    """Result of :func:`register`. ``transform``: ``(4, 4)`` measurement ← robot base (rigid);
    ``scale``: the similarity fit's scale (1 for consistent units); ``residuals_mm``: ``(n,)``
    per-row distance after the rigid fit; ``rms_mm``: their RMS; ``limit_mm``: the largest RMS
    accepted; ``worst_rows``: 0-based indices of the largest residuals, largest first;
    ``tool_offset_mm``: ``(3,)`` the fitted tool point in the last joint frame (``--tool unknown``),
    else None; ``tool_undetermined``: how many of its directions the data left open."""

    transform: np.ndarray
    scale: float
    residuals_mm: np.ndarray
    rms_mm: float
    limit_mm: float
    worst_rows: tuple[int, ...]
    unit_check: str
    tool_offset_mm: np.ndarray | None = None
    tool_undetermined: int = 0

    @property
    def setup_pose(self) -> np.ndarray:
        """The rigid transform as a set-up pose ``(6,)`` [mm, rad]."""
        return matrix_to_pose(self.transform)

    def to_dict(self) -> dict:
        pose = self.setup_pose
        return {
            "setup_xyz_mm": pose[:3].tolist(),
            "setup_rpy_rad": pose[3:].tolist(),
            "rotation_angle_rad": float(Rotation.from_matrix(self.transform[:3, :3]).magnitude()),
            "translation_mm": float(np.linalg.norm(self.transform[:3, 3])),
            "similarity_scale": self.scale,
            "rms_residual_mm": self.rms_mm,
            "limit_mm": self.limit_mm,
            "worst_rows": [i + 1 for i in self.worst_rows],
            "unit_check": self.unit_check,
            "tool_offset_mm": None if self.tool_offset_mm is None else self.tool_offset_mm.tolist(),
        }


def _centroid(x: np.ndarray) -> np.ndarray:
    """``x.mean(0)`` of points ``(n, 3)``: numpy's own sum and division, without its layers."""
    return np.add.reduce(x, 0) / x.shape[0]


def _rms_norm(x: np.ndarray) -> float:
    """``float(np.sqrt(np.mean(np.sum(x**2, axis=1))))``: the RMS length of the rows of ``x`` by
    numpy's own sums and division, without its layers."""
    return float(np.sqrt(np.add.reduce(np.add.reduce(x**2, 1)) / x.shape[0]))


def likely_unit(scale: float) -> tuple[str, str] | None:
    for s, unit, fix in _UNITS:
        if abs(np.log(scale / s)) < np.log(1.15):
            return unit, fix
    return None


def _similarity(b: np.ndarray, m: np.ndarray, bc: np.ndarray | None = None, mc: np.ndarray | None = None,
                B: np.ndarray | None = None) -> tuple[np.ndarray, float, np.ndarray]:
    """Rotation (3, 3), scale and translation (3,) with ``m ≈ s R b + t`` (least squares). The
    rotation is also the rigid fit's (the same centred points): ``m ≈ R b + mc − R bc``.
    ``bc``, ``mc``: the centroids of ``b`` and ``m``, ``B``: ``b − bc``, where the caller has them."""
    bc = b.mean(axis=0) if bc is None else bc
    mc = m.mean(axis=0) if mc is None else mc
    B, M = b - bc if B is None else B, m - mc
    rot, _ = Rotation.align_vectors(M, B)
    R = rot.as_matrix()
    s = float(np.sum(M * (B @ R.T)) / np.sum(B * B))
    return R, s, mc - s * R @ bc


def rigid_residual_mm(model: RobotModel, joints: np.ndarray, measured_mm: np.ndarray, params=None) -> float:
    """RMS [mm] of measured points ``(n, 3)`` after the best rigid alignment of ``model``'s
    base-frame points at ``joints`` to them, without any check: how well the model's shape
    explains the data wherever they were measured from."""
    b = forward(model, np.asarray(joints, dtype=float), params, setup=False)[:, :3, 3]
    m = np.asarray(measured_mm, dtype=float)
    bc, mc = b.mean(0), m.mean(0)
    rot, _ = Rotation.align_vectors(m - mc, b - bc)
    res = m - mc - (b - bc) @ rot.as_matrix().T
    return float(np.sqrt(np.mean(np.sum(res**2, axis=1))))


def rigid_setup(model: RobotModel, joints: np.ndarray, points_mm: np.ndarray, params=None) -> np.ndarray:
    """The set-up pose ``(6,)`` [mm, rad] that places ``model`` (at ``params``, its own set-up
    left out) best onto ``points_mm`` ``(n, 3)`` at ``joints`` ``(n, g)``: the rigid fit, without
    any check. ``validate`` places the nominal robot onto an identified model's own points so,
    wherever the identification put the set-up (split between R and parameters that merge with it)."""
    b = forward(model, np.asarray(joints, dtype=float), params, setup=False)[:, :3, 3]
    m = np.asarray(points_mm, dtype=float)
    bc, mc = b.mean(0), m.mean(0)
    rot, _ = Rotation.align_vectors(m - mc, b - bc)
    T = np.eye(4)
    T[:3, :3] = rot.as_matrix()
    T[:3, 3] = mc - T[:3, :3] @ bc
    return matrix_to_pose(T)


def _limit_text(limit: float, sigma_mm: float, spread_b: float) -> str:
    """Where the residual limit comes from, naming σ and the option that sets it."""
    return (f"the limit {limit:.3g} mm is the larger of {RESIDUAL_NOISE_FACTOR:.0f} × σ "
            f"({RESIDUAL_NOISE_FACTOR:.0f} × {sigma_mm * 1e3:.3g} µm; set σ with --sigma-position) "
            f"and {RESIDUAL_SPREAD_FRACTION:.0%} of the {spread_b:.4g} mm spread of the points")


def _marker_explains(model, q, m, params, limit: float, rms_rigid: float) -> MarkerFit | None:
    """A tool/marker offset fit when it explains what the rigid fit cannot, else None."""
    try:
        fit = fit_marker_offset(model, q, m, params)
    except (np.linalg.LinAlgError, ValueError):
        return None
    shift = float(np.linalg.norm(fit.shift_mm))
    if (fit.rms_mm <= limit and fit.rms_mm < 0.5 * rms_rigid and shift <= MAX_MARKER_OFFSET_MM
            and shift > 3.0 * fit.rms_mm):
        return fit
    return None


def _marker_refusal(fit: MarkerFit, rms_rigid: float) -> ConfigError:
    d = fit.shift_mm
    return ConfigError(
        f"the measured points are the nominal model's with the tool point moved by "
        f"({d[0]:.1f}, {d[1]:.1f}, {d[2]:.1f}) mm ({np.linalg.norm(d):.1f} mm) from the robot file's tool: "
        f"with that offset they fit to {fit.rms_mm:.3g} mm RMS (without it {rms_rigid:.3g} mm). This is a "
        f"marker or reflector offset, not a unit error: fit it with --tool unknown, or give the tool's "
        f"offset in the robot file (the last transform's x, y, z)")


def register(model: RobotModel, joints: np.ndarray, measured_mm: np.ndarray, sigma_mm: float,
             params=None, tool_unknown: bool = False, explain_marker: bool = True,
             base_points: np.ndarray | None = None) -> Registration:
    """Register measured tool positions ``(n, 3)`` [mm] to ``model`` at ``joints`` ``(n, g)``.

    Raises :class:`ConfigError` for a unit mistake (scale far from 1: names m, inch, µm) and
    for a tool/marker offset that explains the data (names ``--tool unknown``), and
    :class:`IdentificationError` when even the best rigid alignment leaves residuals far above
    an uncalibrated robot's errors (wrong joint order, joint units or robot file).

    ``tool_unknown``: the tool point (K's translation) is fitted with the frame
    (:func:`station.core.kinematics.tool_frame.fit_marker_offset`); ``Registration.tool_offset_mm`` holds it.
    ``explain_marker=False`` skips the marker diagnosis (a caller that goes on from its own start).
    ``base_points``: ``(n, 3)`` the model's tool points at ``joints`` and ``params`` without the
    set-up (``forward(..., setup=False)``'s), where the caller has them.
    """
    q = np.asarray(joints, dtype=float)
    m = np.asarray(measured_mm, dtype=float)
    p = np.array(model.nominal if params is None else params, dtype=float)
    b = forward(model, q, p, setup=False)[:, :3, 3] if base_points is None else base_points
    bc, mc = _centroid(b), _centroid(m)
    Bc = b - bc  # the centred points, shared by the spread, the line check and the rigid fit
    spread_b = _rms_norm(Bc)
    spread_m = _rms_norm(m - mc)
    if spread_b < 1e-6 * max(1.0, float(np.abs(b).max())):
        raise ConfigError("the nominal model puts every row at the same tool position; measure "
                          "poses spread over the workspace (move every joint)")
    if spread_m == 0.0:
        raise ConfigError("every measured position is the same point; check the export of the "
                          "instrument (all rows equal or zero) and measure poses spread over the workspace")
    # Rotation needs two independent directions in the nominal points.
    sv = np.linalg.svd(Bc, compute_uv=False)
    if sv[1] < 1e-6 * sv[0]:
        raise ConfigError("the tool positions lie on one line, which leaves the tracker frame's "
                          "rotation about it open; measure poses that move at least two axes")
    limit = max(RESIDUAL_NOISE_FACTOR * sigma_mm, RESIDUAL_SPREAD_FRACTION * spread_b)
    marker = None
    if tool_unknown:
        marker = fit_marker_offset(model, q, m, p)
        if float(np.linalg.norm(marker.shift_mm)) > MAX_MARKER_OFFSET_MM:
            raise IdentificationError(
                f"the tool point fitted {np.linalg.norm(marker.shift_mm):.4g} mm from the robot file's, "
                f"more than the {MAX_MARKER_OFFSET_MM:.0f} mm a marker or tool lies from the flange: check "
                f"the joint order and units of the data file and that the robot file is this robot")
        p[-6:-3] = marker.offset_mm
        b = forward(model, q, p, setup=False)[:, :3, 3]
        bc = _centroid(b)
        Bc = b - bc
    R_sim, s, _ = _similarity(b, m, bc, mc, Bc)
    # Rigid fit: the start of the set-up transform, and the residual check.
    if marker is not None:
        T = marker.transform
    else:
        T = np.eye(4)
        T[:3, :3] = R_sim  # Rotation.align_vectors(m - mc, b - bc): the similarity fit's rotation
        T[:3, 3] = mc - T[:3, :3] @ bc
    res = np.linalg.norm(m - (b @ T[:3, :3].T + T[:3, 3]), axis=1)
    rms = float(np.sqrt(np.mean(res**2)))
    worst = tuple(int(i) for i in np.argsort(-res)[:5])

    def rows() -> str:  # the worst rows, for a refusal only
        return ", ".join(f"row {i + 1}: {res[i]:.1f} mm" for i in worst)
    unit = "consistent (similarity scale {:.5f})".format(s)
    if marker is not None:
        d = marker.shift_mm
        unit += (f"; tool point fitted ({d[0]:.2f}, {d[1]:.2f}, {d[2]:.2f}) mm from the robot file's"
                 + (f", {marker.undetermined} direction(s) not determined by these data (held at the "
                    f"file's value)" if marker.undetermined else ""))
    bad_scale = not np.isfinite(s) or abs(s - 1.0) > SCALE_TOLERANCE
    if bad_scale:
        likely = likely_unit(s) if np.isfinite(s) and s > 0 else None
        if likely:
            raise ConfigError(
                f"the measured positions are {s:.4g}× the nominal model's: they look like {likely[0]}, "
                f"not mm. Label the columns with their unit or {likely[1]}")
    if (bad_scale or rms > limit) and marker is None and explain_marker:
        explained = _marker_explains(model, q, m, p, limit, rms)
        if explained is not None:
            raise _marker_refusal(explained, rms)
    if bad_scale:
        raise IdentificationError(
            f"the measured positions are {s:.4g}× the nominal model's (spread {spread_m:.4g} vs "
            f"{spread_b:.4g} mm), which no unit and no tool offset explains, and the best rigid alignment "
            f"misses by {rms:.3g} mm RMS (worst {rows()}; {_limit_text(limit, sigma_mm, spread_b)}): check the "
            f"joint order and joint units of the data file, the length unit of x, y, z, and that the robot "
            f"file is this robot")
    reg = Registration(T, s, res, rms, limit, worst, unit,
                       None if marker is None else marker.offset_mm,
                       0 if marker is None else marker.undetermined)
    if rms > limit:
        raise IdentificationError(
            f"after the best rigid alignment the measured positions still miss the nominal model by "
            f"{rms:.3g} mm RMS (an uncalibrated robot misses by about {limit:.3g} mm at most: "
            f"{_limit_text(limit, sigma_mm, spread_b)}); worst {rows()}. Check the joint order and joint "
            f"units (deg/rad, mm/m) of the data file, the sign conventions, and that the robot file is "
            f"this robot; if the instrument is noisier than σ, give its σ with --sigma-position")
    return reg


@dataclass(frozen=True)
class DataInformation:
    """What a data set can support, measured before fitting."""

    n_rows: int
    n_distinct_joints: int
    duplicate_rows: tuple[tuple[int, int], ...]
    joint_spread: np.ndarray  # (g,) range of each joint [rad | mm]
    point_spread_mm: float

    def to_dict(self) -> dict:
        return {"rows": self.n_rows, "distinct_joint_configurations": self.n_distinct_joints,
                "duplicate_rows": [[a + 1, b + 1] for a, b in self.duplicate_rows],
                "joint_range_rad_or_mm": self.joint_spread.tolist(),
                "point_spread_mm": self.point_spread_mm}


def _first_equal_row(a: np.ndarray) -> np.ndarray:
    """``(n,)`` for every row of ``a`` ``(n, k)`` the index of the first row equal to it (itself
    when none before it is): ``np.unique(a, axis=0, return_index=True, return_inverse=True)``'s
    ``first[inverse]``, by one stable lexicographic sort."""
    n = a.shape[0]
    if n == 0:
        return np.zeros(0, dtype=int)
    order = np.lexsort(a.T[::-1])
    s = a[order]
    start = np.empty(n, dtype=bool)
    start[0] = True
    np.any(s[1:] != s[:-1], axis=1, out=start[1:])
    group_first = order[np.flatnonzero(start)]  # stable sort: the smallest index of each group
    first = np.empty(n, dtype=int)
    first[order] = group_first[np.cumsum(start) - 1]
    return first


def data_information(model: RobotModel, joints: np.ndarray, measured: np.ndarray | None = None,
                     rows_per_item: int = 3) -> DataInformation:
    """Count distinct joint configurations and duplicate rows, and the spread of the data.

    Raises :class:`ConfigError` for data that cannot support any identification: values that
    are not a robot cell (beyond ±1 km), too few distinct configurations, or exactly repeated
    rows (joints *and* measured values identical: a copied row, which would make the stated
    uncertainty too small)."""
    q = np.asarray(joints, dtype=float)
    n = q.shape[0]
    mm = None
    if measured is not None:
        mm = np.asarray(measured, dtype=float).reshape(n, -1)
        big = np.nonzero(np.abs(mm) > MAX_ABS_MM)[0]
        if big.size:
            raise ConfigError(f"row {big[0] + 1}: a measured value beyond ±{MAX_ABS_MM:.0e} mm is not a "
                              f"robot cell; repair the export (overflow, wrong column) and measure again")
    if np.any(np.abs(q) > MAX_ABS_MM):
        bad = int(np.nonzero(np.any(np.abs(q) > MAX_ABS_MM, axis=1))[0][0])
        raise ConfigError(f"row {bad + 1}: joint values beyond ±{MAX_ABS_MM:.0e} are not a robot; "
                          f"repair the data file")
    dup: tuple[tuple[int, int], ...] = ()
    n_distinct = int(np.count_nonzero(_first_equal_row(q) == np.arange(n)))
    # equal joints alone are a legitimate repeat; equal readings are not (a row repeats another
    # only where its joints do, so with every joint row distinct there is nothing to look for)
    if mm is not None and n_distinct < n:
        first = _first_equal_row(np.concatenate([q, mm], axis=1))
        dup = tuple((int(first[i]), i) for i in np.flatnonzero(first != np.arange(n)).tolist())
    spread = q.max(axis=0) - q.min(axis=0) if n else np.zeros(q.shape[1])
    pts = None
    if measured is not None:
        m = np.asarray(measured, dtype=float)
        # poses are (n, 4, 4): their points are the translation column, not the first matrix row
        pts = m[:, :3, 3] if m.ndim == 3 and m.shape[1:] == (4, 4) else m.reshape(n, -1)[:, :3]
    ps = 0.0 if pts is None else _rms_norm(pts - _centroid(pts))
    info = DataInformation(n, n_distinct, dup, spread, ps)
    need = model.minimal_param_count
    min_distinct = max(3, -(-need // max(1, rows_per_item)))
    if n_distinct < min_distinct:
        raise ConfigError(
            f"only {n_distinct} distinct joint configuration(s) in {n} rows; identifying {model.name} "
            f"needs at least {min_distinct} (its complete model has {need} parameters). "
            f"Measure poses spread over the workspace, moving every joint over its range")
    if dup:
        a, b = dup[0]
        raise ConfigError(
            f"{len(dup)} row(s) repeat another row exactly (joints and measured values), e.g. row {b + 1} = "
            f"row {a + 1}: a copied row counts the same measurement twice and makes the stated σ too "
            f"small. Remove the copies; a real repeat of a pose is measured again and never reads identically")
    return info
