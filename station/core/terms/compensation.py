"""Compensated targets for a robot with error terms beyond geometry (issue 30).

The identified robot stands at ``q + Δq(q)`` when its encoders say ``q`` (compliance, gear
harmonics: :mod:`station.core.terms.error_model`). :func:`station.core.kinematics.compensation.compensated_targets`
finds the joints ``q_geo`` at which the identified *geometry* reaches the target; the joints to
command are then those the robot turns into ``q_geo``: ``q + Δq(q) = q_geo``, solved by fixed-point
iteration ``q ← q_geo − Δq(q)`` (Δq changes by micro-radians per radian, so it converges in a few
steps; the residual after it is reported; :func:`commanded_joints`). The commands are the nominal
model's poses at those joints, as without terms. A SCARA's correction table solves its nodes the
same way (:func:`station.core.table.build.build_correction_table` with ``delta``). Pure
numerics, mm and rad.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from station.core.kinematics.compensation import CompensatedTargets, compensated_targets
from station.core.kinematics.forward import forward
from station.core.kinematics.model import RobotModel
from station.core.kinematics.transforms import invert, pose_error, pose_to_matrix

__all__ = ["JointDelta", "commanded_joints", "compensated_targets_with_terms"]

#: fixed-point steps at most and the joint change [rad] below which it has converged
MAX_STEPS = 20
TOLERANCE = 1e-12
#: a joint change [rad, mm] still above this after :data:`MAX_STEPS` steps: not converged
CONVERGED = 1e-9

#: ``q ↦ Δq(q)``: ``(n, g)`` commanded joints [rad | mm] → ``(n, g)`` how far the identified robot
#: really stands from them (it stands at ``q + Δq(q)``)
JointDelta = Callable[[np.ndarray], np.ndarray]


def commanded_joints(q_geo: np.ndarray, delta_q: JointDelta) -> tuple[np.ndarray, np.ndarray]:
    """The joints ``q`` ``(n, g)`` [rad | mm] to command so that a robot standing at ``q + Δq(q)``
    stands at ``q_geo`` ``(n, g)`` (the identified geometry's IK of a target): the fixed point
    ``q = q_geo − Δq(q)`` from ``q_geo``, and ``(n,)`` bool whether each row converged (its last
    step below :data:`CONVERGED`). Δq changes by micro-radians per radian (a gear harmonic's
    amplitude times its ratio), so each step shrinks the error by that factor."""
    q_geo = np.asarray(q_geo, dtype=float)
    q = q_geo.copy()
    step = np.zeros(q.shape[0])
    for _ in range(MAX_STEPS):
        q_new = q_geo - delta_q(q)
        step = np.max(np.abs(q_new - q), axis=1) if q.size else step
        q = q_new
        if not q.size or float(step.max()) < TOLERANCE:
            break
    return q, step < CONVERGED


def compensated_targets_with_terms(nominal: RobotModel, identified_params, delta_q: JointDelta,
                                   targets, setup: bool = False, **kwargs) -> CompensatedTargets:
    """:func:`~station.core.kinematics.compensation.compensated_targets` for a robot whose joints stand at
    ``q + delta_q(q)`` (``delta_q``: ``(n, g)`` → ``(n, g)`` [rad, mm]). ``kwargs`` as there
    (configuration, allow_singular, …). The residuals are the full model's (geometry and terms)."""
    identified = np.asarray(identified_params, dtype=float)
    res = compensated_targets(nominal, identified, targets, setup=setup, **kwargs)
    has = np.all(np.isfinite(res.joints), axis=1)
    if not np.any(has):
        return res
    q, _ = commanded_joints(res.joints[has], delta_q)
    Tt = np.asarray(targets, dtype=float).reshape(-1, 4, 4)
    if setup:
        Tt = invert(pose_to_matrix(identified[0:6]))[None] @ Tt
    joints = res.joints.copy()
    joints[has] = q
    commands = res.commands.copy()
    commands[has] = forward(nominal, q, nominal.nominal, setup=False)
    reached = forward(nominal, q + delta_q(q), identified, setup=False)
    e = pose_error(reached, Tt[has])
    res_um, res_as = res.residual_um.copy(), res.residual_arcsec.copy()
    res_um[has] = np.linalg.norm(e[:, :3], axis=1) * 1e3
    ang = np.abs(e[:, 5]) if nominal.is_scara else np.linalg.norm(e[:, 3:], axis=1)
    res_as[has] = np.degrees(ang) * 3600.0
    c = pose_error(commands[has], Tt[has])
    cor_um, cor_as = res.correction_um.copy(), res.correction_arcsec.copy()
    cor_um[has] = np.linalg.norm(c[:, :3], axis=1) * 1e3
    cor_as[has] = np.degrees(np.linalg.norm(c[:, 3:], axis=1)) * 3600.0
    return dataclasses.replace(res, joints=joints, commands=commands, residual_um=res_um, residual_arcsec=res_as,
                               correction_um=cor_um, correction_arcsec=cor_as)
