"""Measurement data sets for identification, and the model outputs/Jacobians that match them.

Three kinds (brief §4):

* ``pose``     — measured world←tool poses ``(n, 4, 4)``; residual rows x, y, z, rx, ry, rz.
* ``position`` — measured tool positions ``(n, 3)`` [mm] (a laser tracker's usual output).
* ``distance`` — measured distances ``(k,)`` [mm] between the tool origins of measurement
  pairs ``(k, 2)``; independent of where the set-up stands, so R drops out (eq. 7.4–7.6).

Every set carries the standard deviation of each residual row, which normalises mm against rad
in the objective (W = diag(σ⁻²), eq. 7.3) and feeds the uncertainty analysis.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from station.core.kinematics import forward, forward_with_jacobian
from station.core.model import RobotModel
from station.core.transforms import pose_error
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
    """

    kind: Kind
    joints: np.ndarray
    measured: np.ndarray
    sigma: np.ndarray
    pairs: np.ndarray | None = None
    point_sigma: np.ndarray | None = None

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
        return MeasurementSet(self.kind, self.joints, measured, self.sigma, self.pairs, self.point_sigma)

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
                                  self.point_sigma)
        return MeasurementSet(self.kind, self.joints[idx], self.measured[idx], sig)


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
        r = (p - meas).reshape(p.shape[:-2] + (-1,))
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
        from station.core.transforms import rotation_exp

        shape = exact.shape[:-2]
        e = rng.standard_normal(shape + (6,)) * sig
        out = np.array(exact)
        out[..., :3, 3] += e[..., :3]
        # pose_error's rotation residual is R_model R_meas^T: perturb on the left in world frame.
        out[..., :3, :3] = rotation_exp(-e[..., 3:]) @ out[..., :3, :3]
        return out
    sig = sig[:, 0] if data.kind == "distance" else sig
    return exact + rng.standard_normal(exact.shape) * sig


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
