"""Compensated targets (brief §8): for a controller that keeps its nominal model and takes no
correction table, the Cartesian targets to command so that the real (identified) robot lands
where the user wants it. Pure numerics, mm and rad.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from station.core.kinematics import forward, inverse_kinematics, scara_ik
from station.core.model import RobotModel
from station.core.transforms import invert, pose_to_matrix
from station.errors import ConfigError

__all__ = ["CompensatedTargets", "compensated_targets"]


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
    if nominal.is_scara:
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
