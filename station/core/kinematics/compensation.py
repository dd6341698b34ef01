"""Compensated targets (brief §8): for a controller that keeps its nominal model and takes no
correction table, the Cartesian targets to command so that the real (identified) robot lands
where the user wants it. Works for any robot the general inverse kinematics solves
(:mod:`station.core.kinematics.ik`: six-axis arms, SCARAs, other chains). Pure numerics, mm and rad.

For a wanted pose P: solve the inverse kinematics of the *identified* model, q' = IK_id(P) (in
a chosen configuration), and command C = FK_nominal(q'). The controller, given C and the same
configuration, solves its nominal IK to exactly q', so the real robot reaches FK_id(q') = P.
Targets that cannot be compensated (out of reach, outside the joint limits, the requested
configuration unavailable, near a singularity) are reported per target with the reason; the
others are still compensated.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from station.core.kinematics.forward import forward
from station.core.kinematics.ik import IKStatus, solve_ik
from station.core.kinematics.ik import configuration as arm_configuration
from station.core.kinematics.model import RobotModel
from station.core.kinematics.transforms import invert, pose_error, pose_to_matrix
from station.errors import ConfigError, UnreachableError

__all__ = ["CompensatedTargets", "compensated_targets"]


@dataclass(frozen=True)
class CompensatedTargets:
    """Per target (``n``), in the robot base frame:

    ``joints`` ``(n, g)``: joints that put the identified robot on the target (NaN where none);
    ``commands`` ``(n, 4, 4)``: the Cartesian targets to give the NOMINAL controller,
    ``FK_nominal(joints)`` (NaN where none); ``config`` ``(n, 3)`` shoulder, elbow, wrist signs
    to command with them (:func:`station.core.kinematics.ik.configuration`; a SCARA: elbow only);
    ``residual_um`` / ``residual_arcsec`` ``(n,)``: what the identified robot misses the target
    by with ``joints`` (≈ 0; a SCARA's roll and pitch are not counted, it cannot set them);
    ``correction_um`` / ``correction_arcsec`` ``(n,)``: how far each command lies from its
    target (the size of the compensation); ``status`` / ``reason``: per target, reason "" when
    ok. Rows near a singularity keep their joints and commands but are not ``ok``.
    """

    joints: np.ndarray
    commands: np.ndarray
    config: np.ndarray
    residual_um: np.ndarray
    residual_arcsec: np.ndarray
    correction_um: np.ndarray
    correction_arcsec: np.ndarray
    status: tuple[IKStatus, ...]
    reason: tuple[str, ...]

    @property
    def ok(self) -> np.ndarray:
        """``(n,)`` bool: compensated (allowed singular rows count as ok when requested)."""
        return np.array([s is IKStatus.OK for s in self.status], dtype=bool)

    def failures(self) -> list[tuple[int, IKStatus, str]]:
        """``(index, status, reason)`` of every target not compensated (0-based index)."""
        return [(i, s, r) for i, (s, r) in enumerate(zip(self.status, self.reason)) if s is not IKStatus.OK]

    def raise_for_failures(self) -> np.ndarray:
        """The commands, or :class:`UnreachableError` naming the first failed targets."""
        bad = self.failures()
        if bad:
            head = "; ".join(f"target {i}: {r}" for i, _, r in bad[:3])
            more = f" (and {len(bad) - 3} more)" if len(bad) > 3 else ""
            raise UnreachableError(f"{len(bad)} of {len(self.status)} targets cannot be compensated: {head}{more}")
        return self.commands


def compensated_targets(nominal: RobotModel, identified_params, targets, q0=None, setup: bool = False,
                        configuration=None, allow_singular: bool = False,
                        singular_deg: float = 1.0) -> CompensatedTargets:
    """Compensated Cartesian targets for a controller that keeps its nominal model.

    ``targets`` ``(n, 4, 4)``: where the tool shall be, in the robot base frame (or, with
    ``setup=True``, in the measurement frame; the identified set-up R converts them, and the
    commands are in the base frame). ``configuration``: an :class:`~station.core.kinematics.ik.ArmConfig`,
    a sequence of them or ``(n, 3)`` signs (0 = any) — the controller must be given the same
    configuration as the returned ``config``. ``q0`` ``(n, g)`` (optional): joints near the
    wanted solution; without a ``configuration`` their configuration is requested (for a SCARA:
    the elbow is the sign of q0's second joint) and the solution nearest to them is taken.
    ``allow_singular``: targets near a singularity (wrist sine below sin(``singular_deg``))
    count as compensated. Never raises for a target (:meth:`CompensatedTargets.raise_for_failures`).
    """
    identified = np.asarray(identified_params, dtype=float)
    if identified.shape != nominal.nominal.shape:
        raise ConfigError(f"identified parameters must be a vector of {nominal.n_params} values")
    Tt = np.asarray(targets, dtype=float).reshape(-1, 4, 4)
    n, g = Tt.shape[0], nominal.n_joints
    near = None
    if q0 is not None:
        near = np.asarray(q0, dtype=float).reshape(n, g)
        if configuration is None:
            configuration = arm_configuration(nominal, near, identified, setup=False)
    if setup:
        Tt = invert(pose_to_matrix(identified[0:6]))[None] @ Tt
    ik = solve_ik(nominal, Tt, identified, setup=False, configuration=configuration, near=near,
                  singular_deg=singular_deg)
    status = list(ik.status)
    if allow_singular:
        status = [IKStatus.OK if s is IKStatus.NEAR_SINGULARITY else s for s in status]
    has = ik.has_joints
    joints = ik.joints
    commands = np.full((n, 4, 4), np.nan)
    res_um = np.full(n, np.nan)
    res_as = np.full(n, np.nan)
    cor_um = np.full(n, np.nan)
    cor_as = np.full(n, np.nan)
    if np.any(has):
        q = joints[has]
        reached = forward(nominal, q, identified, setup=False)
        e = pose_error(reached, Tt[has])
        res_um[has] = np.linalg.norm(e[:, :3], axis=1) * 1e3
        ang = np.abs(e[:, 5]) if nominal.is_scara else np.linalg.norm(e[:, 3:], axis=1)
        res_as[has] = np.degrees(ang) * 3600.0
        commands[has] = forward(nominal, q, nominal.nominal, setup=False)
        c = pose_error(commands[has], Tt[has])
        cor_um[has] = np.linalg.norm(c[:, :3], axis=1) * 1e3
        cor_as[has] = np.degrees(np.linalg.norm(c[:, 3:], axis=1)) * 3600.0
    return CompensatedTargets(joints, commands, ik.config, res_um, res_as, cor_um, cor_as,
                              tuple(status), ik.reason)
