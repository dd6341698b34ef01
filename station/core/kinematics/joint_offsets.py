"""Joint-zero offsets only: the correction for controllers that accept nothing else (brief §8).

Many controllers take no correction table and no new kinematic model, but let the user shift the
zero of each joint (axis calibration / mastering offsets). This module fits those offsets so that
the nominal model with shifted zeros behaves as closely as possible like the identified model,
and states what that leaves compared with the full model.

**What is fitted.** Offsets ``δ`` ``(g,)`` [rad for revolute, mm for prismatic joints] such that

    FK_nominal(q + δ) ≈ FK_identified(q)     over a set of joints q (base frame, no set-up R)

by (Gauss–Newton) least squares on the pose residual, rotations weighted by
``rotation_weight_mm`` (200 mm per rad: 1″ counts like about 1 µm). The real robot at the
controller's joints q behaves like the nominal model at q + δ, so a controller that shall reach T
commands ``IK_nominal(T) − δ`` (:func:`offset_joints`; how a controller's own offset parameter is
signed is its manual's business).

**Why fit to the identified model and not to the measurements directly.** (1) The identified model
is already the best estimate of the robot from the measurements: noise averaged, outliers
rejected, with its uncertainty. (2) It can be sampled over the whole workspace the robot will work
in (``joints``: e.g. spread over the limits, or the user's program), so the offsets are best where
they are used rather than at the calibration poses only. (3) It works for every measurement
objective — distance measurements carry no absolute positions to fit to — and needs no second
registration of the measurement frame. A robot whose only errors are joint-zero errors is
recovered exactly either way (tests check that).

Offsets that the residual cannot see (e.g. axis 6 with position-only weighting and the tool on
axis 6) are held at 0 and named in ``unobservable``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from station.core.kinematics.forward import forward, joint_jacobian
from station.core.kinematics.ik import solve_ik
from station.core.kinematics.model import RobotModel
from station.core.kinematics.transforms import matrix_to_pose, pose_error, pose_to_matrix
from station.core.units import ARCSEC, UM
from station.errors import ConfigError

__all__ = ["JointOffsets", "OffsetAccuracy", "ErrorFigures", "apply_joint_offsets", "fit_joint_offsets",
           "offset_joints", "offset_accuracy"]


@dataclass(frozen=True)
class ErrorFigures:
    """RMS and largest position [µm] and orientation [″] error over a set of poses."""

    rms_position_um: float
    max_position_um: float
    rms_orientation_arcsec: float
    max_orientation_arcsec: float

    @classmethod
    def of(cls, pos_mm: np.ndarray, ang_rad: np.ndarray) -> ErrorFigures:
        p, a = np.asarray(pos_mm, dtype=float) / UM, np.asarray(ang_rad, dtype=float) / ARCSEC
        if p.size == 0:
            return cls(float("nan"), float("nan"), float("nan"), float("nan"))
        return cls(float(np.sqrt(np.mean(p ** 2))), float(p.max()), float(np.sqrt(np.mean(a ** 2))), float(a.max()))

    def to_dict(self) -> dict:
        return {"rms_position_um": self.rms_position_um, "max_position_um": self.max_position_um,
                "rms_orientation_arcsec": self.rms_orientation_arcsec,
                "max_orientation_arcsec": self.max_orientation_arcsec}


@dataclass(frozen=True)
class JointOffsets:
    """Fitted offsets ``offsets`` ``(g,)`` [rad | mm] of the joints ``names``; ``unobservable``:
    joints held at 0; ``fit``: how far the offset model stays from the identified model over
    the ``n_poses`` fit joints (what the offsets cannot express)."""

    offsets: np.ndarray
    names: tuple[str, ...]
    joint_types: tuple[str, ...]
    unobservable: tuple[str, ...]
    fit: ErrorFigures
    n_poses: int
    rotation_weight_mm: float

    def params(self, nominal: RobotModel) -> np.ndarray:
        """The nominal parameters with the offsets folded in (``FK(params, q) = FK_nominal(q + δ)``)."""
        return apply_joint_offsets(nominal, nominal.nominal, self.offsets)

    def to_dict(self) -> dict:
        out = []
        for n, t, v in zip(self.names, self.joint_types, self.offsets):
            out.append({"joint": n, **({"offset_deg": float(np.degrees(v)), "offset_arcsec": float(v / ARCSEC)}
                                       if t == "revolute" else {"offset_mm": float(v), "offset_um": float(v / UM)})})
        return {"offsets": out, "unobservable": list(self.unobservable), "fit_poses": self.n_poses,
                "rotation_weight_mm_per_rad": self.rotation_weight_mm,
                "left_versus_identified_model": self.fit.to_dict()}


def apply_joint_offsets(model: RobotModel, params, offsets) -> np.ndarray:
    """``params`` with joint-zero ``offsets`` ``(g,)`` folded into the joint transforms: each
    transform C becomes C·Rz(δ) (revolute) or C·Tz(δ) (prismatic), so that the model at q equals
    the original at q + δ exactly."""
    p = np.array(params, dtype=float)
    d = np.asarray(offsets, dtype=float).reshape(model.n_joints)
    for j, t in enumerate(model.joint_transforms):
        C = pose_to_matrix(p[6 * t: 6 * t + 6])
        S = np.eye(4)
        if model.transforms[t].joint == "revolute":
            c, s = np.cos(d[j]), np.sin(d[j])
            S[:2, :2] = [[c, -s], [s, c]]
        else:
            S[2, 3] = d[j]
        p[6 * t: 6 * t + 6] = matrix_to_pose(C @ S)
    return p


def _pose_errors(model: RobotModel, T_reached, T_wanted) -> tuple[np.ndarray, np.ndarray]:
    e = pose_error(T_reached, T_wanted)
    ang = np.abs(e[:, 5]) if model.is_scara else np.linalg.norm(e[:, 3:], axis=1)
    return np.linalg.norm(e[:, :3], axis=1), ang


def fit_joint_offsets(nominal: RobotModel, identified_params, joints, rotation_weight_mm: float = 200.0,
                      max_iter: int = 20) -> JointOffsets:
    """Least-squares joint-zero offsets (module docstring) over ``joints`` ``(n, g)``.

    ``rotation_weight_mm`` = 0 fits positions only. For a SCARA only x, y, z and yaw count.
    """
    ident = np.asarray(identified_params, dtype=float)
    if ident.shape != nominal.nominal.shape:
        raise ConfigError(f"identified parameters must be a vector of {nominal.n_params} values")
    q = nominal.check_joints(joints)
    if not (np.isfinite(rotation_weight_mm) and rotation_weight_mm >= 0):
        raise ConfigError("rotation_weight_mm must be a finite number ≥ 0")
    g = nominal.n_joints
    rows = np.array([0, 1, 2, 5]) if nominal.is_scara else np.arange(6)
    W = np.where(rows < 3, 1.0, rotation_weight_mm)
    keep = rows[W > 0]
    Wk = W[W > 0]
    T_id = forward(nominal, q, ident, setup=False)
    delta = np.zeros(g)
    free = np.ones(g, dtype=bool)
    # which offsets the residual can see: greedy, drop the one most in the null space
    J0 = joint_jacobian(nominal, q, setup=False).J[:, keep, :] * Wk[:, None]
    A = J0.reshape(-1, g)
    while free.any():
        cols = A[:, free]
        scale = np.linalg.norm(cols, axis=0)
        if np.min(scale) <= 1e-9 * np.max(np.linalg.norm(A, axis=0)):
            free[np.nonzero(free)[0][np.argmin(scale)]] = False
            continue
        _, s, Vt = np.linalg.svd(cols / scale, full_matrices=False)
        if s[-1] > 1e-8 * s[0]:
            break
        free[np.nonzero(free)[0][int(np.argmax(np.abs(Vt[-1])))]] = False
    for _ in range(max_iter):
        res = joint_jacobian(nominal, q + delta, setup=False)
        e = (pose_error(res.T, T_id)[:, keep] * Wk).reshape(-1)
        J = (res.J[:, keep, :] * Wk[:, None]).reshape(-1, g)[:, free]
        step, *_ = np.linalg.lstsq(J, -e, rcond=None)
        delta[free] += step
        if np.max(np.abs(step)) < 1e-14:
            break
    pos, ang = _pose_errors(nominal, forward(nominal, q + delta, setup=False), T_id)
    names = tuple(nominal.transforms[t].name for t in nominal.joint_transforms)
    return JointOffsets(delta, names, nominal.joint_types, tuple(n for n, f in zip(names, free) if not f),
                        ErrorFigures.of(pos, ang), len(q), float(rotation_weight_mm))


def offset_joints(nominal: RobotModel, offsets, targets, configuration=None):
    """The joints a controller with joint-zero ``offsets`` commands for ``targets`` ``(n, 4, 4)``
    (base frame): ``IK_nominal(T) − δ``. Returns the :class:`station.core.kinematics.ik.IKResult` of the
    nominal model with its joints shifted (NaN rows where the nominal IK has none)."""
    from dataclasses import replace

    r = solve_ik(nominal, targets, nominal.nominal, setup=False, configuration=configuration)
    return replace(r, joints=r.joints - np.asarray(offsets, dtype=float)[None, :])


@dataclass(frozen=True)
class OffsetAccuracy:
    """Side by side on the same targets, where the robot (``reference`` parameters) lands when
    the controller uses: its nominal model (``uncorrected``), joint-zero offsets only
    (``joint_offsets``), the full identified model through compensated targets (``full_model``).
    ``n_targets``: targets all three could be evaluated on. With the identified model as the
    reference the full model is exact by construction (its figures are round-off); with the
    true robot (simulation) or measurements they are the real comparison."""

    uncorrected: ErrorFigures
    joint_offsets: ErrorFigures
    full_model: ErrorFigures
    n_targets: int
    reference: str

    def to_dict(self) -> dict:
        return {"reference": self.reference, "targets": self.n_targets, "uncorrected": self.uncorrected.to_dict(),
                "joint_offsets": self.joint_offsets.to_dict(), "full_model": self.full_model.to_dict()}


def offset_accuracy(nominal: RobotModel, identified_params, offsets, targets, reference_params=None,
                    configuration=None) -> OffsetAccuracy:
    """Errors on ``targets`` ``(n, 4, 4)`` (base frame) of the three corrections (:class:`OffsetAccuracy`).

    ``reference_params``: the robot that moves (default: the identified model, i.e. predicted
    figures; in simulation: the true parameters). Each target is solved once on the identified
    model (configuration as :func:`station.core.kinematics.ik.solve_ik` chooses, or ``configuration``) and
    the nominal IKs are asked for that same configuration.
    """
    ident = np.asarray(identified_params, dtype=float)
    ref = ident if reference_params is None else np.asarray(reference_params, dtype=float)
    Tt = np.asarray(targets, dtype=float).reshape(-1, 4, 4)
    full = solve_ik(nominal, Tt, ident, setup=False, configuration=configuration)
    nom = solve_ik(nominal, Tt, nominal.nominal, setup=False, configuration=full.config)
    good = full.has_joints & nom.has_joints
    Tg = Tt[good]
    q_full, q_nom = full.joints[good], nom.joints[good]
    d = np.asarray(offsets, dtype=float)[None, :]
    figs = []
    for q in (q_nom, q_nom - d, q_full):
        pos, ang = _pose_errors(nominal, forward(nominal, q, ref, setup=False), Tg)
        figs.append(ErrorFigures.of(pos, ang))
    return OffsetAccuracy(figs[0], figs[1], figs[2], int(good.sum()),
                          "identified model (predicted)" if reference_params is None else "reference parameters")
