"""The simulated controller's own kinematics, sharing no code with ``station.core`` (issue 42,
"tests that catch the slips").

The simulated controller (simulators/controller_server.py) and the URScript arm
(simulators/urscript/arm.py) turn Cartesian targets into joints and joints into the pose they
report. If they called the station's ``forward`` / ``scara_ik`` / ``inverse_kinematics``, a slip
there (a wrong elbow sign, a yaw offset dropped) would move the robot exactly where the station,
making the same slip, expects it: the end-to-end tests would agree with themselves. So the
controller works here, on the robot file's documented chain (docs/robot-file.md, "Transforms";
the static transforms by :func:`simulators.truth_kinematics.pose_matrix`, as the simulated truth
builds them), by another route than the station's:

* forward: the chain walked once, the frame each joint moves in kept for the Jacobian (a revolute
  joint turns about its frame's z through its origin, a prismatic one moves along its z);
* a SCARA (R R P R; docs/protocols.md: elbow +1 is φ2 > 0): the planar two-link geometry is
  *measured* on the chain at q = 0 (where axes 1, 2 and 4 stand, where the tool sits off axis 4,
  which way the quill moves), the law of cosines gives the start, and Newton steps on x, y, z and
  yaw with the geometric Jacobian finish on the full model, tilts and all;
* any other chain: Levenberg-Marquardt on the position [mm] and the rotation vector of what
  rotation remains [rad], from the joints the arm stands at (which keeps its configuration).

A target it cannot reach raises :class:`Unreachable`. Parameters are plain data (the robot file's
transform kinds and a parameter vector), mm and rad.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.spatial.transform import Rotation

from simulators.truth_kinematics import pose_matrix

__all__ = ["Unreachable", "ArmKinematics"]

#: the residual rows x, y, z, yaw a SCARA can set (roll and pitch it cannot)
_SCARA_ROWS = np.array([0, 1, 2, 5])
#: 1 rad of rotation weighs as 100 mm, about an arm's wrist, so neither the position rows nor the
#: orientation rows dominate the least squares
_WEIGHT = np.array([1.0, 1.0, 1.0, 100.0, 100.0, 100.0])


class Unreachable(ValueError):
    """No joints put the tool at the target (out of reach, no convergence)."""


def _wrap(angle: float) -> float:
    return float(np.angle(np.exp(1j * angle)))


def _error(T: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Target minus reached: position [mm] and the rotation vector of R_target · Rᵀ [rad]."""
    rot = Rotation.from_matrix(target[:3, :3] @ T[:3, :3].T).as_rotvec()
    return np.concatenate([target[:3, 3] - T[:3, 3], rot])


class ArmKinematics:
    """A robot's chain in its base frame (the set-up transform left out, as a controller works).

    ``kinds``: per transform of the robot file, None (set-up, fixed links, tool), "revolute" or
    "prismatic"; ``params``: ``(6 · len(kinds),)`` x, y, z [mm], roll, pitch, yaw [rad] each.
    """

    def __init__(self, kinds: Sequence[str | None], params: np.ndarray):
        p = np.asarray(params, dtype=float).reshape(len(kinds), 6)
        # the static transforms once: a controller's IK walks the chain hundreds of times a move
        self._statics = pose_matrix(p[1:])
        self._kinds = tuple(kinds[1:])
        self.joint_kinds = tuple(k for k in kinds if k is not None)
        self.n_joints = len(self.joint_kinds)
        self.is_scara = self.joint_kinds == ("revolute", "revolute", "prismatic", "revolute")

    def frames(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The tool ``(4, 4)`` at joints ``q`` ``(g,)`` and ``(g, 4, 4)`` the frame each joint
        moves in (the chain up to and including its static transform)."""
        q = np.asarray(q, dtype=float)
        if q.shape != (self.n_joints,):
            raise ValueError(f"expected {self.n_joints} joint values, got shape {q.shape}")
        T = np.eye(4)
        frames = []
        for kind, S in zip(self._kinds, self._statics):
            T = T @ S
            if kind is None:
                continue
            frames.append(T)
            value = q[len(frames) - 1]
            motion = np.eye(4)
            if kind == "revolute":  # Rz(q)
                c, s = np.cos(value), np.sin(value)
                motion[:2, :2] = [[c, -s], [s, c]]
            else:  # Trans(0, 0, q)
                motion[2, 3] = value
            T = T @ motion
        return T, np.array(frames).reshape(self.n_joints, 4, 4)

    def forward(self, q: np.ndarray) -> np.ndarray:
        """The tool ``(4, 4)`` in the robot base frame at joints ``q`` ``(g,)``."""
        return self.frames(q)[0]

    def jacobian(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The tool and the geometric Jacobian ``(6, g)``: rows dx, dy, dz [mm], then the rotation
        vector [rad], per unit of each joint (revolute: ω = z, v = z × (tool − origin); prismatic:
        v = z, ω = 0)."""
        T, frames = self.frames(q)
        J = np.zeros((6, self.n_joints))
        for j, (kind, A) in enumerate(zip(self.joint_kinds, frames)):
            z = A[:3, 2]
            if kind == "revolute":
                J[:3, j] = np.cross(z, T[:3, 3] - A[:3, 3])
                J[3:, j] = z
            else:
                J[:3, j] = z
        return T, J

    def _scara_start(self, target: np.ndarray, elbow: int) -> np.ndarray:
        """Joints of the ideal SCARA (vertical parallel axes) by the law of cosines, on the
        planar geometry measured on the chain at the target's height (a tilted quill moves the
        wrist sideways as it goes down)."""
        T0, frames = self.frames(np.zeros(4))
        q3 = (target[2, 3] - T0[2, 3]) / frames[2][2, 2]  # the quill's z against the base's z
        T0, frames = self.frames(np.array([0.0, 0.0, q3, 0.0]))
        a1, a2, a4 = frames[0][:2, 3], frames[1][:2, 3], frames[3][:2, 3]
        L1, L2 = float(np.linalg.norm(a2 - a1)), float(np.linalg.norm(a4 - a2))
        off1 = np.arctan2((a2 - a1)[1], (a2 - a1)[0])
        off2 = np.arctan2((a4 - a2)[1], (a4 - a2)[0]) - off1
        turn = np.arctan2(target[1, 0], target[0, 0]) - np.arctan2(T0[1, 0], T0[0, 0])
        c, s = np.cos(turn), np.sin(turn)
        tool = T0[:2, 3] - a4  # the tool off axis 4 turns with the tool's yaw
        w = target[:2, 3] - np.array([c * tool[0] - s * tool[1], s * tool[0] + c * tool[1]]) - a1
        c_beta = (w @ w - L1**2 - L2**2) / (2 * L1 * L2)
        # a little beyond the ideal arm's reach may be inside the tilted one's: Newton decides
        if not abs(c_beta) <= 1.0 + 1e-3:
            raise Unreachable(f"the target at x={target[0, 3]:.1f} y={target[1, 3]:.1f} mm is outside "
                              f"the arm's reach ({abs(L1 - L2):.0f}..{L1 + L2:.0f} mm from axis 1)")
        # off the stretched arm's singularity, on the asked elbow's side
        beta = elbow * max(float(np.arccos(np.clip(c_beta, -1.0, 1.0))), 1e-3)
        alpha = np.arctan2(w[1], w[0]) - np.arctan2(L2 * np.sin(beta), L1 + L2 * np.cos(beta))
        q1, q2 = alpha - off1, beta - off2
        return np.array([_wrap(q1), _wrap(q2), q3, _wrap(turn - q1 - q2)])

    def scara_inverse(self, target: np.ndarray, elbow: int, tol: float = 1e-10, max_iter: int = 30) -> np.ndarray:
        """Joints ``(4,)`` [rad, rad, mm, rad] that put an R R P R arm's tool at ``target``
        ``(4, 4)`` in x, y, z and yaw, with elbow ``+1`` (φ2 > 0) or ``-1``."""
        if not self.is_scara:
            raise ValueError(f"not a SCARA (R R P R): {self.joint_kinds}")
        if elbow not in (1, -1):
            raise ValueError("elbow must be +1 or -1")
        T_target = np.asarray(target, dtype=float)
        q = self._scara_start(T_target, elbow)
        for _ in range(max_iter):
            T, J = self.jacobian(q)
            e = _error(T, T_target)[_SCARA_ROWS]
            try:
                step = np.linalg.solve(J[_SCARA_ROWS], e)
            except np.linalg.LinAlgError as exc:
                raise Unreachable("the SCARA stands stretched or folded: no unique joints") from exc
            q = q + step
            if np.max(np.abs(step)) < tol:
                if np.max(np.abs(_error(self.forward(q), T_target)[_SCARA_ROWS][:3])) > 1e-6:
                    break
                return q
        raise Unreachable("the SCARA's Newton steps did not settle: the target is out of reach")

    def inverse(self, target: np.ndarray, q_near: np.ndarray, tol_mm: float = 1e-6, max_iter: int = 200) -> np.ndarray:
        """Joints ``(g,)`` that put the tool at ``target`` ``(4, 4)``, found from ``q_near`` (the
        configuration the arm stands in) by Levenberg-Marquardt. With fewer than six joints the
        closest pose is the answer (in the weighted least-squares sense)."""
        T_target = np.asarray(target, dtype=float)
        q = np.array(q_near, dtype=float)
        lam = 1e-3
        T, J = self.jacobian(q)
        e = _error(T, T_target) * _WEIGHT
        for _ in range(max_iter):
            Jw = J * _WEIGHT[:, None]
            step = np.linalg.solve(Jw.T @ Jw + lam * np.eye(self.n_joints), Jw.T @ e)
            T_new, J_new = self.jacobian(q + step)
            e_new = _error(T_new, T_target) * _WEIGHT
            if e_new @ e_new < e @ e:  # accepted: towards Gauss-Newton
                q, J, e, lam = q + step, J_new, e_new, max(lam / 10.0, 1e-12)
                if np.max(np.abs(step)) < 1e-12:
                    break
            else:  # refused: towards gradient descent
                lam *= 10.0
                if lam > 1e12:
                    break
        if self.n_joints >= 6 and not (np.linalg.norm(e[:3]) <= tol_mm and np.linalg.norm(e[3:]) <= tol_mm):
            raise Unreachable(f"no joints reach the target (left {np.linalg.norm(e[:3]):.3g} mm off)")
        return q
