"""The shape of the gravity torques fitted where the robot file gives no masses (issue 38): the
``mass_shape`` family. Pure functions; mm, rad, kg, N·m inside.

Without masses, the compliance term of :mod:`station.core.terms.error_model` loads every joint
with a *lumped* torque: 1 kg at every later joint's origin and at the tool point. A real arm
carries most of its weight at the elbow and the wrist (the simulated IRB 2600 class of
:mod:`simulators.joint_errors`: 60 kg at joint 3, 25 kg at joint 5, 5 kg at the tool), and the
lumped shape then misses: on that arm, noise-free, the geometry with lumped compliance and the
true harmonics misses the simulated arm by 4.6-5.0 µm RMS, with the true masses by 0.8 µm
(``benchmarks/bench_six_axis.py --terms``).

A joint's deflection under gravity is ``Δq_i = c_i τ_i = c_i Σ_b m_b τ_i^b(q)``, with ``τ_i^b`` the
torque about joint i of 1 kg at the lumped point b. The lumped term takes every ``m_b = 1``; the
mass shape frees the products ``c_i m_b``: one parameter per loaded joint and lumped point it
carries, linear like every other term (one ``c_i`` per mass instead of one compliance and shared
mass ratios: linear, so the cross-validation, σ and the paired test apply unchanged, at the cost of
a few parameters more than the bilinear form). The lumped compliance column is the sum of its
joint's mass-shape columns, so beside compliance one column per joint merges with it and the fit
drops it (:func:`station.core.terms.fit.fit_terms`), as it drops points that coincide (a spherical
wrist's joint 4, 5 and 6 origins). ``--model auto`` tries the shape after compliance, at
compliance's physics level, and keeps it only where the held-out error earns it
(:mod:`station.core.terms.selection`).
"""

from __future__ import annotations

import numpy as np

from station.core.kinematics.forward import _chain
from station.core.kinematics.model import RobotModel

__all__ = ["FAMILY", "UNIT", "lumped_points", "point_torques"]

#: the family's name (``mass_shape.q2.j3``: joint 2 loaded by 1 kg at joint 3's origin)
FAMILY = "mass_shape"
#: the unit of a mass-shape parameter: the joint's compliance times the mass there
UNIT = "rad per N·m of 1 kg there"


def lumped_points(model: RobotModel) -> tuple[str, ...]:
    """The labels of the lumped term's points: ``j2`` … ``jg`` (later joints' origins) and ``tool``."""
    return tuple(f"j{k + 2}" for k in range(model.n_joints - 1)) + ("tool",)


def point_torques(model: RobotModel, joints: np.ndarray, gravity: tuple[float, float, float], params=None) -> np.ndarray:
    """``(b, n, g)`` [N·m; N for a prismatic joint] the torque about every joint of 1 kg at each
    lumped point (:func:`lumped_points`) at ``joints`` ``(n, g)`` of the geometry ``params``
    (default nominal), gravity ``(3,)`` [m/s²] in the robot base frame. Their sum over the points
    is the lumped term of :func:`station.core.terms.error_model.gravity_torques`."""
    q = model.check_joints(joints)
    T, pres, consts, _ = _chain(model, q, params, setup=False, keep_frames=True)
    axes = [pres[t] @ consts[t] for t in model.joint_transforms]  # frame whose z axis is joint k's axis
    tool = T[..., :3, 3]
    points = [np.broadcast_to(a[..., :3, 3], tool.shape) for a in axes[1:]] + [tool]
    g_vec = np.asarray(gravity, dtype=float)
    out = np.zeros((len(points),) + q.shape)
    for b, pt in enumerate(points):
        for i in range(min(b + 1, len(axes))):  # point b (joint b+2's origin, or the tool) hangs on joints 1 … b+1
            z = np.broadcast_to(axes[i][..., :3, 2], tool.shape)
            if model.joint_types[i] == "revolute":
                lever = (pt - axes[i][..., :3, 3]) * 1e-3  # m
                out[b, :, i] = np.einsum("...c,...c->...", z, np.cross(lever, g_vec))
            else:
                out[b, :, i] = z @ g_vec
    return out
