"""Measurement data sets for identification, and the model outputs/Jacobians that match them.

Three kinds (brief §4):

* ``pose``     — measured world←tool poses ``(n, 4, 4)``; residual rows x, y, z, rx, ry, rz.
* ``position`` — measured tool positions ``(n, 3)`` [mm] (a laser tracker's usual output).
* ``distance`` — measured distances ``(k,)`` [mm] between the tool origins of measurement
  pairs ``(k, 2)``; independent of where the set-up stands, so R drops out (eq. 7.4–7.6).

Every set carries the standard deviation of each residual row, which normalises mm against rad
in the objective (W = diag(σ⁻²), eq. 7.3) and feeds the uncertainty analysis.

Calibration-body uncertainty (optional): a measurement at a body measuring point is the head
pose body_point · M⁻¹, so an error of the point's pose in the CMM report (position δ, rotation ε
about the point's origin) moves the measured frame by δ + ε × l (l: the lever from the point's
origin to the measured frame's origin) and turns it by ε — the SAME error in every measurement
of that point. ``body_point`` names each measurement's point, ``body_sigma`` gives each point's σ
and ``body_lever`` the levers; :meth:`MeasurementSet.body_sensitivity` is the derivative B of
the measured values by the point's error, the fit weights use σ_meas² + diag(B Σ_body Bᵀ)
(:meth:`MeasurementSet.fit_sigma`), and the correlation between rows that share a point goes
into the parameter covariance (:func:`station.core.measurement.uncertainty.body_sandwich`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from station.core.kinematics.forward import forward, forward_with_jacobian
from station.core.kinematics.model import RobotModel
from station.core.kinematics.transforms import pose_error
from station.errors import ConfigError

Kind = Literal["pose", "position", "distance"]
KINDS: tuple[Kind, ...] = ("pose", "position", "distance")

# Defaults from the chapter's probe head: a point to ≤ 15 µm; orientation from probes ~50 mm
# apart gives about 1e-4 rad (20″).
DEFAULT_SIGMA_POSITION_MM = 0.015
DEFAULT_SIGMA_ANGLE_RAD = 1e-4


def _ro(a, dtype=float):
    a = np.array(a, dtype=dtype)
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class MeasurementSet:
    """One identification data set.

    ``joints``: ``(n, g)``. ``measured``: pose ``(n, 4, 4)`` | position ``(n, 3)`` |
    distance ``(k,)``. ``pairs``: ``(k, 2)`` indices into ``joints`` (distance only).
    ``sigma``: ``(n_rows,)`` standard deviation of every residual row, or a per-row pattern
    (6,) / (3,) / scalar that is repeated.
    ``point_sigma`` (distance only): ``(n, 3)`` standard deviation [mm] of every coordinate of the
    measured *points* the distances were computed from (or a scalar / (3,) pattern). Distances
    that share a point are correlated through it; the uncertainty analysis builds their
    covariance from this. Default: ``sigma / √2`` (each distance from two equal points).

    Calibration-body uncertainty (all optional; without it, or with every σ 0, nothing changes):
    ``body_point``: ``(n,)`` index of the body measuring point each measurement (joints row) was
    taken at. ``body_sigma``: ``(m, 2)`` σ of every body point: position [mm] (per coordinate)
    and angle [rad] (per axis), m > max(body_point). ``body_lever``: ``(n, 3)`` [mm] vector from
    the body point's origin to the measured frame's origin, in the measurement frame (default 0).
    """

    kind: Kind
    joints: np.ndarray
    measured: np.ndarray
    sigma: np.ndarray
    pairs: np.ndarray | None = None
    point_sigma: np.ndarray | None = None
    body_point: np.ndarray | None = None
    body_sigma: np.ndarray | None = None
    body_lever: np.ndarray | None = None

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ConfigError(f"measurement kind must be one of {KINDS}, got {self.kind!r}")
        q = np.asarray(self.joints, dtype=float)
        if q.ndim != 2:
            raise ConfigError("joints must be a (n, g) array")
        if not np.all(np.isfinite(q)):
            raise ConfigError("joint values contain NaN or infinity; remove those rows")
        m = np.asarray(self.measured, dtype=float)
        if not np.all(np.isfinite(m)):
            raise ConfigError("measured values contain NaN or infinity; remove those rows")
        n = q.shape[0]
        if self.kind == "pose" and m.shape != (n, 4, 4):
            raise ConfigError(f"pose data needs ({n}, 4, 4) measured poses, got {m.shape}")
        if self.kind == "position" and m.shape != (n, 3):
            raise ConfigError(f"position data needs ({n}, 3) measured positions, got {m.shape}")
        if self.kind == "distance":
            if self.pairs is None:
                raise ConfigError("distance data needs the index pairs of every distance")
            pr = np.asarray(self.pairs, dtype=int)
            if pr.ndim != 2 or pr.shape[1] != 2 or pr.shape[0] != m.shape[0]:
                raise ConfigError("distance data needs pairs (k, 2) matching k distances")
            if pr.min(initial=0) < 0 or pr.max(initial=0) >= n or np.any(pr[:, 0] == pr[:, 1]):
                raise ConfigError("distance pairs must index two different measurements")
            object.__setattr__(self, "pairs", _ro(pr, int))
        rows = self.rows_per_item * self.n_items
        s = np.asarray(self.sigma, dtype=float)
        s = np.broadcast_to(s, (self.n_items, self.rows_per_item)).reshape(-1) if s.size in (1, self.rows_per_item) else s.reshape(-1)
        if s.shape != (rows,) or np.any(~np.isfinite(s)) or np.any(s <= 0):
            raise ConfigError(f"sigma must be {rows} positive finite standard deviations")
        object.__setattr__(self, "joints", _ro(q))
        object.__setattr__(self, "measured", _ro(m))
        object.__setattr__(self, "sigma", _ro(s))
        if self.kind == "distance":
            ps = (np.sqrt(np.mean(s**2) / 2.0) if self.point_sigma is None
                  else np.asarray(self.point_sigma, dtype=float))
            try:
                ps = np.broadcast_to(ps, (n, 3))
            except ValueError:
                raise ConfigError(f"point_sigma must be a scalar, (3,) or ({n}, 3)") from None
            if np.any(~np.isfinite(ps)) or np.any(ps <= 0):
                raise ConfigError("point_sigma must be positive finite standard deviations [mm]")
            object.__setattr__(self, "point_sigma", _ro(ps))
        elif self.point_sigma is not None:
            raise ConfigError("point_sigma belongs to distance data only")
        self._check_body(n)

    def _check_body(self, n: int) -> None:
        if self.body_point is None and self.body_sigma is None:
            if self.body_lever is not None:
                raise ConfigError("body_lever needs body_point and body_sigma")
            return
        if self.body_point is None or self.body_sigma is None:
            raise ConfigError("body uncertainty needs both body_point (n,) and body_sigma (m, 2)")
        bp = np.asarray(self.body_point)
        if bp.shape != (n,) or not np.issubdtype(bp.dtype, np.integer):
            raise ConfigError(f"body_point must be ({n},) integer indices of the body points")
        bs = np.asarray(self.body_sigma, dtype=float)
        if bs.ndim != 2 or bs.shape[1] != 2 or not np.all(np.isfinite(bs)) or np.any(bs < 0):
            raise ConfigError("body_sigma must be (m, 2) finite σ ≥ 0: position [mm], angle [rad]")
        if bp.min(initial=0) < 0 or bp.max(initial=0) >= bs.shape[0]:
            raise ConfigError(f"body_point indices must lie in 0 … {bs.shape[0] - 1} (one body_sigma row per point)")
        lev = np.zeros((n, 3)) if self.body_lever is None else np.asarray(self.body_lever, dtype=float)
        if lev.shape != (n, 3) or not np.all(np.isfinite(lev)):
            raise ConfigError(f"body_lever must be ({n}, 3) finite lengths [mm]")
        object.__setattr__(self, "body_point", _ro(bp, int))
        object.__setattr__(self, "body_sigma", _ro(bs))
        object.__setattr__(self, "body_lever", _ro(lev))

    @property
    def has_body_sigma(self) -> bool:
        """Whether some body point has a σ > 0 (otherwise the body is taken as exact)."""
        return self.body_sigma is not None and bool(np.any(self.body_sigma > 0))

    def body_sigma6(self) -> np.ndarray:
        """``(m, 6)`` σ of every body point's error (δx, δy, δz [mm], εx, εy, εz [rad])."""
        if self.body_sigma is None:
            raise ConfigError("this data set has no body uncertainty")
        return np.repeat(self.body_sigma, 3, axis=1)

    def body_sensitivity(self) -> np.ndarray:
        """Derivative B of the measured values by the error of their body point: ``(n, 6, 6)``
        for pose data (rows x, y, z, rx, ry, rz of the measured frame; columns δ, ε), ``(n, 3, 6)``
        for position and distance data (the measured points). B = [[I, −[l]×], [0, I]]: a
        rotation ε of the point about its origin moves the frame at lever l by ε × l = −[l]× ε.
        The residual (model − measured) moves by −B."""
        if self.body_lever is None:
            raise ConfigError("this data set has no body uncertainty")
        lev = self.body_lever
        n = lev.shape[0]
        B = np.zeros((n, 6, 6))
        B[:, :3, :3] = np.eye(3)
        lx, ly, lz = lev[:, 0], lev[:, 1], lev[:, 2]
        # −[l]× = [[0, lz, −ly], [−lz, 0, lx], [ly, −lx, 0]]
        B[:, 0, 4], B[:, 0, 5] = lz, -ly
        B[:, 1, 3], B[:, 1, 5] = -lz, lx
        B[:, 2, 3], B[:, 2, 4] = ly, -lx
        B[:, 3:, 3:] = np.eye(3)
        return B if self.kind == "pose" else B[:, :3]

    def body_row_variance(self, unit: np.ndarray | None = None) -> np.ndarray:
        """``(n_rows,)`` variance that the body points' σ adds to every residual row: the
        diagonal of B Σ_body Bᵀ. Distance data need ``unit`` ``(k, 3)``, the unit vectors
        p_i − p_j of the pairs; two measurements at the same point share its error."""
        if not self.has_body_sigma:
            return np.zeros(self.sigma.size)
        bp = self.body_point
        assert bp is not None  # has_body_sigma: checked together on creation
        B = self.body_sensitivity()
        s2 = self.body_sigma6()[bp] ** 2  # (n, 6)
        if self.kind != "distance":
            return np.einsum("nrc,nc->nr", B**2, s2).reshape(-1)
        if unit is None:
            raise ConfigError("the body variance of distances needs the pairs' unit vectors")
        pr = self.distance_pairs()
        i, j = pr[:, 0], pr[:, 1]
        a_i = np.einsum("kr,krc->kc", unit, B[i])
        a_j = np.einsum("kr,krc->kc", unit, B[j])
        same = (bp[i] == bp[j])[:, None]
        return np.sum(np.where(same, (a_i - a_j) ** 2 * s2[i], a_i**2 * s2[i] + a_j**2 * s2[j]), axis=1)

    def fit_sigma(self, unit: np.ndarray | None = None) -> np.ndarray:
        """``(n_rows,)`` σ the fit weights every row with: √(σ_meas² + σ_body²). Without body σ it
        is :attr:`sigma` itself (the fit is then exactly the one without a body)."""
        if not self.has_body_sigma:
            return self.sigma
        return np.sqrt(self.sigma**2 + self.body_row_variance(unit))

    @property
    def n_items(self) -> int:
        """Number of measurements (poses / positions) or distances."""
        return self.measured.shape[0]

    @property
    def rows_per_item(self) -> int:
        return {"pose": 6, "position": 3, "distance": 1}[self.kind]

    @property
    def uses_setup(self) -> bool:
        return self.kind != "distance"

    def distance_pairs(self) -> np.ndarray:
        """The ``(k, 2)`` index pairs of a distance set (always present: checked on creation)."""
        if self.pairs is None:
            raise ConfigError(f"{self.kind} data has no index pairs; only distance data has them")
        return self.pairs

    def with_measured(self, measured: np.ndarray) -> "MeasurementSet":
        return MeasurementSet(self.kind, self.joints, measured, self.sigma, self.pairs, self.point_sigma,
                              self.body_point, self.body_sigma, self.body_lever)

    def with_body(self, body_point, body_sigma, body_lever=None) -> "MeasurementSet":
        """The same data with the uncertainty of the calibration body (see the class)."""
        return MeasurementSet(self.kind, self.joints, self.measured, self.sigma, self.pairs, self.point_sigma,
                              body_point, body_sigma, body_lever)

    def points_sigma(self) -> np.ndarray:
        """``(n, 3)`` σ [mm] of the measured points behind a distance set."""
        if self.point_sigma is None:
            raise ConfigError(f"{self.kind} data has no point σ; only distance data has them")
        return self.point_sigma

    def subset(self, items: np.ndarray) -> "MeasurementSet":
        """The measurements (or distances) with the given indices."""
        idx = np.asarray(items, dtype=int)
        sig = self.sigma.reshape(self.n_items, -1)[idx]
        if self.kind == "distance":
            return MeasurementSet("distance", self.joints, self.measured[idx], sig, self.distance_pairs()[idx],
                                  self.point_sigma, self.body_point, self.body_sigma, self.body_lever)
        if self.body_point is None:
            return MeasurementSet(self.kind, self.joints[idx], self.measured[idx], sig)
        return MeasurementSet(self.kind, self.joints[idx], self.measured[idx], sig, None, None,
                              self.body_point[idx], self.body_sigma, None if self.body_lever is None else self.body_lever[idx])


def model_outputs(model: RobotModel, data: MeasurementSet, params) -> np.ndarray:
    """Model predictions in the data's form: poses (n,4,4), positions (n,3) or distances (k,)."""
    T = forward(model, data.joints, params, setup=data.uses_setup)
    if data.kind == "pose":
        return T
    if data.kind == "position":
        return T[..., :3, 3]
    p = T[..., :3, 3]
    pairs = data.distance_pairs()
    return np.linalg.norm(p[..., pairs[:, 0], :] - p[..., pairs[:, 1], :], axis=-1)


def residuals_and_jacobian(model: RobotModel, data: MeasurementSet, params, joints=None,
                           measured=None, with_jacobian: bool = True):
    """Unweighted residuals (model − measured) ``(..., n_rows)`` and Jacobian ``(..., n_rows, P)``.

    ``params`` may carry leading batch axes (one parameter set per synthetic data set), as may
    ``joints`` and ``measured`` overrides of the data's values.
    """
    q = data.joints if joints is None else joints
    meas = data.measured if measured is None else measured
    if with_jacobian:
        res = forward_with_jacobian(model, q, params, setup=data.uses_setup)
        T, J = res.T, res.J
    else:
        T, J = forward(model, q, params, setup=data.uses_setup), None
    if data.kind == "pose":
        r = pose_error(T, meas)
        r = r.reshape(r.shape[:-2] + (-1,))
        if J is not None:
            J = J.reshape(J.shape[:-3] + (-1, J.shape[-1]))
        return r, J
    p = T[..., :3, 3]
    if data.kind == "position":
        r = p - meas  # either may carry the batch axes
        r = r.reshape(r.shape[:-2] + (-1,))
        if J is not None:
            J = J[..., :3, :].reshape(J.shape[:-3] + (-1, J.shape[-1]))
        return r, J
    pairs = data.distance_pairs()
    i, j = pairs[:, 0], pairs[:, 1]
    diff = p[..., i, :] - p[..., j, :]
    d = np.linalg.norm(diff, axis=-1)
    r = d - meas
    if J is not None:
        u = diff / d[..., None]
        Jp = J[..., :3, :]
        J = np.einsum("...kc,...kcp->...kp", u, Jp[..., i, :, :] - Jp[..., j, :, :])
    return r, J


def synthetic_set(model: RobotModel, kind: Kind, joints, true_params, sigma=None, rng=None,
                  pairs=None, point_sigma=None) -> MeasurementSet:
    """Exact (or, with ``rng``, noisy) measurements that the robot ``true_params`` would give.

    Distance data are noisy the way they are measured: the noise is on the two points (σ
    ``point_sigma``), and the distances are computed from the noisy points, so distances that
    share a point are correlated."""
    sig = default_sigma(kind) if sigma is None else np.asarray(sigma, dtype=float)
    proto = MeasurementSet(kind, joints, _placeholder(kind, joints, pairs), sig, pairs, point_sigma)
    if kind == "distance" and rng is not None:
        pts = forward(model, proto.joints, true_params, setup=False)[..., :3, 3]
        pts = pts + rng.standard_normal(pts.shape) * proto.points_sigma()
        pr = proto.distance_pairs()
        return proto.with_measured(np.linalg.norm(pts[pr[:, 0]] - pts[pr[:, 1]], axis=-1))
    meas = model_outputs(model, proto, true_params)
    if rng is not None:
        meas = add_noise(proto, meas, rng)
    return proto.with_measured(meas)


def _placeholder(kind, joints, pairs):
    n = np.asarray(joints).shape[0]
    if kind == "pose":
        return np.broadcast_to(np.eye(4), (n, 4, 4))
    if kind == "position":
        return np.zeros((n, 3))
    return np.ones(np.asarray(pairs).shape[0])


def add_noise(data: MeasurementSet, exact: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Exact outputs ``(B?, ...)`` plus Gaussian noise of the data's σ (batch axes allowed)."""
    sig = data.sigma.reshape(data.n_items, data.rows_per_item)
    if data.kind == "pose":
        from station.core.kinematics.transforms import rotation_exp

        shape = exact.shape[:-2]
        e = rng.standard_normal(shape + (6,)) * sig
        out = np.array(exact)
        out[..., :3, 3] += e[..., :3]
        # pose_error's rotation residual is R_model R_meas^T: perturb on the left in world frame.
        out[..., :3, :3] = rotation_exp(-e[..., 3:]) @ out[..., :3, :3]
        return out
    sig = sig[:, 0] if data.kind == "distance" else sig
    return exact + rng.standard_normal(exact.shape) * sig


def add_body_error(data: MeasurementSet, exact: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Exact poses ``(B?, n, 4, 4)`` or points ``(B?, n, 3)`` (for distance data: the points
    the distances are formed from) as a body whose points are off by their σ would give them:
    one error (δ, ε) per body point and per data set (batch entry), shared by every measurement
    at that point, applied as the rigid motion it is (turn by ε about the point's origin, shift
    by δ). Without body σ the input is returned unchanged."""
    if not data.has_body_sigma:
        return exact
    pose = data.kind == "pose"
    batch = exact.shape[:-3] if pose else exact.shape[:-2]
    assert data.body_point is not None and data.body_lever is not None
    e = rng.standard_normal(batch + (data.body_sigma6().shape[0], 6)) * data.body_sigma6()
    e = e[..., data.body_point, :]  # (B?, n, 6): every measurement takes its point's error
    from station.core.kinematics.transforms import rotation_exp

    R = rotation_exp(e[..., 3:])
    shift = e[..., :3] + np.einsum("...ij,...j->...i", R - np.eye(3), np.broadcast_to(data.body_lever, e[..., :3].shape))
    out = np.array(exact, dtype=float)
    if pose:
        out[..., :3, 3] += shift
        out[..., :3, :3] = R @ out[..., :3, :3]
    else:
        out += shift
    return out


def default_sigma(kind: Kind) -> np.ndarray:
    s, a = DEFAULT_SIGMA_POSITION_MM, DEFAULT_SIGMA_ANGLE_RAD
    if kind == "pose":
        return np.array([s, s, s, a, a, a])
    if kind == "position":
        return np.array([s, s, s])
    return np.array([np.sqrt(2.0) * s])


def random_pairs(n: int, k: int, rng: np.random.Generator) -> np.ndarray:
    """``k`` distinct random pairs of ``n`` measurements (all pairs if fewer exist)."""
    iu = np.array(np.triu_indices(n, 1)).T
    if k >= len(iu):
        return iu
    return iu[np.sort(rng.choice(len(iu), size=k, replace=False))]
