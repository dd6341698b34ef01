"""The validated sections of a cell configuration: one frozen dataclass per TOML table
(``[devices]``, ``[plan]``, ``[identification]``, ``[correction]``, ``[recheck]``, ``[fleet]``,
``[verification]``, ``[cell]``'s traceability, ``[warmup]``, ``[conformance]``, ``[[tool]]``).
:mod:`station.cell.config.cell_config` builds them from the checked file and re-exports them;
mm and rad inside.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from station.core.kinematics.transforms import pose_to_matrix
from station.core.measurement.repeatability import with_repeatability
from station.core.terms.error_model import GravityModel
from station.core.units import ARCSEC

__all__ = ["DeviceConfig", "PlanConfig", "IdentificationConfig", "CorrectionConfig", "RecheckConfig", "FleetConfig",
           "VerificationConfig", "CellIdentity", "WarmupConfig", "ConformanceConfig", "ToolConfig",
           "ObstacleConfig"]


@dataclass(frozen=True)
class DeviceConfig:
    probe_head: str
    baudrate: int  # checked against the dialect's unit; the factory default when the file gives none
    probe_timeout_s: float
    controller_host: str
    controller_port: int
    device_id: int
    word_order: str
    controller_timeout_s: float
    motion_timeout_s: float
    probe_protocol: str = "keyence-dl-rs1a"
    probe_bytesize: int = 8
    probe_parity: str = "none"
    controller_register_base: int = 0
    probe_refresh_s: float | None = None  # None: the dialect's
    controller_link_timeout_s: float = 1.0


@dataclass(frozen=True)
class PlanConfig:
    elbows: tuple[int, ...]
    approach_deg: float
    approach_mm: float
    clearance_mm: float
    speed: float
    settle_s: float
    samples: int
    max_spread_um: float
    both_directions: bool
    verification_every: int  # every k-th (point, elbow) is held out for verification
    verification_cycles: int
    select: int  # > 0: keep this many identification steps, chosen by D-optimality
    repeats: int  # visits per identification target (each with a slightly varied approach)
    recenter_attempts: int
    recenter_margin_mm: float
    max_residual_um: float
    remeasure_attempts: int = 1  # re-touches when a redundant head's probes disagree
    #: how far a measuring point may lie from where [robot].setup puts it [mm] ([robot] setup_uncertainty_mm)
    setup_uncertainty_mm: float = 5.0
    locate_steps: int = 3  # search steps per face normal when locating the body (station/cell/plan/locating.py)
    collision_margin_mm: float = 2.0  # least clearance of every pose and path (station/cell/plan/collision.py)


@dataclass(frozen=True)
class IdentificationConfig:
    objective: str
    sigma_position_um: float
    sigma_angle_arcsec: float
    prefer: tuple[str, ...]
    fix: tuple[str, ...]
    exclude: tuple[str, ...]
    model: str = "geometric"  # error terms beyond geometry: "geometric", "auto" or families joined by "+"
    # the robot file's [gravity] (a GravityModel; None: the lumped torques) and [gears] ratios (None: 1),
    # read only when the model has terms
    gravity: GravityModel | None = None
    gear_ratios: tuple[float, ...] | None = None
    #: the robot file's ISO 9283 pose repeatability RP [mm] (None: the file states none)
    repeatability_mm: float | None = None

    @property
    def terms(self) -> tuple[str, ...]:
        """``model`` as names (``("geometric",)``, ``("auto",)``, ``("compliance", "cyclic")``, …)."""
        return tuple(n.strip() for n in self.model.split("+") if n.strip()) or ("geometric",)

    def pose_sigma(self) -> np.ndarray:
        """σ of the six pose residual rows (x, y, z [mm], rx, ry, rz [rad]): the measurement's, with
        the robot's repeatability (``repeatability_mm``) in quadrature on x, y, z: the fit's
        weights, the σ it reports and the plan's stopping rule all see the robot that is measured."""
        s, a = self.sigma_position_um * 1e-3, self.sigma_angle_arcsec * ARCSEC
        return with_repeatability(np.array([s, s, s, a, a, a]), self.repeatability_mm)


@dataclass(frozen=True)
class CorrectionConfig:
    """[correction]: x/y/z_mm (start, stop, step) [mm], all or none (designed); region (lo, hi) per axis or None."""
    x_mm: tuple[float, float, float] | None
    y_mm: tuple[float, float, float] | None
    z_mm: tuple[float, float, float] | None
    yaw_step_deg: float | None
    max_interpolation_um: float
    region: tuple[tuple[float, float], tuple[float, float], tuple[float, float]] | None = None

    @property
    def explicit(self) -> bool:  # the grid is given (x_mm, y_mm, z_mm), not designed
        return self.x_mm is not None and self.y_mm is not None and self.z_mm is not None


@dataclass(frozen=True)
class RecheckConfig:
    """``station recheck``: how many poses, and the tolerances (0: derived from the baseline)."""

    poses: int = 10
    tolerance_um: float = 0.0  # RMS position drift accepted; 0: 3× the baseline's accuracy
    offset_tolerance_arcsec: float = 0.0  # 0: tolerance_um over a 500 mm lever
    length_tolerance_um: float = 0.0  # 0: tolerance_um
    repeat_tolerance_um: float = 0.0  # first pose vs its repeat at the end; 0: tolerance_um


@dataclass(frozen=True)
class FleetConfig:
    """``[fleet]``: where finished runs are published (None: nowhere, unless STATION_FLEET_URL),
    this station's name there, and the days between rechecks the fleet's due dates use."""

    url: str | None = None
    station: str | None = None
    recheck_interval_days: int = 30


@dataclass(frozen=True)
class VerificationConfig:
    """``[verification]``: the accuracy specification the report judges the held-out poses by
    after correction (ISO 9283 AP and RP per pose [µm]; None: not judged) and the test conditions
    it states (air temperature [°C], mass on the flange [kg]; None: not recorded)."""

    max_ap_um: float | None = None
    max_rp_um: float | None = None
    temperature_c: float | None = None
    load_kg: float | None = None


@dataclass(frozen=True)
class CellIdentity:
    """``[cell]``'s traceability: the robot's serial number, the controller (make, model, serial)
    and the operator, as the report names them ("": not given)."""

    robot_serial: str = ""
    controller: str = ""
    operator: str = ""


@dataclass(frozen=True)
class WarmupConfig:
    """A warm-up before measuring: cycles of a motion program over the workspace, each ended by
    a measurement of one reference pose, until its extrapolated remaining drift is below
    ``converged_um`` (``until = "converged"``) or for ``minutes`` (``until = "time"``)."""

    until: str = "converged"
    minutes: float = 20.0
    max_cycles: int = 200
    converged_um: float = 2.0
    program_poses: int = 8


@dataclass(frozen=True, eq=False)
class ConformanceConfig:
    """``station conformance``: where the robot is parked and how far the kit may move it.
    ``park_joints`` [rad | mm]; the park zone is ``park_joints ± test_move_joint`` per joint."""

    park_joints: np.ndarray
    test_move_joint: np.ndarray  # test_move in joint units (rad for revolute, mm for prismatic)
    move_speed: float
    position_tolerance_joint: np.ndarray  # in joint units

    def zone(self) -> np.ndarray:
        """The park zone ``(n_joints, 2)`` [lower, upper] (rad | mm)."""
        return np.stack([self.park_joints - self.test_move_joint, self.park_joints + self.test_move_joint], axis=1)


@dataclass(frozen=True, eq=False)
class ToolConfig:
    """A tool that replaces the probe head after the calibration (``[[tool]]``).

    ``tcp``: ``(6,)`` x, y, z [mm], roll, pitch, yaw [rad] of the tool centre point in the flange
    (tool-mount) frame, from the tool's own measurement (the file holds degrees).
    ``correction``: the grid its table is built on: ``[correction]`` with the tool's own
    ``x_mm`` / ``y_mm`` / ``z_mm`` where it gives them (a tool works at other heights than the head).
    """

    name: str
    tcp: np.ndarray
    correction: CorrectionConfig

    @property
    def tcp_matrix(self) -> np.ndarray:
        """``(4, 4)`` flange ← TCP [mm]."""
        return pose_to_matrix(self.tcp)


@dataclass(frozen=True)
class ObstacleConfig:
    """A fixed obstacle (``[[obstacle]]``, issue 40): ``shape`` "box" (``size`` its edges) or
    "cylinder" (``size`` = radius, height; axis along its own z), centred at ``pose`` (4, 4) in
    ``frame`` ("body" or "base"); mm."""

    name: str
    shape: str
    frame: str
    pose: np.ndarray
    size: tuple[float, ...]
