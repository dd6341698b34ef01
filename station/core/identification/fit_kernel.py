"""The identification fit's residuals and Jacobian at fixed joints, at the speed of the arithmetic.

A fit evaluates one data set at many parameter vectors. The joints never change, so their
motions are computed once; each evaluation composes the chain once and keeps the frame in front
of every transform, so that the Jacobian at a point whose residuals were just computed costs only
its assembly. The arithmetic is exactly that of :func:`station.core.kinematics.forward.forward_with_jacobian`
and :func:`station.core.measurement.measurements.residuals_and_jacobian` (the same operations in the same
order): the residuals and Jacobian are bit for bit theirs, and so is every fit that uses them.

:class:`DataEvaluator` remembers the last point evaluated and the last point whose Jacobian was
asked for: the solver's Jacobian at the point it has just evaluated, and the result's residuals and
Jacobian at the returned parameters, are taken from it when the parameters are the same bits.
:class:`FitProblem` is what a least-squares solver calls (``fun``, ``jac``); :func:`minpack_lm`
runs MINPACK's Levenberg–Marquardt on it. Pure numerics (mm, rad inside).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import _minpack

from station.core.kinematics.forward import _turn
from station.core.kinematics.model import RobotModel
from station.core.kinematics.transforms import pose_error, pose_to_matrix
from station.core.measurement.measurements import MeasurementSet


class FixedJointsChain:
    """``model``'s chain at fixed ``joints`` ``(n, g)``, evaluated at single parameter vectors."""

    def __init__(self, model: RobotModel, joints: np.ndarray, setup: bool):
        q = np.asarray(joints, dtype=float)
        self.n = q.shape[0]
        self.nt = len(model.transforms)
        self.setup = setup
        # each transform's joint motion (kind, values) or None, applied as the forward chain applies it
        motions: list[tuple[str, np.ndarray] | None] = []
        j = 0
        for spec in model.transforms:
            if spec.joint is None:
                motions.append(None)
            else:
                motions.append((spec.joint, q[:, j].copy()))
                j += 1
        self._motions = motions
        self._eye = np.ascontiguousarray(np.broadcast_to(np.eye(4), (self.n, 4, 4)))
        self._eye.flags.writeable = False

    def frames(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World←tool ``(n, 4, 4)`` and the frame in front of every transform ``(nt, n, 4, 4)``."""
        n = self.n
        C = pose_to_matrix(p.reshape(self.nt, 6))
        P = np.empty((self.nt, n, 4, 4))
        T = self._eye
        for t in range(self.nt):
            P[t] = T
            if t == 0 and not self.setup:
                continue
            # one (4n, 4) · (4, 4) product: the same sums as the stacked T @ C[t], one BLAS call
            T = (T.reshape(4 * n, 4) @ C[t]).reshape(n, 4, 4)
            m = self._motions[t]
            if m is not None:
                _turn(T, *m)
        return T, P

    def tool(self, p: np.ndarray, setup: bool) -> np.ndarray:
        """World←tool ``(n, 4, 4)`` at ``p`` with or without the set-up transform: :meth:`frames`'s
        chain (and so :func:`station.core.kinematics.forward`'s values) without the frames."""
        C = pose_to_matrix(p.reshape(self.nt, 6))
        n = self.n
        T = self._eye
        for t in range(0 if setup else 1, self.nt):
            T = (T.reshape(4 * n, 4) @ C[t]).reshape(n, 4, 4)
            m = self._motions[t]
            if m is not None:
                _turn(T, *m)
        return T

    def jacobian(self, T: np.ndarray, P: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Geometric Jacobian ``(n, 6, n_params)`` from :meth:`frames`: forward_with_jacobian's
        columns, transform by transform (translations: the frame's axes; rotations about the
        transform's origin: axis × lever over the axis)."""
        n, nt = self.n, self.nt
        Rp = np.ascontiguousarray(P[:, :, :3, :3])  # (nt, n, 3, 3)
        pt = p.reshape((nt, 6))
        origin = P[:, :, :3, 3] + np.einsum("...ij,...j->...i", Rp, pt[:, None, :3])
        # The axes of roll (Rz Ry e_x), pitch (Rz e_y) and yaw (e_z) in the frame in front of the
        # transform: each entry is a single product of rot_z's and rot_y's entries, so these are
        # the values of forward_with_jacobian's (Rz @ rot_y)[..., 0] and Rz[..., 1].
        yaw, pitch = pt[None, :, 5], pt[None, :, 4]
        cz, sz, cy, sy = np.cos(yaw)[0], np.sin(yaw)[0], np.cos(pitch)[0], np.sin(pitch)[0]
        local = np.zeros((nt, 3, 3))
        local[:, 0, 0], local[:, 1, 0], local[:, 2, 0] = cz * cy, sz * cy, -sy
        local[:, 0, 1], local[:, 1, 1] = -sz, cz
        local[:, 2, 2] = 1.0
        # Rp @ local: one (3n, 3) · (3, 3) product per transform, all in one stacked call
        RL = (Rp.reshape(nt, 3 * n, 3) @ local).reshape(nt, n, 3, 3)
        lever = T[None, :, :3, 3] - origin  # (nt, n, 3)
        l0, l1, l2 = lever[..., 0, None], lever[..., 1, None], lever[..., 2, None]
        a0, a1, a2 = RL[:, :, 0], RL[:, :, 1], RL[:, :, 2]  # (nt, n, 3 [roll, pitch, yaw]) per coordinate
        J = np.zeros((n, 6, nt, 6))
        J[:, :3, :, :3] = Rp.transpose(1, 2, 0, 3)
        # axis × lever (kinematics._cross's products and differences), each coordinate written
        # straight to its Jacobian row
        J[:, 0, :, 3:] = (a1 * l2 - a2 * l1).transpose(1, 0, 2)
        J[:, 1, :, 3:] = (a2 * l0 - a0 * l2).transpose(1, 0, 2)
        J[:, 2, :, 3:] = (a0 * l1 - a1 * l0).transpose(1, 0, 2)
        J[:, 3:, :, 3:] = RL.transpose(1, 2, 0, 3)
        if not self.setup:
            J[:, :, 0] = 0.0
        return J.reshape(n, 6, nt * 6)


#: the entries of a rotation whose differences are its rotation vector's direction (pose_error's vee)
_VEE_PLUS = (slice(None), np.array([2, 0, 1]), np.array([1, 2, 0]))
_VEE_MINUS = (slice(None), np.array([1, 2, 0]), np.array([2, 0, 1]))


class DataEvaluator:
    """Residuals and Jacobian of one data set at single parameter vectors, remembering the last
    point: its residuals, and its Jacobian once asked for, are reused while the parameters are
    the same bits (a solver asks for the Jacobian where it has just evaluated the residuals)."""

    def __init__(self, model: RobotModel, data: MeasurementSet):
        self.data = data
        self.chain = FixedJointsChain(model, data.joints, setup=data.uses_setup)
        self._meas = data.measured
        if data.kind == "distance":
            pr = data.distance_pairs()
            self._i, self._j = pr[:, 0], pr[:, 1]
        if data.kind == "pose":
            self._RmT = np.swapaxes(self._meas[:, :3, :3], -1, -2)
            self._meas_p = self._meas[:, :3, 3]
        self._key: bytes | None = None
        self._at: tuple = ()
        # the last point whose Jacobian was asked for: a solver returns a point it took, and it
        # took it after asking for the Jacobian there
        self._jkey: bytes | None = None
        self._jat: tuple[np.ndarray, np.ndarray] | None = None

    def _evaluate(self, p: np.ndarray) -> tuple:
        key = p.tobytes()
        if key != self._key:
            T, P = self.chain.frames(p)
            self._key, self._at = key, (p.copy(), T, P, self._residuals(T))
        return self._at

    def _residuals(self, T: np.ndarray) -> np.ndarray:
        kind = self.data.kind
        if kind == "pose":
            return self._pose_residuals(T)
        pts = T[..., :3, 3]
        if kind == "position":
            return (pts - self._meas).reshape(pts.shape[:-2] + (-1,))
        diff = pts[..., self._i, :] - pts[..., self._j, :]
        return np.linalg.norm(diff, axis=-1) - self._meas

    def _pose_residuals(self, T: np.ndarray) -> np.ndarray:
        """:func:`station.core.kinematics.transforms.pose_error` ``(T, measured)`` flattened, with the measured
        rotations' transposes kept and fewer array operations: the same values (rotations near
        180° take pose_error itself)."""
        dR = T[:, :3, :3] @ self._RmT
        cos = (dR[:, 0, 0] + dR[:, 1, 1] + dR[:, 2, 2] - 1.0) / 2.0
        angle = np.arccos(np.minimum(np.maximum(cos, -1.0), 1.0))  # np.clip's values, without its layers
        if (angle > np.pi - 1e-6).any():
            return pose_error(T, self._meas).reshape(-1)
        small = angle < 1e-6
        if small.any():
            factor = np.where(small, 0.5 + angle**2 / 12.0, angle / (2.0 * np.where(small, 1.0, np.sin(angle))))
        else:
            factor = angle / (2.0 * np.sin(angle))
        out = np.empty((self.chain.n, 6))
        out[:, :3] = T[:, :3, 3] - self._meas_p
        # (R21 − R12, R02 − R20, R10 − R01) · factor, the three rows at once
        out[:, 3:] = (dR[_VEE_PLUS] - dR[_VEE_MINUS]) * factor[:, None]
        return out.reshape(-1)

    def _jacobian_rows(self, T: np.ndarray, J: np.ndarray) -> np.ndarray:
        kind = self.data.kind
        if kind == "pose":
            return J.reshape(J.shape[:-3] + (-1, J.shape[-1]))
        if kind == "position":
            return J[..., :3, :].reshape(J.shape[:-3] + (-1, J.shape[-1]))
        pts = T[..., :3, 3]
        diff = pts[..., self._i, :] - pts[..., self._j, :]
        u = diff / np.linalg.norm(diff, axis=-1)[..., None]
        Jp = J[..., :3, :]
        return np.einsum("...kc,...kcp->...kp", u, Jp[..., self._i, :, :] - Jp[..., self._j, :, :])

    def residuals(self, p: np.ndarray) -> np.ndarray:
        """Unweighted residuals (model − measured) ``(n_rows,)`` at ``p`` ``(n_params,)``."""
        p = np.asarray(p, dtype=float)
        if self._jat is not None and p.tobytes() == self._jkey:
            return self._jat[0]
        return self._evaluate(p)[3]

    def residuals_and_jacobian(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Unweighted residuals ``(n_rows,)`` and Jacobian ``(n_rows, n_params)`` at ``p``: those of
        :func:`station.core.measurement.measurements.residuals_and_jacobian`, bit for bit."""
        p = np.asarray(p, dtype=float)
        key = p.tobytes()
        if self._jat is None or key != self._jkey:
            p, T, P, r = self._evaluate(p)
            self._jkey, self._jat = key, (r, self._jacobian_rows(T, self.chain.jacobian(T, P, p)))
        return self._jat


class FitProblem:
    """Weighted residuals ``fun(x)`` and Jacobian ``jac(x)`` of the parameters ``idx`` (the rest
    held at ``p0``), each row multiplied by ``w``: what identification minimises."""

    def __init__(self, evaluator: DataEvaluator, p0: np.ndarray, idx: np.ndarray, w: np.ndarray):
        self.evaluator = evaluator
        self.p0 = np.array(p0, dtype=float)
        self.idx = np.asarray(idx, dtype=int)
        self.w = w

    def full(self, x: np.ndarray) -> np.ndarray:
        p = self.p0.copy()
        p[self.idx] = x
        return p

    def fun(self, x: np.ndarray) -> np.ndarray:
        return self.evaluator.residuals(self.full(x)) * self.w

    def jac(self, x: np.ndarray) -> np.ndarray:
        _, J = self.evaluator.residuals_and_jacobian(self.full(x))
        return J[:, self.idx] * self.w[:, None]


#: MINPACK's ``info`` → scipy ``least_squares``' status and message (the fit reports them as before)
_STATUS = {0: -1, 1: 2, 2: 3, 3: 4, 4: 1, 5: 0}
_MESSAGES = {
    -1: "Improper input parameters status returned from `leastsq`",
    0: "The maximum number of function evaluations is exceeded.",
    1: "`gtol` termination condition is satisfied.",
    2: "`ftol` termination condition is satisfied.",
    3: "`xtol` termination condition is satisfied.",
    4: "Both `ftol` and `xtol` termination conditions are satisfied.",
}


@dataclass(frozen=True)
class LMSolution:
    """What :func:`minpack_lm` returns: ``x``, MINPACK's evaluation count ``nfev``, and the status
    (> 0: converged) and message in scipy ``least_squares``' terms."""

    x: np.ndarray
    nfev: int
    status: int
    message: str


def minpack_lm(prob: FitProblem, x0: np.ndarray, max_nfev: int, tol: float = 1e-15) -> LMSolution:
    """Levenberg–Marquardt on ``prob`` from ``x0``: MINPACK's ``lmder`` with exactly the arguments
    scipy ``least_squares(method="lm", x_scale="jac")`` gives it (the same iterates, bit for
    bit), without that wrapper's per-call layers and its extra Jacobian at the end."""
    x0 = np.array(x0, dtype=float).reshape(-1)
    f0 = prob.fun(x0)
    if not np.all(np.isfinite(f0)):
        raise ValueError("Residuals are not finite in the initial point.")
    if np.size(f0) < x0.size:
        raise TypeError(f"Improper input: func input vector length N={x0.size} must not exceed func output "
                        f"vector length M={np.size(f0)}")
    # MINPACK's lmder itself, called as scipy's ``leastsq`` calls it (the same compiled routine with the
    # same arguments, so the same iterates), without leastsq's trial calls of fun and jac and the
    # covariance it builds from MINPACK's factor at the end, which nothing here reads. The Jacobian goes
    # over as its transpose (col_deriv): numpy lays it out column-major for MINPACK faster than the
    # wrapper's element-by-element transposition does; the numbers are the same.
    x, info, ier = _minpack._lmder(prob.fun, lambda x: prob.jac(x).T, x0, (), 1, 1, tol, tol, tol,
                                   max_nfev if max_nfev > 0 else 100 * (x0.size + 1), 100.0, None)
    status = _STATUS.get(int(ier), -1)  # 6–8 (a tolerance below round-off) cannot occur at tol > eps
    return LMSolution(np.asarray(x, dtype=float), int(info["nfev"]), status, _MESSAGES[status])
