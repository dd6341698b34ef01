"""Drift of the simulated robot between and during runs (issue 13).

* :class:`ThermalModel` - link lengths and joint offsets change along an exponential warm-up
  curve, ``Δp(t) = amplitude · (1 − exp(−t / τ))``, with ``t`` the robot's simulated motion
  time (every commanded move adds its duration from the controller's motion model, whatever
  the time scale), so a test never depends on the wall clock. A cold robot starts at ``t = 0``.
* :func:`step_change` - a step between runs: a re-mastered axis (a joint-offset step) or a
  bumped tool (a shift of the head). It is applied to the cell's true parameters, so the
  oracle of a calibration made after the step includes it.

Units: mm and rad inside; the constructors take µm, arc seconds and degrees as people state them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from station.core.kinematics.model import RobotModel
from station.core.units import ARCSEC

__all__ = ["ThermalModel", "step_change", "joint_offset_index", "arm_length_indices", "motion_seconds"]

#: joint speeds of the motion model when the controller does not say (rad/s, mm/s): the
#: controller simulator's defaults at the station's default speed fraction 0.5
DEFAULT_MAX_SPEED = {"revolute": 2.5, "prismatic": 1000.0}
DEFAULT_SPEED = 0.5


def joint_offset_index(model: RobotModel, joint: int) -> int:
    """Index of joint ``joint``'s (from 0) offset parameter: the yaw of its transform for a
    revolute joint, z for a prismatic one."""
    t = model.joint_transforms[joint]
    return 6 * t + (5 if model.joint_types[joint] == "revolute" else 2)


def arm_length_indices(model: RobotModel) -> list[int]:
    """Indices of the arm lengths: the largest in-plane translation (x or y) of each joint
    transform after the first whose nominal value is not zero (SR 800: A2.x, A3.x)."""
    out = []
    for t in model.joint_transforms[1:]:
        xy = np.abs(np.asarray(model.nominal[6 * t: 6 * t + 2], dtype=float))
        if xy.max() > 1.0:
            out.append(6 * t + int(np.argmax(xy)))
    return out


def motion_seconds(model: RobotModel, dq: np.ndarray, speed: float = DEFAULT_SPEED) -> float:
    """Duration of a move by ``dq`` in the controller simulator's motion model (time scale 1)."""
    vmax = np.array([DEFAULT_MAX_SPEED[k] for k in model.joint_types]) * speed
    return float(np.max(np.abs(np.asarray(dq, dtype=float)) / vmax)) + 0.05


@dataclass(frozen=True)
class ThermalModel:
    """``amplitude`` (n_params,): parameter change at steady state (warm); ``tau_s``: time
    constant in seconds of motion."""

    amplitude: np.ndarray
    tau_s: float

    @classmethod
    def for_model(cls, model: RobotModel, length_um: float = 0.0, offset_arcsec: float = 0.0,
                  tau_s: float = 600.0) -> ThermalModel:
        """Every arm length grows by ``length_um`` (scaled by its length over the longest arm, as
        expansion goes) and every revolute joint offset but the last drifts by ``offset_arcsec``
        (alternating sign: the gears of neighbouring axes warm differently)."""
        amp = np.zeros(model.n_params)
        arms = arm_length_indices(model)
        if arms:
            lengths = np.abs(np.asarray(model.nominal)[arms])
            amp[arms] = length_um * 1e-3 * lengths / lengths.max()
        rev = [j for j, k in enumerate(model.joint_types) if k == "revolute"][:-1]
        for n, j in enumerate(rev):
            amp[joint_offset_index(model, j)] = offset_arcsec * ARCSEC * (1 if n % 2 == 0 else -1)
        if tau_s <= 0:
            raise ValueError("the thermal time constant must be > 0")
        return cls(amp, float(tau_s))

    @property
    def active(self) -> bool:
        return bool(np.any(self.amplitude != 0))

    def delta(self, t_s: float) -> np.ndarray:
        """Parameter change (n_params,) after ``t_s`` seconds of motion from cold."""
        return self.amplitude * (1.0 - np.exp(-max(float(t_s), 0.0) / self.tau_s))


def step_change(model: RobotModel, joint: int = 0, offset_deg: float = 0.0,
                tool_um: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> np.ndarray:
    """Parameter change (n_params,) of a step: joint ``joint`` (from 1; 0: none) re-mastered by
    ``offset_deg`` (revolute joints), the head (tool) shifted by ``tool_um`` in x, y, z."""
    d = np.zeros(model.n_params)
    if joint:
        j = joint - 1
        if not 0 <= j < model.n_joints:
            raise ValueError(f"step joint {joint}: the robot has {model.n_joints} joints")
        if model.joint_types[j] != "revolute":
            raise ValueError(f"step joint {joint} is prismatic: a step of its offset is a tool shift in z (step_tool_um)")
        d[joint_offset_index(model, j)] = np.deg2rad(offset_deg)
    k = model.n_params - 6  # the head transform K is the last
    d[k:k + 3] = np.asarray(tool_um, dtype=float) * 1e-3
    return d
