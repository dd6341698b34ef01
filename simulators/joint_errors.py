"""Joint errors beyond geometry of a simulated arm (issue 30): joints that bend under gravity and
gears that err once per turn. The truth's own physics, sharing no code with ``station.core``
(the station's error terms are fitted against it, so they must not be computed by it).

* compliance — each joint gives way by ``c_j · τ_j`` [rad], ``τ_j`` [N·m] the gravity torque about
  it: ``τ = −∂V/∂q`` with ``V = Σ m_b g z_b`` of point masses ``m_b`` at joint origins and at the
  tool (payload), by central differences of :func:`simulators.truth_kinematics.true_forward`.
* cyclic — each joint errs by ``a_j cos q_j + b_j sin q_j`` [rad] (first harmonic).

:func:`six_axis_joint_errors` gives values of a 1.6 m industrial arm (IRB 2600 class: ~60 kg
carried at the elbow, ~25 kg at the wrist, a 5 kg head; joint stiffness 1.7–2.5·10⁶ N·m/rad at
shoulder and elbow, so the shoulder gives ~0.3 mrad, ~0.3 mm at the tool, at full reach; gear
errors of ~10″); :func:`scara_joint_errors` the gear errors of a SCARA (its vertical axes carry no
gravity torque, its quill the same load in every pose: no compliance). Units: rad, kg, mm, N·m.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from simulators.truth_kinematics import true_forward
from station.core.kinematics.model import RobotModel

__all__ = ["JointErrors", "six_axis_joint_errors", "scara_joint_errors", "NO_JOINT_ERRORS"]

GRAVITY = 9.80665


@dataclass(frozen=True)
class JointErrors:
    """``compliance`` ``(g,)`` [rad/(N·m)]; ``masses``: ``((joint index, kg), …)`` point masses at
    those joints' origins; ``payload_kg`` at the tool point; ``cyclic`` ``(g, 2)`` [rad] the
    cos and sin amplitudes of every joint's first harmonic."""

    compliance: tuple[float, ...] = ()
    masses: tuple[tuple[int, float], ...] = ()
    payload_kg: float = 0.0
    cyclic: tuple[tuple[float, float], ...] = ()

    @property
    def active(self) -> bool:
        return any(self.compliance) or any(a or b for a, b in self.cyclic)

    def torques(self, model: RobotModel, params: np.ndarray, q: np.ndarray) -> np.ndarray:
        """``(n, g)`` [N·m] gravity torque about every joint at joints ``q`` (robot base frame, −z down)."""
        kinds = [t.joint for t in model.transforms]
        jt = [i for i, k in enumerate(kinds) if k is not None]
        p = np.asarray(params, dtype=float)

        def potential(qq: np.ndarray) -> np.ndarray:
            v = np.zeros(qq.shape[0])
            for j, m in self.masses:
                t = jt[j]
                v += m * GRAVITY * 1e-3 * true_forward(kinds[:t + 1], p[:6 * (t + 1)], qq[:, :j + 1],
                                                      setup=False)[:, 2, 3]
            if self.payload_kg:
                v += self.payload_kg * GRAVITY * 1e-3 * true_forward(kinds, p, qq, setup=False)[:, 2, 3]
            return v

        q = np.atleast_2d(np.asarray(q, dtype=float))
        n, g = q.shape
        h = 1e-6
        # every joint's ±h at once: one batch through the kinematics instead of 2·g calls (the
        # simulated controller computes this at every command)
        steps = np.concatenate([np.eye(g) * h, -np.eye(g) * h])
        v = potential((q[None, :, :] + steps[:, None, :]).reshape(-1, g)).reshape(2 * g, n)
        return -(v[:g] - v[g:]).T / (2 * h)

    def delta(self, model: RobotModel, params: np.ndarray, q: np.ndarray) -> np.ndarray:
        """``(n, g)`` [rad] how far the joints stand from where the encoders say, at joints ``q``."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        out = np.zeros(q.shape)
        if any(self.compliance):
            out += np.asarray(self.compliance, dtype=float) * self.torques(model, params, q)
        if self.cyclic:
            ab = np.asarray(self.cyclic, dtype=float)
            out += ab[:, 0] * np.cos(q) + ab[:, 1] * np.sin(q)
        return out


NO_JOINT_ERRORS = JointErrors()


def six_axis_joint_errors(seed: int = 1, scale: float = 1.0) -> JointErrors:
    """Realistic joint errors of a 1.6 m six-axis arm (see the module), phases of the gear errors
    drawn from ``seed``; ``scale`` multiplies every amplitude (0: none)."""
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 30]))
    arcsec = np.pi / 180 / 3600
    amp = np.array([8.0, 12.0, 10.0, 15.0, 15.0, 20.0]) * arcsec * scale
    phase = rng.uniform(0.0, 2 * np.pi, 6)
    compliance = tuple(float(c) * scale for c in (0.0, 4e-7, 6e-7, 1e-6, 1e-6, 1e-6))
    return JointErrors(compliance=compliance, masses=((2, 60.0), (4, 25.0)), payload_kg=5.0,
                       cyclic=tuple((float(a * np.cos(p)), float(a * np.sin(p))) for a, p in zip(amp, phase)))


def scara_joint_errors(seed: int = 1, scale: float = 1.0) -> JointErrors:
    """The first harmonics of a SCARA's revolute joints 1, 2 and 4 (harmonic drives of a 0.8 m
    arm: 25″, 20″ and 15″ [?] — amplitudes of the six-axis arm's order, chosen to show clearly over
    the reference cell's 5 µm repeatability), phases from ``seed``; the quill (joint 3) none.
    ``scale`` multiplies every amplitude."""
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 31]))
    arcsec = np.pi / 180 / 3600
    amp = np.array([25.0, 20.0, 0.0, 15.0]) * arcsec * scale
    phase = rng.uniform(0.0, 2 * np.pi, 4)
    return JointErrors(cyclic=tuple((float(a * np.cos(p)), float(a * np.sin(p))) for a, p in zip(amp, phase)))
