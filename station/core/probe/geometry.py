"""Geometry of the 3-2-1 probe head (brief §5): readings <-> pose of the cube corner.

Frames
------
MPKS, the measuring-point frame, sits on a TOP corner of a precision cube of edge ``E``
(``cube_edge_mm``); locally the cube fills ``0 <= x <= E, 0 <= y <= E, -E <= z <= 0``.
The probes touch three faces, each a plane ``n·x = h`` in MPKS with outward normal ``n``:

=====  ==========  ==============  =======================================
face   plane       outward normal  face rectangle (a contact outside: miss)
=====  ==========  ==============  =======================================
0 top  z = 0       +z              0 <= x <= E, 0 <= y <= E
1 x    x = 0       -x              0 <= y <= E, -E <= z <= 0
2 y    y = 0       -y              0 <= x <= E, -E <= z <= 0
=====  ==========  ==============  =======================================

MKKS is the probe-head frame. ``M`` (4x4) is the pose of MPKS in MKKS: ``p_MKKS = M p_MPKS``.

Probe model and sign convention
-------------------------------
Probe ``i`` has a mounting point ``b_i`` (tip-sphere centre at reading 0) and a unit
direction ``d_i`` pointing from the probe body towards the surface it touches (the direction
the spring pushes the plunger out). A reading ``s_i`` [mm] puts the tip-sphere centre at
``c_i = b_i + s_i d_i``. So **a positive reading means the plunger is extended further** (the
face is farther from the head); a face that comes closer pushes the plunger back and the
reading decreases. Contact: ``n_M · c_i - h_M = rho_i`` with the face plane in MKKS and the tip
radius ``rho_i``. Valid readings lie within ``[-stroke_i/2, +stroke_i/2]`` (reading 0 mid-stroke).
Tip radius and stroke may differ from probe to probe; each probe also has an id, the channel it
sits on at the interface unit and a certificate scale (a head file, ``docs/probe-head.md``,
:mod:`station.io.head_file`). At the nominal touch a probe need not read 0, but inside its stroke
with a margin (:data:`NOMINAL_STROKE_MARGIN`). With more than six probes the solver is least
squares; :mod:`station.core.probe.check` tests the residual and finds a probe that disagrees.

Default arrangement (``default_probe_head``)
-------------------------------------------
Cube edge 40 mm (a 25 mm cube leaves no room for a useful probe spacing), tip radius 1 mm,
stroke 10 mm. The nominal pose is ``Trans(0, 0, -60)``: the corner sits 60 mm below the head
origin with axes parallel to MKKS, every probe then reads 0. Contact points in MPKS:

* probes 0-2 on top, pointing -z: (5, 5), (35, 5), (20, 35)  -> z, roll, pitch (lever 30 mm)
* probes 3-4 on the x face, pointing +x: (y, z) = (8, -15), (32, -15) -> x, yaw (lever 24 mm)
* probe 5 on the y face, pointing +y: (x, z) = (20, -15) -> y

Every contact is at least 5 mm inside its face, which covers the robot's positioning error.

Sensitivity (``contact_pose_covariance`` at the nominal pose, 1 µm reading σ on every probe):
position σ ≈ 1.3-1.7 µm, roll 8.4″, pitch 9.7″, yaw 12.2″ (a test checks these against a
Monte Carlo of the solver). It
scales linearly with the reading noise and inversely with the probe spacing; the chapter's
50 mm spacing would give "a few arc seconds" per µm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from station.core.kinematics.transforms import matrix_to_pose, pose_to_matrix, rotation_exp

__all__ = [
    "FACE_TOP",
    "FACE_X",
    "FACE_Y",
    "FACE_NORMALS",
    "PoseSolveError",
    "ProbeHeadGeometry",
    "PoseSolution",
    "default_probe_head",
    "readings_from_pose",
    "readings_from_poses",
    "solve_pose",
    "contact_pose_covariance",
    "reading_jacobian",
    "NOMINAL_STROKE_MARGIN",
]

FACE_TOP, FACE_X, FACE_Y = 0, 1, 2
#: Outward normals of the three faces in MPKS; every face plane passes through the origin.
FACE_NORMALS = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
#: The two in-plane coordinates (MPKS axes) spanning each face, and their ranges as a
#: fraction of the edge: top (x, y) in [0, E]; side faces (y|x, z) with z in [-E, 0].
_FACE_AXES = np.array([[0, 1], [1, 2], [0, 2]])
_FACE_LO = np.array([[0.0, 0.0], [0.0, -1.0], [0.0, -1.0]])
_FACE_HI = np.array([[1.0, 1.0], [1.0, 0.0], [1.0, 0.0]])
#: A probe whose direction is within ~8° of parallel to its face is treated as a miss:
#: the tip would slide, and the reading's sensitivity to the face position explodes.
_MIN_INCIDENCE = 0.14


class PoseSolveError(ValueError):
    """The readings do not determine a valid cube pose; the measurement must be repeated."""


#: The nominal readings must stay this fraction of the stroke away from either stroke end: the
#: robot's positioning error before calibration (tenths of a mm) and the runner's re-centring
#: margin need room on both sides.
NOMINAL_STROKE_MARGIN = 0.2


@dataclass(frozen=True, eq=False)
class ProbeHeadGeometry:
    """Probe arrangement in MKKS. Arrays are read-only.

    ``mount_points (n,3)`` mm, ``directions (n,3)`` unit vectors (normalised here), ``faces (n,)``
    int (0 top, 1 x face, 2 y face); n >= 6 (the 3-2-1 head has 6; more make the residual a test
    of the touch). ``tip_radius_mm`` and ``stroke_mm``: one value for every probe or ``(n,)``
    (:attr:`tip_radii` and :attr:`strokes` are always ``(n,)``). ``ids``, ``channels`` (1-based
    channel on the interface unit, unique) and ``scales`` (certificate factor: displacement =
    scale x displayed value) default to ``"1" … "n"``, ``1 … n`` and 1. ``reading_sigma_mm``: σ
    of one reading, what the residual test of a redundant head compares against.
    ``nominal_pose`` (4,4): the pose the head is designed to touch at (None: the identity); every
    probe's reading there must lie inside its stroke with a margin of
    :data:`NOMINAL_STROKE_MARGIN` x stroke at both ends (a probe does not have to read 0 there).
    """

    mount_points: np.ndarray
    directions: np.ndarray
    faces: np.ndarray
    tip_radius_mm: float | np.ndarray = 1.0
    stroke_mm: float | np.ndarray = 10.0
    cube_edge_mm: float = 40.0
    #: (4,4) the pose of MPKS in MKKS at the nominal touch; None means the identity
    nominal_pose: np.ndarray | None = None
    ids: tuple[str, ...] | None = None
    channels: np.ndarray | None = None
    scales: np.ndarray | None = None
    name: str = "probe head"
    #: σ of one probe reading [mm] (certificate repeatability): the redundancy test's noise
    reading_sigma_mm: float = 0.0005

    def __post_init__(self) -> None:
        b = np.array(self.mount_points, dtype=float)
        d = np.array(self.directions, dtype=float)
        f = np.array(self.faces, dtype=int)
        if b.ndim != 2 or b.shape[1] != 3 or d.shape != b.shape or f.shape != (b.shape[0],):
            raise ValueError("mount_points and directions must be (n,3), faces (n,)")
        n = b.shape[0]
        if n < 6:
            raise ValueError("a pose needs at least six probes")
        if np.any((f < 0) | (f > 2)):
            raise ValueError("faces must be 0 (top), 1 (x face) or 2 (y face)")
        norms = np.linalg.norm(d, axis=1, keepdims=True)
        if not np.all(np.isfinite(b)) or not np.all(np.isfinite(d)) or np.any(norms < 1e-9):
            raise ValueError("mount points and directions must be finite, directions non-zero")
        d = d / norms
        M0 = np.eye(4) if self.nominal_pose is None else np.array(self.nominal_pose, float)
        for name, arr in (("mount_points", b), ("directions", d), ("faces", f),
                          ("nominal_pose", M0)):
            arr.flags.writeable = False
            object.__setattr__(self, name, arr)
        per_probe = {}
        for key, value, default in (("tip_radius_mm", self.tip_radius_mm, None),
                                    ("stroke_mm", self.stroke_mm, None),
                                    ("channels", self.channels, np.arange(1, n + 1)),
                                    ("scales", self.scales, np.ones(n))):
            given = np.asarray(default if value is None else value, dtype=float)
            if given.ndim != 0 and given.shape != (n,):
                raise ValueError(f"{key} must be one value or one per probe ({n}), got shape {given.shape}")
            a = np.array(np.broadcast_to(given, (n,)))
            a.flags.writeable = False
            per_probe[key] = a
        if np.any(per_probe["tip_radius_mm"] < 0) or np.any(per_probe["stroke_mm"] <= 0):
            raise ValueError("tip radii must be >= 0 and strokes > 0")
        ch = per_probe["channels"]
        if np.any(ch != np.round(ch)) or np.any(ch < 1) or len(set(ch.tolist())) != n:
            raise ValueError(f"channels must be unique integers >= 1, got {ch.tolist()}")
        if not (self.reading_sigma_mm > 0 and np.isfinite(self.reading_sigma_mm)):
            raise ValueError("reading_sigma_mm must be a finite number > 0")
        if not np.all(per_probe["scales"] > 0):
            raise ValueError("scale factors must be > 0")
        ids = tuple(str(i + 1) for i in range(n)) if self.ids is None else tuple(str(i) for i in self.ids)
        if len(ids) != n or len(set(ids)) != n:
            raise ValueError(f"ids must name each of the {n} probes once, got {list(ids)}")
        object.__setattr__(self, "_tip", per_probe["tip_radius_mm"])
        object.__setattr__(self, "_stroke", per_probe["stroke_mm"])
        object.__setattr__(self, "_channels", per_probe["channels"].astype(int))
        object.__setattr__(self, "_scales", per_probe["scales"])
        object.__setattr__(self, "_ids", ids)
        # A geometry whose probes do not touch their faces inside their stroke at the nominal
        # pose is a wrong geometry file; better to fail here than in every solve.
        s0, _, incidence = _contact(self, M0)
        limit = self.strokes * (0.5 - NOMINAL_STROKE_MARGIN)
        bad = [i for i in range(n) if not (np.isfinite(s0[i]) and abs(s0[i]) <= limit[i]
                                           and incidence[i] < -_MIN_INCIDENCE)]
        if bad:
            what = "; ".join(
                f"probe {self.label(i)} reads {s0[i]:.3f} mm, allowed ±{limit[i]:.3f} mm"
                if np.isfinite(s0[i]) and incidence[i] < -_MIN_INCIDENCE
                else f"probe {self.label(i)} does not point into its face" for i in bad)
            raise ValueError(
                f"at the nominal touch {what} (the nominal readings must stay "
                f"{NOMINAL_STROKE_MARGIN:.0%} of the stroke away from its ends): check mount point, "
                "direction and face of these probes and the nominal contact pose of the head")
        # faces the nominal contacts must land on (a contact outside its face: a wrong file)
        nominal = readings_from_poses(self, M0)
        off = [self.label(i) for i in range(n) if np.isnan(nominal[i])]
        if off:
            raise ValueError(f"at the nominal touch probes {', '.join(off)} land outside their cube face: "
                             "check their mount points against the cube edge")

    @property
    def n_probes(self) -> int:
        return self.mount_points.shape[0]

    @property
    def tip_radii(self) -> np.ndarray:
        """``(n,)`` tip-sphere radii [mm]."""
        return self._tip  # type: ignore[attr-defined]

    @property
    def strokes(self) -> np.ndarray:
        """``(n,)`` strokes [mm]: valid readings lie within ±stroke/2."""
        return self._stroke  # type: ignore[attr-defined]

    @property
    def probe_channels(self) -> np.ndarray:
        """``(n,)`` int: the channel (1-based) of each probe on the interface unit."""
        return self._channels  # type: ignore[attr-defined]

    @property
    def probe_scales(self) -> np.ndarray:
        """``(n,)`` certificate factors: displacement [mm] = scale x displayed value."""
        return self._scales  # type: ignore[attr-defined]

    @property
    def probe_ids(self) -> tuple[str, ...]:
        return self._ids  # type: ignore[attr-defined]

    def label(self, i: int) -> str:
        """``P3 (channel 4)``: how the messages name probe ``i`` (0-based index)."""
        return f"{self._ids[i]} (channel {int(self._channels[i])})"  # type: ignore[attr-defined]

    def nominal_contact_pose(self) -> np.ndarray:
        """(4,4) pose of MPKS in MKKS at the nominal touch."""
        if self.nominal_pose is None:  # not after __post_init__, which stores the identity for None
            return np.eye(4)
        return self.nominal_pose.copy()

    def nominal_readings(self) -> np.ndarray:
        """``(n,)`` readings [mm] at the nominal touch (not all 0 for a real head)."""
        return readings_from_poses(self, self.nominal_contact_pose())

    def subset(self, keep) -> "ProbeHeadGeometry":
        """The head with only the probes ``keep`` (indices or a boolean mask), in their order."""
        idx = np.arange(self.n_probes)[np.asarray(keep)]
        return ProbeHeadGeometry(
            self.mount_points[idx], self.directions[idx], self.faces[idx], self.tip_radii[idx],
            self.strokes[idx], self.cube_edge_mm, self.nominal_pose,
            tuple(self.probe_ids[i] for i in idx), self.probe_channels[idx], self.probe_scales[idx], self.name,
            self.reading_sigma_mm)


@dataclass(frozen=True, eq=False)
class PoseSolution:
    """``M (4,4)`` pose of MPKS in MKKS; ``residuals_mm (n,)`` plane residuals at ``M``;
    ``condition``: condition number of the 6-column Jacobian with the rotation columns scaled
    by the cube edge (so mm and rad·edge are comparable)."""

    M: np.ndarray
    residuals_mm: np.ndarray
    iterations: int
    converged: bool
    condition: float


def default_probe_head(cube_edge_mm: float = 40.0, tip_radius_mm: float = 1.0,
                       stroke_mm: float = 10.0, height_mm: float = 60.0) -> ProbeHeadGeometry:
    """The 3-2-1 head described in the module docstring; contacts scale with the edge."""
    E, rho = cube_edge_mm, tip_radius_mm
    k = E / 40.0
    top = [(5 * k, 5 * k), (35 * k, 5 * k), (20 * k, 35 * k)]
    xface = [(8 * k, -15 * k), (32 * k, -15 * k)]
    yface = [(20 * k, -15 * k)]
    # Tip-sphere centres in MPKS at the nominal pose: one radius off each face, outward.
    centres = ([(x, y, rho) for x, y in top] + [(-rho, y, z) for y, z in xface]
               + [(x, -rho, z) for x, z in yface])
    dirs = [(0, 0, -1)] * 3 + [(1, 0, 0)] * 2 + [(0, 1, 0)]
    M0 = pose_to_matrix(np.array([0.0, 0.0, -height_mm, 0.0, 0.0, 0.0]))
    b = np.asarray(centres, float) @ M0[:3, :3].T + M0[:3, 3]
    return ProbeHeadGeometry(b, np.asarray(dirs, float), np.array([0, 0, 0, 1, 1, 2]),
                             tip_radius_mm=rho, stroke_mm=stroke_mm, cube_edge_mm=E,
                             nominal_pose=M0, name="reference 3-2-1 head")


def _contact(geom: ProbeHeadGeometry, M: np.ndarray):
    """Unclipped readings ``(..., n)``, contact points in MPKS ``(..., n, 3)`` and the
    incidence ``n_M·d`` ``(..., n)`` (negative when the probe points into its face)."""
    M = np.asarray(M, dtype=float)
    R, t = M[..., :3, :3], M[..., :3, 3]
    rho = geom.tip_radii                                            # (n,)
    n_f = FACE_NORMALS[geom.faces]                                  # (n,3) in MPKS
    nM = np.einsum("...ij,nj->...ni", R, n_f)                      # (...,n,3) in MKKS
    hM = np.einsum("...ni,...i->...n", nM, t)                       # face planes pass the origin
    incidence = np.einsum("...ni,ni->...n", nM, geom.directions)
    nb = np.einsum("...ni,ni->...n", nM, geom.mount_points)
    # a probe parallel to its face reads ±inf and its contact is NaN: readings_from_poses
    # reports it as a miss, check_arrangement as a probe that fixes nothing
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (rho + hM - nb) / incidence
        c = geom.mount_points + s[..., None] * geom.directions      # tip centres in MKKS
        q = np.einsum("...ji,...nj->...ni", R, c - t[..., None, :]) # ... in MPKS
    contact = q - rho[:, None] * n_f
    return s, contact, incidence


def readings_from_poses(geom: ProbeHeadGeometry, M: np.ndarray) -> np.ndarray:
    """Vectorised :func:`readings_from_pose`: ``(..., 4, 4)`` -> ``(..., n)``."""
    s, contact, incidence = _contact(geom, M)
    E = geom.cube_edge_mm
    axes = _FACE_AXES[geom.faces]                                   # (n,2)
    uv = np.take_along_axis(contact, np.broadcast_to(axes, contact.shape[:-1] + (2,)), axis=-1)
    lo, hi = _FACE_LO[geom.faces] * E, _FACE_HI[geom.faces] * E
    on_face = np.all((uv >= lo) & (uv <= hi), axis=-1)
    hit = on_face & (incidence < -_MIN_INCIDENCE) & np.isfinite(s)
    half = geom.strokes / 2.0
    out = np.where(s > half, np.inf, np.where(s < -half, -np.inf, s))
    return np.where(hit, out, np.nan)


def readings_from_pose(geom: ProbeHeadGeometry, M: np.ndarray) -> np.ndarray:
    """Exact readings ``(n,)`` [mm] for the MPKS pose ``M (4,4)`` in MKKS.

    +inf beyond +stroke/2, -inf below -stroke/2, NaN where the probe misses its face (contact
    point outside the face rectangle, or direction nearly parallel to / away from the face).
    """
    M = np.asarray(M, dtype=float)
    if M.shape != (4, 4):
        raise ValueError(f"M must be (4,4), got {M.shape}")
    return readings_from_poses(geom, M)


def _residuals_and_jacobian(geom: ProbeHeadGeometry, M: np.ndarray, s: np.ndarray):
    """Plane residuals ``f_i = n_f·q_i - rho`` with ``q_i`` the tip centre in MPKS, and their
    Jacobian ``(n,6)`` w.r.t. a local twist ``(v, w)``: ``M <- M · [exp(w), v]``.

    With ``q' = q - v - w×q`` to first order: ``df/dv = -n_f``, ``df/dw = -(q × n_f)``.
    """
    R, t = M[:3, :3], M[:3, 3]
    c = geom.mount_points + s[:, None] * geom.directions
    q = (c - t) @ R
    n_f = FACE_NORMALS[geom.faces]
    f = np.einsum("ni,ni->n", n_f, q) - geom.tip_radii
    J = np.hstack([-n_f, -np.cross(q, n_f)])
    return f, J, q


def solve_pose(geom: ProbeHeadGeometry, readings: np.ndarray, M0: np.ndarray | None = None,
               noise_mm: float = 0.0005, max_iterations: int = 30,
               check_residuals: bool = True) -> PoseSolution:
    """Pose of MPKS in MKKS from the probe readings ``(n,)`` [mm], by Gauss-Newton (least
    squares when there are more than six probes).

    Starts at ``M0`` (default: the nominal contact pose). Raises :class:`PoseSolveError` for
    non-finite readings, a singular arrangement, no convergence, plane residuals above
    ``5·noise_mm`` (only possible with more than six probes; ``check_residuals=False`` leaves
    that test to the caller, :func:`station.core.probe.check.residual_test`), or a solution whose
    contact points fall outside the cube faces (the probes touched something else).
    """
    s = np.asarray(readings, dtype=float)
    if s.shape != (geom.n_probes,):
        raise PoseSolveError(f"expected {geom.n_probes} readings, got shape {s.shape}")
    bad = np.flatnonzero(~np.isfinite(s))
    if bad.size:
        raise PoseSolveError(
            f"probes {bad.tolist()} have no valid reading (out of stroke or missing the cube): "
            "correct the approach pose of this measuring point and measure again"
        )
    M = geom.nominal_contact_pose() if M0 is None else np.array(M0, dtype=float)
    tol_step = 1e-13 * max(1.0, geom.cube_edge_mm)
    converged = False
    iterations = 0
    for iterations in range(1, max_iterations + 1):  # noqa: B007 - the count is reported after the loop
        f, J, _ = _residuals_and_jacobian(geom, M, s)
        step, *_ = np.linalg.lstsq(J, -f, rcond=None)
        if not np.all(np.isfinite(step)):
            break
        D = np.eye(4)
        D[:3, :3] = rotation_exp(step[3:])
        D[:3, 3] = step[:3]
        M = M @ D
        # Step size in mm, rotations converted by the cube edge (the probes' lever arms).
        if np.max(np.abs(step[:3])) + geom.cube_edge_mm * np.max(np.abs(step[3:])) < tol_step:
            converged = True
            break
    f, J, q = _residuals_and_jacobian(geom, M, s)
    scaled = J * np.r_[np.ones(3), np.full(3, 1.0 / geom.cube_edge_mm)]
    sv = np.linalg.svd(scaled, compute_uv=False)
    condition = float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf")
    if not converged:
        raise PoseSolveError(
            f"pose solve did not converge in {iterations} iterations (condition {condition:.3g}): "
            "the readings are inconsistent with the head geometry; check the probe geometry "
            "file and repeat the measurement"
        )
    if condition > 1e6:
        raise PoseSolveError(f"probe arrangement is singular (condition {condition:.3g})")
    bound = 5.0 * noise_mm + 1e-9
    if check_residuals and np.max(np.abs(f)) > bound:
        raise PoseSolveError(
            f"plane residuals up to {np.max(np.abs(f)) * 1000:.2f} µm exceed {bound * 1000:.2f} µm "
            "(5 x probe noise): a probe is dirty, loose or touched the wrong surface; clean and "
            "check the probes, then measure again"
        )
    check = readings_from_poses(geom, M)
    missed = np.flatnonzero(np.isnan(check))
    if missed.size:
        raise PoseSolveError(
            f"the solved pose puts probes {missed.tolist()} off their cube faces: they touched "
            "another surface; correct the approach pose and measure again"
        )
    M.flags.writeable = False
    f.flags.writeable = False
    return PoseSolution(M, f, iterations, converged, condition)


def contact_pose_covariance(geom: ProbeHeadGeometry, M: np.ndarray,
                            sigma_mm: float | np.ndarray) -> np.ndarray:
    """Linearised ``(6,6)`` covariance of the pose vector ``matrix_to_pose(M)``
    (x, y, z [mm], roll, pitch, yaw [rad]) from independent reading noise ``sigma_mm``
    (scalar or ``(n,)``): ``Σ = (Gᵀ W G)⁻¹`` with ``G = ds/dpose``, ``W = diag(σ⁻²)``.
    """
    G = reading_jacobian(geom, M)                                    # (n,6)
    sigma = np.broadcast_to(np.asarray(sigma_mm, dtype=float), (geom.n_probes,))
    Gw = G / sigma[:, None]
    return np.linalg.pinv(Gw.T @ Gw)


def reading_jacobian(geom: ProbeHeadGeometry, M: np.ndarray) -> np.ndarray:
    """``G (n,6)``: derivative of the unclipped readings [mm] w.r.t. the pose vector
    ``matrix_to_pose(M)`` (x, y, z [mm], roll, pitch, yaw [rad]), by central differences."""
    p0 = matrix_to_pose(np.asarray(M, dtype=float))
    h = 1e-6
    P = p0 + np.concatenate([np.eye(6) * h, -np.eye(6) * h])
    s, _, _ = _contact(geom, pose_to_matrix(P))
    return np.asarray(((s[:6] - s[6:]) / (2 * h)).T)
