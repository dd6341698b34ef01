"""A small six-axis arm for the URScript executor: it moves to commanded joints in simulated
time (one call of :meth:`Arm.step` per 2 ms frame), never in wall-clock time.

Motion follows the Script Directory's §14.22 ``movej``: "linear in joint-space", a trapezoid
speed profile whose ``a`` (joint acceleration) and ``v`` (joint speed) are those "of leading
axis"; every joint arrives at the same time. §14.44 ``stopj(a)`` decelerates the joint speeds to
zero at ``a`` (rad/s², of the leading axis). Kinematics (§15.11 ``get_forward_kin``, §15.13
``get_inverse_kin``) are the nominal model of a configured robot (default the built-in six-axis
``irb2600``), in metres and rotation vectors as URScript poses are: a stand-in for the UR's own
calibrated kinematics, which the station does not know. They are the simulator's own
(:class:`simulators.arm_kinematics.ArmKinematics`), never the station's: a slip in the station's
kinematics must not be made by the arm too, where the two would cancel.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["Arm"]


class Arm:
    """Joint positions ``q`` (rad) and the motion that changes them."""

    def __init__(self, q0=None, model_name: str = "irb2600"):
        self.q = np.zeros(6) if q0 is None else np.array(q0, dtype=float)
        if self.q.shape != (6,):
            raise ValueError("the arm has six joints")
        self.qd = np.zeros(6)
        self._model_name = model_name
        self._model: Any = None
        self._kinematics: Any = None
        self._move: tuple[np.ndarray, np.ndarray, float, float, float, float] | None = None
        self._stop: tuple[np.ndarray, np.ndarray, float] | None = None
        self._t = 0.0
        self.moves = 0

    # ------------------------------------------------------------------ motion
    @property
    def idle(self) -> bool:
        return self._move is None and self._stop is None

    def movej(self, target, a: float, v: float) -> None:
        """Start a joint move to ``target`` (§14.22): trapezoid of the leading axis."""
        q1 = np.array(target, dtype=float)
        if q1.shape != (6,) or not np.all(np.isfinite(q1)):
            raise ValueError("movej needs six finite joint positions")
        if not (a > 0 and v > 0):
            raise ValueError("movej needs a > 0 and v > 0")
        q0 = self.q.copy()
        d = float(np.max(np.abs(q1 - q0)))
        if d <= 0.0:
            self._move = None
            return
        if d >= v * v / a:
            ta = v / a
            total = d / v + ta
            vmax = v
        else:
            ta = math.sqrt(d / a)
            total = 2 * ta
            vmax = a * ta
        self._move = (q0, q1, d, a, vmax, total)
        self._stop = None
        self._t = 0.0
        self.moves += 1

    def stopj(self, a: float) -> None:
        """Decelerate every joint to rest (§14.44), the leading axis at ``a``."""
        if not a > 0:
            raise ValueError("stopj needs a > 0")
        self._move = None
        lead = float(np.max(np.abs(self.qd)))
        if lead <= 0.0:
            self._stop = None
            return
        self._stop = (self.q.copy(), self.qd.copy(), lead / a)
        self._t = 0.0

    def halt(self) -> None:
        """The program stopped: the arm stands where it is."""
        self._move = None
        self._stop = None
        self.qd = np.zeros(6)

    def step(self, dt: float) -> None:
        """Advance the motion by ``dt`` seconds of simulated time."""
        self._t += dt
        t = self._t
        if self._move is not None:
            q0, q1, d, a, vmax, total = self._move
            ta = vmax / a
            if t >= total:
                s, sd = d, 0.0
                self._move = None
            elif t < ta:
                s, sd = 0.5 * a * t * t, a * t
            elif t < total - ta:
                s, sd = 0.5 * a * ta * ta + vmax * (t - ta), vmax
            else:
                r = total - t
                s, sd = d - 0.5 * a * r * r, a * r
            self.q = q0 + (q1 - q0) * (s / d)
            self.qd = (q1 - q0) * (sd / d)
        elif self._stop is not None:
            qs, qds, tstop = self._stop
            tt = min(t, tstop)
            self.q = qs + qds * tt - 0.5 * (qds / tstop) * tt * tt
            self.qd = qds * (1.0 - tt / tstop)
            if t >= tstop:
                self._stop = None
                self.qd = np.zeros(6)
        else:
            self.qd = np.zeros(6)

    # ------------------------------------------------------------------ kinematics
    @property
    def model(self):
        if self._model is None:
            from station.io.robot.files import load_robot

            self._model = load_robot(self._model_name)
        return self._model

    @property
    def kinematics(self):
        if self._kinematics is None:
            from simulators.arm_kinematics import ArmKinematics

            self._kinematics = ArmKinematics([t.joint for t in self.model.transforms], self.model.nominal)
        return self._kinematics

    @staticmethod
    def _pose_matrix(pose) -> np.ndarray:
        from scipy.spatial.transform import Rotation

        T = np.eye(4)
        T[:3, :3] = Rotation.from_rotvec(np.asarray(pose[3:6], dtype=float)).as_matrix()
        T[:3, 3] = np.asarray(pose[:3], dtype=float) * 1000.0  # m -> mm
        return T

    @staticmethod
    def _matrix_pose(T: np.ndarray) -> list[float]:
        from scipy.spatial.transform import Rotation

        rv = Rotation.from_matrix(T[:3, :3]).as_rotvec()
        return [*(T[:3, 3] / 1000.0).tolist(), *rv.tolist()]

    def forward(self, q, tcp) -> list[float]:
        T = self.kinematics.forward(np.asarray(q, dtype=float))
        return self._matrix_pose(T @ self._pose_matrix(tcp))

    def inverse(self, pose, qnear, tcp, max_pos_m: float, max_rot: float) -> np.ndarray | None:
        from simulators.arm_kinematics import Unreachable
        from simulators.truth_kinematics import inverse

        target = self._pose_matrix(pose) @ inverse(self._pose_matrix(tcp))
        try:
            q = self.kinematics.inverse(target, np.asarray(qnear, dtype=float))
        except (Unreachable, np.linalg.LinAlgError):
            return None
        lo, hi = self.model.joint_limits.T
        if not np.all((lo <= q) & (q <= hi)):  # the arm cannot take joints beyond its limits
            return None
        T = self.kinematics.forward(q)
        err_pos = float(np.linalg.norm(T[:3, 3] - target[:3, 3])) / 1000.0
        err_rot = float(np.linalg.norm((T[:3, :3].T @ target[:3, :3]) - np.eye(3)))
        tol_pos = max(max_pos_m, 1e-7)  # a numerical IK: 0.1 µm at best
        tol_rot = max(max_rot, 1e-6)
        if not (np.all(np.isfinite(q)) and err_pos <= tol_pos and err_rot <= tol_rot):
            return None
        return q
