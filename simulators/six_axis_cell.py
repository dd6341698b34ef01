"""The built-in simulated six-axis cell (issue 9): an ABB IRB 2600-12/1.65 (``--robot irb2600``)
with the probe head on its flange, in front of a calibration body it reaches with the head in
several orientations and configurations.

* :data:`SIX_AXIS_SETUP` - the nominal pose of the robot base in the body frame KKS: the robot
  stands 1000 mm behind the body's origin and 450 mm below the plate, so the cube corners lie
  750 … 1250 mm in front of axis 1 at the height of the shoulder, where the arm reaches them
  with the head pointing down and tilted, the wrist flipped or not.
* :data:`SIX_AXIS_CUBES` - six cubes spread over 500 × 800 mm and 0 … 250 mm high.
* :func:`six_axis_truth` - the true robot: errors of the brief's magnitudes in *every*
  parameter (σ 0.2 mm for every length, 0.02° for every angle, of every joint transform and the
  head K: about 1.4 mm RMS at the tool over the workspace), the set-up placed to σ 0.5 mm and
  0.03° (over a 1 m lever the set-up weighs as much as the robot's errors; the probes' ±5 mm
  stroke and the cube's 40 mm edge must still catch the first touch), repeatability and backlash
  per joint (mm at each joint's lever, so the wrist's are larger in angle).
* :func:`start_six_axis_cell` - the controller and probe-head simulators on that cell (the same
  transports as the SCARA cell); :func:`six_axis_config_text` - the cell configuration the
  station reads, as :mod:`simulators.reference_cell` writes it for the SCARA.

Units mm and rad inside; the configuration text in mm and degrees.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from simulators import SimulatedCellServers, start_simulated_cell
from simulators.cell import CalibrationBody, CellTruth, CubeSpec, SimulatedCell
from simulators.reference_cell import CellEndpoints, body_and_devices_toml
from station.core.kinematics.model import RobotModel
from station.io.robot.files import load_robot

__all__ = ["SIX_AXIS_ROBOT", "SIX_AXIS_SETUP", "SIX_AXIS_CUBES", "SIX_AXIS_HOME", "SIX_AXIS_LIMITS_DEG",
           "six_axis_truth", "six_axis_body", "six_axis_cell", "start_six_axis_cell", "six_axis_config_text"]

#: the built-in robot file of the cell
SIX_AXIS_ROBOT = "irb2600"
#: nominal pose of the robot base in KKS (x, y, z [mm], roll, pitch, yaw [rad])
SIX_AXIS_SETUP = np.array([-1000.0, 0.0, -450.0, 0.0, 0.0, 0.0])
#: cubes: centre (x, y) [mm] in KKS, pillar height [mm], yaw [rad]
SIX_AXIS_CUBES = (
    CubeSpec(200.0, -350.0, 0.0, np.deg2rad(10.0)),
    CubeSpec(150.0, 50.0, 120.0, np.deg2rad(-20.0)),
    CubeSpec(-100.0, -150.0, 250.0, np.deg2rad(30.0)),
    CubeSpec(250.0, 350.0, 60.0, np.deg2rad(5.0)),
    CubeSpec(-200.0, 300.0, 180.0, np.deg2rad(-15.0)),
    CubeSpec(-250.0, -400.0, 0.0, np.deg2rad(45.0)),
)
#: joints at start (rad): the data sheet's calibration position with the wrist bent
SIX_AXIS_HOME = np.deg2rad([0.0, 0.0, 0.0, 0.0, 30.0, 0.0])
#: the cell's soft limits (deg), a few degrees inside the robot's working ranges
SIX_AXIS_LIMITS_DEG = ((-175.0, 175.0), (-90.0, 150.0), (-175.0, 70.0), (-395.0, 395.0), (-115.0, 115.0),
                       (-395.0, 395.0))
#: lever [mm] at which each joint's repeatability and backlash are given (arm, forearm, wrist)
LEVERS_MM = np.array([1100.0, 1000.0, 900.0, 250.0, 250.0, 160.0])


def six_axis_truth(seed: int = 1, model: RobotModel | None = None, length_sigma_mm: float = 0.2,
                   angle_sigma_deg: float = 0.02, setup_sigma_mm: float = 0.5,
                   setup_yaw_sigma_deg: float = 0.03, setup_tilt_sigma_deg: float = 0.02,
                   repeatability_mm: float = 0.01, backlash_mm: float = 0.1,
                   encoder_resolution: float = 1e-6) -> CellTruth:
    """The seeded true robot: nominal + errors in every length (σ ``length_sigma_mm``) and every
    angle (σ ``angle_sigma_deg``) of A1 … A6 and K; the set-up R = :data:`SIX_AXIS_SETUP` + σ
    ``setup_sigma_mm`` (x, y, z), ``setup_yaw_sigma_deg``, ``setup_tilt_sigma_deg``. Joint ``j``
    repeats to ``repeatability_mm`` and has a reversal error of ``backlash_mm`` at its lever
    :data:`LEVERS_MM` [j]."""
    model = load_robot(SIX_AXIS_ROBOT) if model is None else model
    model = model.with_setup(SIX_AXIS_SETUP)
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 2600]))
    n_t = model.n_params // 6
    err = np.zeros((n_t, 6))
    err[1:, :3] = rng.normal(0.0, length_sigma_mm, (n_t - 1, 3))
    err[1:, 3:] = rng.normal(0.0, np.deg2rad(angle_sigma_deg), (n_t - 1, 3))
    err[0, :3] = rng.normal(0.0, setup_sigma_mm, 3)
    err[0, 3:5] = rng.normal(0.0, np.deg2rad(setup_tilt_sigma_deg), 2)
    err[0, 5] = rng.normal(0.0, np.deg2rad(setup_yaw_sigma_deg))
    g = model.n_joints
    lever = LEVERS_MM[:g] if g <= len(LEVERS_MM) else np.full(g, 500.0)
    rev = np.array([t == "revolute" for t in model.joint_types])
    rep = np.where(rev, repeatability_mm / lever, repeatability_mm)
    bl = np.where(rev, backlash_mm / lever, backlash_mm)
    return CellTruth(model, model.nominal + err.ravel(), rep, bl, np.full(g, float(encoder_resolution)), int(seed))


def six_axis_body(seed: int = 1) -> CalibrationBody:
    """The calibration body: :data:`SIX_AXIS_CUBES`, 40 mm cubes, all four top corners."""
    return CalibrationBody.generate(cubes=SIX_AXIS_CUBES, cube_edge_mm=40.0, seed=seed)


def six_axis_cell(seed: int = 1, **truth_kwargs: Any) -> SimulatedCell:
    """The simulated six-axis cell (truth, body, head), the robot at :data:`SIX_AXIS_HOME`."""
    return SimulatedCell(truth=six_axis_truth(seed, **truth_kwargs), body=six_axis_body(seed), seed=seed,
                         initial_joints=SIX_AXIS_HOME)


def start_six_axis_cell(seed: int = 1, time_scale: float = 0.0, **kwargs: Any) -> SimulatedCellServers:
    """Start the controller and probe-head simulators on :func:`six_axis_cell` (the controller's
    soft limits are the robot's working ranges). ``kwargs`` go to
    :func:`simulators.start_simulated_cell` (word order, port …)."""
    return start_simulated_cell(seed=seed, time_scale=time_scale, cell=six_axis_cell(seed), **kwargs)




def six_axis_config_text(servers: CellEndpoints, seed: int) -> str:
    """The cell configuration of the simulated six-axis cell (its CMM body report, endpoints)."""
    setup = [*SIX_AXIS_SETUP[:3], *np.degrees(SIX_AXIS_SETUP[3:])]
    limits = ", ".join(f"[{lo!r}, {hi!r}]" for lo, hi in SIX_AXIS_LIMITS_DEG)
    return f"""# Built-in simulated six-axis cell (seed {seed}): ABB IRB 2600-12/1.65 with the probe head.
[cell]
name = "simulated six-axis cell"

[robot]
model = "{SIX_AXIS_ROBOT}"
setup = [{", ".join(repr(float(v)) for v in setup)}]

[limits]
joints = [{limits}]

{body_and_devices_toml(servers)}
[plan]
settle_s = 0.0
repeats = 2
verification_cycles = 3
verification_every = 4
# every joint arrives from below by this much: 0.1 deg keeps the head within ~2 mm of the
# corner on the last move of a 1.6 m arm
approach_deg = 0.1
clearance_mm = 15.0
# the most informative identification poses of the candidates (greedy D-optimal)
select = 120

[identification]
# the simulated arm repeats to ~10 µm (joint noise at the levers) on top of 0.5 µm probes
sigma_position_um = 15.0
sigma_angle_arcsec = 15.0

[simulation]
seed = {seed}
"""
