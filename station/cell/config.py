"""Cell configuration (TOML): robot, calibration body, probe head, devices, limits, plan,
identification and correction settings. ``station init`` writes :data:`TEMPLATE`.

Validation names the key and the fix. Inside, everything is mm and rad; the file holds degrees
where people write angles (keys ending in ``_deg``), µm and arc seconds for uncertainties.

Every key is checked before anything moves, in two stages:

1. The file's schema (:class:`_CellFile`, pydantic v2 in strict mode): types, bounds and unknown
   keys. Every numeric key has bounds (the template states them); an integer is never a bool or a
   float, a float is finite. The bounds are the one source: the error messages and the test that
   reads the template's comments take them from the schema.
2. What needs the robot: the robot file, ``[limits]`` (one finite, ordered pair per joint, inside
   the robot's limits), the parameter names of ``prefer``/``fix``/``exclude``, and the correction
   grid (whole number of steps, the controller's capacity for this robot's joints).

Every failure is a :class:`ConfigError` (exit code 2); a malformed file never gives a traceback.
"""

from __future__ import annotations

import math
import re
import reprlib
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Literal

import annotated_types
import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator
from pydantic.fields import FieldInfo

from station.core.model import RobotModel
from station.core.table_grid import GridSpec
from station.core.transforms import pose_to_matrix
from station.core.units import ARCSEC, DEG, UM
from station.errors import ConfigError
from station.io.robot_files import load_robot, read_user_text

#: a configuration file larger than this is refused before it is read (a real one is a few kB;
#: a body of 5 000 points is ~0.5 MB)
MAX_CONFIG_BYTES = 4 * 1024 * 1024


@dataclass(frozen=True)
class DeviceConfig:
    probe_head: str
    baudrate: int
    probe_timeout_s: float
    controller_host: str
    controller_port: int
    device_id: int
    word_order: str
    controller_timeout_s: float
    motion_timeout_s: float


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


@dataclass(frozen=True)
class IdentificationConfig:
    objective: str
    sigma_position_um: float
    sigma_angle_arcsec: float
    prefer: tuple[str, ...]
    fix: tuple[str, ...]
    exclude: tuple[str, ...]

    def pose_sigma(self) -> np.ndarray:
        """σ of the six pose residual rows (x, y, z [mm], rx, ry, rz [rad])."""
        s, a = self.sigma_position_um * 1e-3, self.sigma_angle_arcsec * ARCSEC
        return np.array([s, s, s, a, a, a])


@dataclass(frozen=True)
class CorrectionConfig:
    x_mm: tuple[float, float, float]
    y_mm: tuple[float, float, float]
    z_mm: tuple[float, float, float]
    yaw_step_deg: float
    max_interpolation_um: float


@dataclass(frozen=True)
class RecheckConfig:
    """``station recheck``: how many poses, and the tolerances (0: derived from the baseline)."""

    poses: int = 10
    tolerance_um: float = 0.0  # RMS position drift accepted; 0: 3× the baseline's accuracy
    offset_tolerance_arcsec: float = 0.0  # 0: tolerance_um over a 500 mm lever
    length_tolerance_um: float = 0.0  # 0: tolerance_um
    repeat_tolerance_um: float = 0.0  # first pose vs its repeat at the end; 0: tolerance_um


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


@dataclass(frozen=True, eq=False)  # identity: it holds arrays, and caches key on it
class CellConfig:
    """A validated cell configuration. ``body_points``: ``(n, 4, 4)`` KKS←MPKS nominal
    (CMM) poses, ``point_ids`` their names. ``model``: robot with the configured nominal set-up."""

    name: str
    model: RobotModel
    soft_limits: np.ndarray
    point_ids: tuple[str, ...]
    body_points: np.ndarray
    cube_edge_mm: float
    devices: DeviceConfig
    plan: PlanConfig
    identification: IdentificationConfig
    correction: CorrectionConfig
    source_text: str = field(repr=False, default="")
    simulated_seed: int | None = None
    recheck: RecheckConfig = RecheckConfig()
    warmup: WarmupConfig | None = None  # None: no warm-up ([warmup] absent or enabled = false)
    conformance: ConformanceConfig | None = None  # None: no [conformance].park_joints
    # --- one field per owner; each is filled in parse_config on its own line below ---
    head: Any = None  # ProbeHeadGeometry of the [head] file (None: not yet given)
    head_in_flange: np.ndarray | None = None  # (4,4) MKKS in the flange frame, from the head's CMM report
    body_sigma: np.ndarray | None = None  # (n_points, 2) σ of each body point: position [mm], angle [rad]
    tools: tuple[ToolConfig, ...] = ()  # the tools that replace the head ([[tool]])
    simulation: Any = None  # the validated [simulation] table (what --simulated CONFIG simulates)
    source: str = ""  # the file it was read from (or a label such as "<simulated cell>")


# --------------------------------------------------------------------------------------------
# stage 1: the file's schema (types, bounds, unknown keys)
# --------------------------------------------------------------------------------------------

#: positions (set-up, body points, grid) are within ±10 m of the body frame
MAX_MM = 10_000.0
_NO_CONTROL = r"^[^\x00-\x1f\x7f]*$"  # no control characters (NUL, newline, escape, ...)

Text = Annotated[str, Field(min_length=1, max_length=256, pattern=_NO_CONTROL)]
PathText = Annotated[str, Field(min_length=1, max_length=1024, pattern=_NO_CONTROL)]
PointId = Annotated[str, Field(min_length=1, max_length=64, pattern=_NO_CONTROL)]
ParamName = Annotated[str, Field(min_length=1, max_length=64, pattern=_NO_CONTROL)]
Mm = Annotated[float, Field(ge=-MAX_MM, le=MAX_MM)]
Deg = Annotated[float, Field(ge=-360.0, le=360.0)]
# TOML gives lists; the tuple fixes the length and the bounds of each element (elements stay strict)
Pose = Annotated[tuple[Mm, Mm, Mm, Deg, Deg, Deg], Field(strict=False)]
GridStep = Annotated[float, Field(ge=1.0, le=MAX_MM)]
GridAxis = Annotated[tuple[Mm, Mm, GridStep], Field(strict=False)]

_POSE_WHAT = "x, y, z [mm] within ±10000, roll, pitch, yaw [deg] within ±360"


def _num(default: Any, *, what: str, ge: float | None = None, gt: float | None = None,
         le: float | None = None) -> Any:
    """A bounded number; ``what`` says what it is (it ends up in the error message)."""
    return Field(default, ge=ge, gt=gt, le=le, description=what)


def _absent(**kw: Any) -> Any:
    """No default: the key may be left out (``None`` then means "not given")."""
    return Field(None, **kw)


class _Section(BaseModel):
    # strict: an int is never a bool or a float, a float never a string; finite only; unknown
    # keys are refused so that a typo never silently falls back to a default
    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False, frozen=True)


class _Cell(_Section):
    name: Text = Field("calibration cell", description="the cell's name in reports, 1 … 256 characters")


class _Robot(_Section):
    model: PathText = Field(description='a built-in robot ("sr800") or a robot file (docs/robot-file.md)')
    setup: Pose = Field((0.0,) * 6, description=f"nominal pose of the robot base in the body frame: {_POSE_WHAT}")


class _Limits(_Section):
    # checked against the robot in stage 2 (one [lower, upper] per joint)
    joints: list[Any] = _absent(max_length=64, description="[lower, upper] per joint (deg | mm)")


class _Point(_Section):
    id: PointId = Field(description="the point's name from the CMM report, 1 … 64 characters")
    pose: Pose = Field(description=f"pose of the corner frame in the body frame: {_POSE_WHAT}")
    # the CMM's uncertainty of this point (absent: [body] default_sigma_*)
    sigma_position_um: float | None = _absent(ge=0.0, le=1000.0, description="σ of the point's position [µm]")
    sigma_angle_arcsec: float | None = _absent(ge=0.0, le=3600.0, description="σ of the point's angles [arc seconds]")


class _Body(_Section):
    cube_edge_mm: float = _num(40.0, gt=0.0, le=1000.0, what="edge of the body's cubes [mm]")
    points: Annotated[list[_Point], Field(min_length=3, max_length=5000)] | None = _absent(
        description='3 … 5000 measuring points from the CMM report: { id = "C1.a", pose = [x, y, z, '
                    'roll, pitch, yaw] } in mm and deg')
    file: PathText | None = _absent(
        description='the body\'s CMM report, a CSV relative to this file (docs/data-files.md), e.g. "body.csv"')
    default_sigma_position_um: float = _num(0.0, ge=0.0, le=1000.0,
                                            what="σ of a point's position where the report gives none [µm], 0: exact")
    default_sigma_angle_arcsec: float = _num(0.0, ge=0.0, le=3600.0,
                                             what="σ of a point's angles where the report gives none [arc seconds], 0: exact")

    @field_validator("points")
    @classmethod
    def _unique_ids(cls, pts: list[_Point] | None) -> list[_Point] | None:
        seen: set[str] = set()
        for p in pts or ():
            if p.id in seen:
                raise ValueError(f"point id {p.id!r} appears twice; ids must be unique")
            seen.add(p.id)
        return pts

    @model_validator(mode="after")
    def _points_or_file(self) -> "_Body":
        if (self.points is None) == (self.file is None):
            raise ValueError('give the measuring points either from the CMM report, file = "body.csv", or inline, '
                             'points = [ … ] (exactly one of the two)')
        return self


_CONTROLLER = re.compile(r"^([^\s:][^\s]*):([0-9]{1,5})$")


class _Devices(_Section):
    probe_head: PathText = Field("/dev/ttyUSB0", description="serial device, or socket://host:port, rfc2217://host:port")
    baudrate: Literal[9600, 19200, 38400, 57600, 115200] = Field(
        38400, description="the rate set on the probe unit: 9600, 19200, 38400, 57600 or 115200")
    probe_timeout_s: float = _num(0.5, ge=0.01, le=60.0, what="seconds to wait for a probe reply")
    controller: str = Field("127.0.0.1:502", max_length=300,
                            description='Modbus TCP host:port, e.g. "192.168.0.10:502" (port 1 … 65535)')
    device_id: int = _num(1, ge=0, le=255, what="Modbus unit id of the controller")
    word_order: Literal["big", "little"] = Field(
        "big", description='"big" or "little" (how the controller orders 32-bit words)')
    controller_timeout_s: float = _num(1.0, ge=0.01, le=60.0, what="seconds to wait for a controller reply")
    motion_timeout_s: float = _num(60.0, ge=1.0, le=600.0, what="seconds one motion may take")

    @field_validator("controller")
    @classmethod
    def _host_port(cls, v: str) -> str:
        m = _CONTROLLER.match(v)
        if not m or not 1 <= int(m.group(2)) <= 65535:
            raise ValueError("write it as host:port with a port 1 … 65535")
        return v


class _Plan(_Section):
    elbows: list[Literal[1, -1]] = Field(
        [1, -1], description="[1, -1] (both elbows, the correction table's order) or [1]")
    approach_deg: float = _num(0.5, gt=0.0, le=10.0, what="approach from below per joint [deg]")
    approach_mm: float = _num(1.0, gt=0.0, le=50.0, what="approach of a prismatic joint [mm]")
    clearance_mm: float = _num(20.0, gt=0.0, le=500.0, what="retract height above a measuring point [mm]")
    speed: float = _num(0.5, gt=0.0, le=1.0, what="fraction of the robot's maximum speed")
    settle_s: float = _num(0.2, ge=0.0, le=30.0, what="wait after a motion before reading the probes [s]")
    samples: int = _num(4, ge=1, le=100, what="probe snapshots averaged per reading")
    max_spread_um: float = _num(10.0, gt=0.0, le=1000.0, what="largest spread of a reading's snapshots [µm]")
    both_directions: bool = Field(False, description="true or false")
    verification_every: int = _num(4, ge=2, le=100, what="every k-th (point, elbow) is held out for verification")
    verification_cycles: int = _num(3, ge=1, le=30, what="ISO 9283 repetitions per verification pose")
    select: int = _num(0, ge=0, le=5000, what="0: every identification step; N: the N most informative")
    repeats: int = _num(2, ge=1, le=20, what="visits per identification pose")
    recenter_attempts: int = _num(2, ge=0, le=10, what="re-centring attempts near a probe's stroke end")
    recenter_margin_mm: float = _num(1.5, ge=0.0, le=4.0, what="distance from the stroke end that triggers a re-centring [mm]")
    max_residual_um: float = _num(10.0, gt=0.0, le=1000.0, what="plane residual above which a reading is not valid [µm]")
    remeasure_attempts: int = _num(1, ge=0, le=5, what="re-touches when the probes of a redundant head disagree")

    @field_validator("elbows")
    @classmethod
    def _elbow_order(cls, v: list[int]) -> list[int]:
        if tuple(v) not in ((1, -1), (1,)):
            raise ValueError("the correction table holds elbow +1, then elbow -1: write [1, -1] or [1]")
        return v


class _Identification(_Section):
    objective: Literal["pose", "distance"] = Field(
        "pose", description='"pose" (robot + set-up + head) or "distance" (robot only)')
    sigma_position_um: float = _num(15.0, ge=0.01, le=1000.0, what="σ of a measured position [µm]")
    sigma_angle_arcsec: float = _num(20.0, ge=0.01, le=3600.0, what="σ of a measured angle [arc seconds]")
    prefer: list[ParamName] = _absent(max_length=500, description='parameter names such as "K.x"')
    fix: list[ParamName] = Field([], max_length=500, description='parameter names such as "K.x"')
    exclude: list[ParamName] = Field([], max_length=500, description='parameter names such as "K.x"')


class _Correction(_Section):
    x_mm: GridAxis = Field((250.0, 650.0, 40.0), description="[start, stop, step] in mm, step 1 … 10000")
    y_mm: GridAxis = Field((-350.0, 350.0, 50.0), description="[start, stop, step] in mm, step 1 … 10000")
    z_mm: GridAxis = Field((250.0, 450.0, 200.0), description="[start, stop, step] in mm, step 1 … 10000")
    yaw_step_deg: float = _num(30.0, ge=1.0, le=180.0, what="yaw step of the table [deg], a divisor of 360")
    max_interpolation_um: float = _num(15.0, gt=0.0, le=1000.0, what="largest interpolation bound accepted [µm]")


class _Simulation(_Section):
    """``[simulation]``: what ``--simulated CONFIG`` and ``python -m simulators --config`` simulate.
    The defaults are the built-in cell's (``simulators/from_config.py``, :class:`SimulationPhysics`
    holds the same numbers): a realistic SCARA of the 800 mm class and a CMM-measured body."""

    seed: int = _num(None, ge=0, le=2**32 - 1, what="seed of the simulated cell")
    # the true errors of the simulated robot (seeded; σ of a normal distribution each)
    length_sigma_um: float = _num(40.0, ge=0.0, le=5000.0,
                                  what="σ of the true errors of the robot's lengths (arms, head) [µm]")
    angle_sigma_arcsec: float = _num(150.0, ge=0.0, le=36000.0,
                                     what="σ of the true errors of the robot's angles (offsets, axis tilts) [arc seconds]")
    setup_sigma_mm: float = _num(1.5, ge=0.0, le=100.0,
                                 what="σ of the true set-up against the nominal [robot].setup, x, y, z [mm]")
    setup_yaw_sigma_deg: float = _num(0.2, ge=0.0, le=10.0, what="σ of the true set-up's yaw [deg]")
    setup_tilt_sigma_deg: float = _num(0.03, ge=0.0, le=5.0, what="σ of the true set-up's roll and pitch [deg]")
    # the physics of the simulated robot, probe head and body
    repeatability_um: float = _num(5.0, ge=0.0, le=1000.0,
                                   what="σ of a joint's position per move [µm] (revolute: at lever_mm)")
    backlash_um: float = _num(100.0, ge=0.0, le=5000.0,
                              what="reversal error of a revolute joint at lever_mm [µm]")
    prismatic_backlash_um: float = _num(20.0, ge=0.0, le=5000.0, what="reversal error of a prismatic joint [µm]")
    lever_mm: float = _num(450.0, ge=10.0, le=5000.0,
                           what="lever at which a revolute joint's repeatability and backlash are stated [mm]")
    probe_noise_um: float = _num(0.5, ge=0.0, le=100.0, what="σ of a probe reading's noise [µm]")
    body_position_sigma_um: float = _num(2.0, ge=0.0, le=1000.0,
                                         what="σ of a body point's true position against its CMM report [µm] "
                                              "(a point's own σ in the body file takes precedence)")
    body_angle_sigma_arcsec: float = _num(3.0, ge=0.0, le=3600.0,
                                          what="σ of a body point's true angles against its CMM report [arc seconds]")
    capture_mm: float = _num(8.0, gt=0.0, le=100.0,
                             what="distance within which the head finds a corner [mm]")
    capture_angle_deg: float = _num(10.0, gt=0.0, le=45.0,
                                    what="angle within which the head finds a corner [deg]")
    # drift of the simulated robot (simulators/thermal.py); a recheck's baseline check ignores these
    thermal_length_um: float = _num(0.0, ge=0.0, le=5000.0,
                                    what="steady-state growth of the arm lengths when warm [µm], 0: no thermal model")
    thermal_offset_arcsec: float = _num(0.0, ge=-3600.0, le=3600.0,
                                        what="steady-state drift of the revolute joint offsets when warm [arc seconds]")
    thermal_time_constant_s: float = _num(600.0, gt=0.0, le=1e6,
                                          what="time constant of the warm-up curve [s of simulated motion]")
    step_joint: int = _num(0, ge=0, le=16, what="joint (1 …) whose offset steps (a re-mastered axis), 0: none")
    step_offset_deg: float = _num(0.0, ge=-10.0, le=10.0, what="the joint offset step [deg]")
    step_tool_um: tuple[Annotated[float, Field(ge=-10000.0, le=10000.0)], ...] = Field(
        (0.0, 0.0, 0.0), min_length=3, max_length=3, strict=False,
        description="a bumped tool: shift of the head x, y, z [µm], each within ±10000")


class _Recheck(_Section):
    poses: int = _num(10, ge=3, le=100, what="poses a recheck measures")
    tolerance_um: float = _num(0.0, ge=0.0, le=10000.0,
                               what="RMS position drift accepted [µm]; 0: 3× the baseline's accuracy")
    offset_tolerance_arcsec: float = _num(0.0, ge=0.0, le=36000.0,
                                          what="joint offset change accepted [arc seconds]; 0: tolerance_um over 500 mm")
    length_tolerance_um: float = _num(0.0, ge=0.0, le=10000.0, what="arm length change accepted [µm]; 0: tolerance_um")
    repeat_tolerance_um: float = _num(0.0, ge=0.0, le=10000.0,
                                      what="first pose against its repeat at the end [µm]; 0: tolerance_um")


class _Warmup(_Section):
    enabled: bool = Field(False, description="true or false")
    until: Literal["converged", "time"] = Field(
        "converged", description='"converged" (the reference pose stops moving) or "time" (minutes)')
    minutes: float = _num(20.0, gt=0.0, le=600.0, what="longest warm-up [min] (with until = \"time\": its length)")
    max_cycles: int = _num(200, ge=1, le=100000, what="most warm-up cycles")
    converged_um: float = _num(2.0, gt=0.0, le=1000.0,
                               what="remaining drift of the reference pose, extrapolated, below which it is warm [µm]")
    program_poses: int = _num(8, ge=2, le=100, what="poses of the motion program per cycle")


class _Conformance(_Section):
    # checked against the robot and [limits] in stage 2 (one value per joint, inside the limits)
    park_joints: list[Annotated[float, Field(ge=-MAX_MM, le=MAX_MM)]] | None = _absent(
        min_length=1, max_length=16, strict=False,
        description="the joints the robot is parked at for 'station conformance', one per joint (deg | mm)")
    test_move: float = _num(1.0, ge=0.1, le=5.0, what="half-width of the park zone around park_joints (deg | mm)")
    move_speed: float = _num(0.05, ge=0.001, le=0.2, what="speed of the kit's test motions, fraction of the maximum")
    position_tolerance: float = _num(0.01, ge=0.0001, le=1.0,
                                     what="largest difference between target and arrived joints (deg | mm)")


#: a tool's name: it names the tool in reports, the run database (``tool:<name>``) and on the command line
ToolName = Annotated[str, Field(min_length=1, max_length=64)]
ToolMm = Annotated[float, Field(ge=-2000.0, le=2000.0)]
ToolPose = Annotated[tuple[ToolMm, ToolMm, ToolMm, Deg, Deg, Deg], Field(strict=False)]
MAX_TOOLS = 16


class _Tool(_Section):
    name: ToolName = Field(description='the tool\'s name: letters, digits, "_", "." and "-", 1 … 64 characters, '
                                       'starting with a letter or digit')
    tcp: ToolPose = Field(description="the TCP in the flange frame from the tool's measurement: x, y, z [mm] within "
                                      "±2000, roll, pitch, yaw [deg] within ±360")
    x_mm: GridAxis | None = _absent(description="the tool's own grid x [start, stop, step] in mm (default: [correction])")
    y_mm: GridAxis | None = _absent(description="the tool's own grid y [start, stop, step] in mm (default: [correction])")
    z_mm: GridAxis | None = _absent(description="the tool's own grid z [start, stop, step] in mm (default: [correction])")

    @field_validator("name")
    @classmethod
    def _name_chars(cls, v: str) -> str:
        if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_.-]*", v):
            raise ValueError('use letters, digits, "_", "." and "-", starting with a letter or digit (the name goes '
                             'into the run database and onto the command line)')
        return v


class _Head(_Section):
    file: PathText | None = _absent(description='the probe-head file (docs/probe-head.md), e.g. "head.toml", '
                                                'relative to this configuration')


class _CellFile(_Section):
    cell: _Cell = Field(default_factory=lambda: _Cell.model_validate({}), description="a table [cell]")
    robot: _Robot = Field(description='a table [robot] with model = "sr800" (or a robot file)')
    body: _Body = Field(description="a table [body] with the measuring points from the CMM report")
    devices: _Devices = Field(default_factory=lambda: _Devices.model_validate({}), description="a table [devices]")
    limits: _Limits = Field(default_factory=lambda: _Limits.model_validate({}), description="a table [limits]")
    plan: _Plan = Field(default_factory=lambda: _Plan.model_validate({}), description="a table [plan]")
    identification: _Identification = Field(default_factory=lambda: _Identification.model_validate({}), description="a table [identification]")
    correction: _Correction = Field(default_factory=lambda: _Correction.model_validate({}), description="a table [correction]")
    simulation: _Simulation = Field(default_factory=lambda: _Simulation.model_validate({}), description="a table [simulation]")
    recheck: _Recheck = Field(default_factory=lambda: _Recheck.model_validate({}), description="a table [recheck]")
    warmup: _Warmup = Field(default_factory=lambda: _Warmup.model_validate({}), description="a table [warmup]")
    conformance: _Conformance = Field(default_factory=lambda: _Conformance.model_validate({}), description="a table [conformance]")
    head: _Head = Field(default_factory=lambda: _Head.model_validate({}), description="a table [head] with file = \"head.toml\"")
    tool: list[_Tool] = Field([], max_length=MAX_TOOLS, description=f"[[tool]] tables, at most {MAX_TOOLS}, "
                              f'each with name = "…" and tcp = [x, y, z, roll, pitch, yaw] (mm, deg)')

    @field_validator("tool")
    @classmethod
    def _unique_tools(cls, tools: list[_Tool]) -> list[_Tool]:
        seen: set[str] = set()
        for t in tools:
            if t.name in seen:
                raise ValueError(f"tool name {t.name!r} appears twice; each [[tool]] needs its own name")
            seen.add(t.name)
        return tools


# -- messages: the key, what is wrong, and the fix ----------------------------------------------

_short = reprlib.Repr()
_short.maxstring, _short.maxother, _short.maxlist, _short.maxdict, _short.maxlevel = 60, 60, 8, 6, 3


def _key(loc: tuple) -> str:
    out = ""
    for part in loc:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out


def _section_of(annotation: Any) -> type[BaseModel] | None:
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for arg in getattr(annotation, "__args__", ()):
        found = _section_of(arg)
        if found is not None:
            return found
    return None


def _field_info(loc: tuple) -> tuple[type[BaseModel] | None, FieldInfo | None]:
    """The section and the field a location points into (list indices are skipped)."""
    model: type[BaseModel] | None = _CellFile
    parent, info = None, None
    for part in loc:
        if isinstance(part, int):
            continue
        if model is None or part not in model.model_fields:
            return model, None
        parent, info = model, model.model_fields[part]
        model = _section_of(info.annotation)
    return parent, info


def bounds_text(info: FieldInfo) -> str:
    """The bounds of a numeric field as the template states them: ``1 … 100``, ``> 0 … 1``."""
    lo = hi = ""
    for m in info.metadata:
        if isinstance(m, annotated_types.Ge):
            lo = f"{m.ge:g}"
        elif isinstance(m, annotated_types.Gt):
            lo = f"> {m.gt:g}"
        elif isinstance(m, annotated_types.Le):
            hi = f"{m.le:g}"
    return f"{lo} … {hi}" if lo and hi else ""


_PROBLEM = {
    "finite_number": "not a finite number",
    "int_type": "expected an integer",
    "float_type": "expected a number",
    "bool_type": "expected true or false",
    "string_type": "expected a string in quotes",
    "list_type": "expected a list [ … ]",
    "tuple_type": "expected a list [ … ]",
    "model_type": "expected a table",
    "dict_type": "expected a table",
    "literal_error": "not one of the allowed values",
    "string_pattern_mismatch": "contains control characters",
    "string_too_short": "is empty",
}


def _describe(err: dict) -> str:
    loc, typ = tuple(err["loc"]), err["type"]
    if typ == "missing" and loc and isinstance(loc[-1], int):  # a list too short for a tuple
        loc, typ = loc[:-1], "too_short"
    key = _key(loc)
    parent, info = _field_info(loc)
    if typ == "extra_forbidden":
        where = _key(loc[:-1]) or "the file"
        allowed = ", ".join(parent.model_fields) if parent is not None and not isinstance(loc[-1], int) else ""
        return (f"{where}: unknown key {loc[-1]!r}; allowed: {allowed} (check the spelling: an unknown "
                f"key would otherwise be ignored)")
    what = info.description if info is not None and info.description else ""
    rng = bounds_text(info) if info is not None else ""
    if typ == "missing":
        return f"{key} is missing; add {what or 'it'} (see 'station init' for the template)"
    ctx = err.get("ctx") or {}
    bound = {"greater_than": ("gt", ">"), "greater_than_equal": ("ge", "≥"), "less_than": ("lt", "<"),
             "less_than_equal": ("le", "≤")}.get(typ)
    if bound is not None:
        limit = ctx.get(bound[0])
        problem = f"must be {bound[1]} {limit:g}" if isinstance(limit, (int, float)) else "out of range"
    elif typ == "value_error":  # the validator's message says what to write
        v = err.get("input")
        shown = f" = {_short.repr(v)}" if isinstance(v, (str, int, float)) else ""
        return f"{key}{shown}: {str(err['msg']).removeprefix('Value error, ')}"
    elif typ in ("too_short", "too_long"):
        n = ctx.get("actual_length")
        problem = f"has {n} items" if n is not None else "has the wrong number of items"
    else:
        problem = _PROBLEM.get(typ, str(err["msg"]))
    fix = f"use {rng} ({what})" if rng else (f"expected {what}" if what else "see 'station init' for the template")
    value = _short.repr(err["input"]) if "input" in err else "?"
    return f"{key} = {value}: {problem}; {fix}"


def _validate_schema(data: dict, source: str) -> _CellFile:
    try:
        return _CellFile.model_validate(data)
    except ValidationError as exc:
        errors = exc.errors(include_url=False)
        msgs = list(dict.fromkeys(_describe(dict(e)) for e in errors))
        more = f" (and {len(msgs) - 5} more)" if len(msgs) > 5 else ""
        raise ConfigError(f"{source}: " + "; ".join(msgs[:5]) + more) from None


# --------------------------------------------------------------------------------------------
# stage 2: what needs the robot
# --------------------------------------------------------------------------------------------

def _pose_deg(v) -> np.ndarray:
    return np.array([*v[:3], *(a * DEG for a in v[3:])], dtype=float)


def _robot_path(model_name: str, source: str) -> str:
    if Path(model_name).is_absolute():
        return model_name
    beside = Path(source).parent / model_name
    try:
        return str(beside) if beside.exists() else model_name
    except (OSError, ValueError):  # a name too long for the file system: load_robot says why
        return model_name


def _body_points(b: _Body, source: str) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
    """ids, ``(n, 6)`` poses [mm, rad] and ``(n, 2)`` σ [mm, rad] of the body's measuring points:
    from ``[body] file`` (the CMM report, relative to the configuration file) or inline; a point
    without σ takes ``default_sigma_*``."""
    default = (b.default_sigma_position_um * UM, b.default_sigma_angle_arcsec * ARCSEC)
    if b.file is not None:
        from station.io.body_file import read_body_file

        path = Path(b.file)
        if not path.is_absolute():
            path = Path(source).parent / path
        try:
            report = read_body_file(path)
        except ConfigError as exc:
            raise ConfigError(f"{source}: body.file: {exc}") from None
        return report.ids, np.array(report.poses), report.sigma_with_default(*default)
    assert b.points is not None  # the schema allows exactly one of the two
    ids = tuple(pt.id for pt in b.points)
    poses = np.array([_pose_deg(pt.pose) for pt in b.points])
    sigma = np.array([[default[0] if pt.sigma_position_um is None else pt.sigma_position_um * UM,
                       default[1] if pt.sigma_angle_arcsec is None else pt.sigma_angle_arcsec * ARCSEC]
                      for pt in b.points])
    return ids, poses, sigma


def _head(file: str | None, cube_edge_mm: float, model: RobotModel, source: str) -> tuple[Any, np.ndarray, RobotModel]:
    """``[head] file``: the head's geometry, MKKS in the flange (4,4), and the robot model with
    the head frame as its nominal K. Without it: the built-in reference head on the robot file's K."""
    from station.core.probe_geometry import default_probe_head
    from station.io.head_file import load_head

    if file is None:
        return default_probe_head(cube_edge_mm=cube_edge_mm), pose_to_matrix(model.nominal[-6:]), model
    path = file if Path(file).is_absolute() else str(Path(source).parent / file)
    try:
        h = load_head(path, cube_edge_mm)
    except ConfigError as exc:
        raise ConfigError(f"{source}: head.file: {exc}") from None
    return h.geometry, h.frame_in_flange, model.with_tool(h.frame_pose)


def _soft_limits(raw: list | None, model: RobotModel, source: str) -> np.ndarray:
    """``[limits].joints`` in rad / mm: one finite, ordered pair per joint inside the robot's."""
    n = model.n_joints
    units = ["deg" if k == "revolute" else "mm" for k in model.joint_types]
    if raw is None:
        return np.array(model.joint_limits, dtype=float)
    if len(raw) != n:
        raise ConfigError(f"{source}: limits.joints lists {len(raw)} joints; the robot {model.name!r} has {n}: "
                          f"write [lower, upper] for each joint (deg for revolute, mm for prismatic)")
    soft = np.zeros((n, 2))
    for j, (pair, unit) in enumerate(zip(raw, units)):
        label = f"{source}: limits.joints: joint {j + 1} = {_short.repr(pair)}"
        if not (isinstance(pair, list) and len(pair) == 2
                and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in pair)):
            raise ConfigError(f"{label}: write [lower, upper] as two numbers ({unit})")
        lo, hi = float(pair[0]), float(pair[1])
        if not (math.isfinite(lo) and math.isfinite(hi)):
            raise ConfigError(f"{label}: lower and upper must be finite numbers ({unit}); a NaN or "
                              f"infinite limit would switch the soft-limit check off")
        if not lo < hi:
            raise ConfigError(f"{label}: lower must be < upper; write [{hi:g}, {lo:g}]" if lo > hi
                              else f"{label}: lower must be < upper")
        scale = DEG if unit == "deg" else 1.0
        soft[j] = lo * scale, hi * scale
        rlo, rhi = model.joint_limits[j] / scale
        if soft[j, 0] < model.joint_limits[j, 0] - 1e-9 or soft[j, 1] > model.joint_limits[j, 1] + 1e-9:
            raise ConfigError(f"{label}: joint {j + 1}'s soft limits exceed the robot's limits "
                              f"[{rlo:g}, {rhi:g}] {unit}; narrow them")
    return soft


def correction_grid(correction: CorrectionConfig, elbows: tuple[int, ...]) -> GridSpec:
    """The configured correction grid (robot base frame) for the given plan elbows."""
    c = correction
    return GridSpec(x_range=(c.x_mm[0], c.x_mm[1]), x_step=c.x_mm[2], y_range=(c.y_mm[0], c.y_mm[1]),
                    y_step=c.y_mm[2], z_range=(c.z_mm[0], c.z_mm[1]), z_step=c.z_mm[2],
                    yaw_step=float(np.deg2rad(c.yaw_step_deg)), elbows=tuple(elbows))


_GRID_KEY = {"x": "correction.x_mm", "y": "correction.y_mm", "z": "correction.z_mm", "yaw": "correction.yaw_step_deg"}


def _check_grid(corr: CorrectionConfig, elbows: tuple[int, ...], n_joints: int, source: str) -> None:
    """The grid's ranges and steps and the controller's capacity, before anything moves (the
    same :class:`GridSpec` the pipeline builds the table on)."""
    for key in ("x_mm", "y_mm", "z_mm"):
        lo, hi, step = getattr(corr, key)
        if not hi > lo:
            raise ConfigError(f"{source}: correction.{key} = [{lo:g}, {hi:g}, {step:g}]: [start, stop, step] needs "
                              f"stop > start")
    n = 360.0 / corr.yaw_step_deg
    if abs(n - round(n)) > 1e-9 * n:
        steps = [360.0 / k for k in range(2, 361) if (3600 % k) == 0]  # divisors to 0.1 deg
        lower = max((v for v in steps if v < corr.yaw_step_deg), default=1.0)
        upper = min((v for v in steps if v > corr.yaw_step_deg), default=180.0)
        hint = f"{lower:g} or {upper:g}"
        raise ConfigError(f"{source}: correction.yaw_step_deg = {corr.yaw_step_deg:g}: must divide 360 deg "
                          f"({n:.4g} steps); use e.g. {hint}")
    try:
        correction_grid(corr, elbows).check_capacity(n_joints)
    except ConfigError as exc:
        m = re.match(r"grid (yaw|x|y|z)", str(exc))
        key = _GRID_KEY[m.group(1)] if m else "correction (x_mm, y_mm, z_mm, yaw_step_deg)"
        raise ConfigError(f"{source}: {key}: {exc}") from None
    except ValueError as exc:  # TableError: a node count the controller cannot hold
        raise ConfigError(f"{source}: correction (x_mm, y_mm, z_mm, yaw_step_deg): {exc}; use larger steps") from None


def _conformance(c: _Conformance, model: RobotModel, soft: np.ndarray, source: str) -> ConformanceConfig | None:
    """``[conformance]`` in rad / mm: one park value per joint, inside the soft limits (None
    without ``park_joints``: the cell has not been prepared for ``station conformance``)."""
    if c.park_joints is None:
        return None
    n = model.n_joints
    if len(c.park_joints) != n:
        raise ConfigError(f"{source}: conformance.park_joints lists {len(c.park_joints)} joints; the robot "
                          f"{model.name!r} has {n}: give one value per joint (deg for revolute, mm for prismatic)")
    scale = np.array([DEG if k == "revolute" else 1.0 for k in model.joint_types])
    park = np.asarray(c.park_joints, dtype=float) * scale
    for j in range(n):
        if not soft[j, 0] <= park[j] <= soft[j, 1]:
            unit = "deg" if model.joint_types[j] == "revolute" else "mm"
            raise ConfigError(f"{source}: conformance.park_joints: joint {j + 1} = {c.park_joints[j]:g} {unit} is outside "
                              f"the soft limits [{soft[j, 0] / scale[j]:g}, {soft[j, 1] / scale[j]:g}] {unit}; park "
                              f"the robot inside [limits]")
    return ConformanceConfig(park, c.test_move * scale, c.move_speed, c.position_tolerance * scale)


def _tools(tools: list[_Tool], corr: CorrectionConfig, elbows: tuple[int, ...], n_joints: int,
           source: str) -> tuple[ToolConfig, ...]:
    """``[[tool]]`` in mm / rad, each with its grid (``[correction]`` with the tool's overrides),
    checked like the head's grid (whole steps, the controller's capacity)."""
    out = []
    for t in tools:
        c = CorrectionConfig(x_mm=t.x_mm or corr.x_mm, y_mm=t.y_mm or corr.y_mm, z_mm=t.z_mm or corr.z_mm,
                             yaw_step_deg=corr.yaw_step_deg, max_interpolation_um=corr.max_interpolation_um)
        if c != corr:
            _check_grid(c, elbows, n_joints, f"{source}: tool {t.name!r} (its x_mm, y_mm, z_mm replace [correction]'s)")
        out.append(ToolConfig(t.name, _pose_deg(t.tcp), c))
    return tuple(out)


def parse_config(data: dict, source: str = "<config>", text: str = "") -> CellConfig:
    """A validated :class:`CellConfig` from parsed TOML; :class:`ConfigError` names the key."""
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: a configuration is a TOML document of tables, got {type(data).__name__}")
    f = _validate_schema(data, source)

    model = load_robot(_robot_path(f.robot.model, source)).with_setup(_pose_deg(f.robot.setup))
    head, head_in_flange, model = _head(f.head.file, f.body.cube_edge_mm, model, source)  # [head]
    soft = _soft_limits(f.limits.joints, model, source)

    d = f.devices
    host, _, port = d.controller.rpartition(":")
    devices = DeviceConfig(
        probe_head=d.probe_head, baudrate=d.baudrate, probe_timeout_s=d.probe_timeout_s,
        controller_host=host, controller_port=int(port), device_id=d.device_id, word_order=d.word_order,
        controller_timeout_s=d.controller_timeout_s, motion_timeout_s=d.motion_timeout_s)
    p = f.plan
    plan = PlanConfig(
        elbows=tuple(p.elbows), approach_deg=p.approach_deg, approach_mm=p.approach_mm,
        clearance_mm=p.clearance_mm, speed=p.speed, settle_s=p.settle_s, samples=p.samples,
        max_spread_um=p.max_spread_um, both_directions=p.both_directions,
        verification_every=p.verification_every, verification_cycles=p.verification_cycles,
        select=p.select, repeats=p.repeats, recenter_attempts=p.recenter_attempts,
        recenter_margin_mm=p.recenter_margin_mm, max_residual_um=p.max_residual_um,
        remeasure_attempts=p.remeasure_attempts)

    i = f.identification
    ident = IdentificationConfig(
        objective=i.objective, sigma_position_um=i.sigma_position_um,
        sigma_angle_arcsec=i.sigma_angle_arcsec,
        prefer=tuple(model.prefer if i.prefer is None else i.prefer), fix=tuple(i.fix), exclude=tuple(i.exclude))
    for key in ("prefer", "fix", "exclude"):
        for n in getattr(ident, key):
            try:
                model.param_index(n)
            except ConfigError as exc:
                raise ConfigError(f"{source}: identification.{key}: {exc}") from None

    c = f.correction
    corr = CorrectionConfig(x_mm=c.x_mm, y_mm=c.y_mm, z_mm=c.z_mm, yaw_step_deg=c.yaw_step_deg,
                            max_interpolation_um=c.max_interpolation_um)
    if model.is_scara:  # an articulated arm gets compensated targets, not a table (issue 9)
        _check_grid(corr, plan.elbows, model.n_joints, source)

    ids, poses, body_sigma = _body_points(f.body, source)
    r, w = f.recheck, f.warmup
    recheck = RecheckConfig(poses=r.poses, tolerance_um=r.tolerance_um, offset_tolerance_arcsec=r.offset_tolerance_arcsec,
                            length_tolerance_um=r.length_tolerance_um, repeat_tolerance_um=r.repeat_tolerance_um)
    warmup = (WarmupConfig(until=w.until, minutes=w.minutes, max_cycles=w.max_cycles, converged_um=w.converged_um,
                           program_poses=w.program_poses) if w.enabled else None)
    sim = f.simulation
    if sim.step_joint > model.n_joints:
        raise ConfigError(f"{source}: simulation.step_joint = {sim.step_joint}: the robot has {model.n_joints} joints")
    return CellConfig(
        f.cell.name, model, soft, ids, pose_to_matrix(poses), f.body.cube_edge_mm,
        devices, plan, ident, corr, text, f.simulation.seed, recheck, warmup,
        conformance=_conformance(f.conformance, model, soft, source),
        head=head,  # ProbeHeadGeometry of the [head] file, or the built-in reference head
        head_in_flange=head_in_flange,  # (4,4) MKKS in the flange frame (the robot model's nominal K)
        body_sigma=body_sigma,  # (n, 2) [mm, rad] from the CMM report or the inline points (0: exact)
        tools=_tools(f.tool, corr, plan.elbows, model.n_joints, source),  # [[tool]] (station/cell/tools.py)
        simulation=f.simulation,  # the validated [simulation] table (simulators/from_config.py reads it)
        source=source,  # where it was read: relative robot, head and body files resolve beside it
    )


def simulation_settings(text: str, source: str = "<config>") -> dict[str, Any]:
    """The ``[simulation]`` table of a configuration (or of a file holding only that table), validated:
    what ``station … --simulated CONFIG`` passes to the simulated cell (seed, the true errors'
    magnitudes, the physics, thermal model, step), in the file's units."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{source}: not valid TOML ({exc}); fix the syntax there") from None
    raw = data.get("simulation", {})
    try:
        sim = _Simulation.model_validate(raw)
    except ValidationError as exc:
        msgs = [_describe({**dict(e), "loc": ("simulation", *e["loc"])}) for e in exc.errors(include_url=False)]
        raise ConfigError(f"{source}: " + "; ".join(msgs[:5])) from None
    return sim.model_dump()


def load_config(path: str | Path) -> CellConfig:
    """Read and validate a configuration file: only a regular file of at most
    :data:`MAX_CONFIG_BYTES`, UTF-8 (a device, FIFO or directory is refused before reading)."""
    p = Path(path)
    text = read_user_text(p, MAX_CONFIG_BYTES, "configuration file",
                          missing=f"no such configuration file; 'station init {p}' writes a template")
    return parse_text(text, str(p))


def parse_text(text: str, source: str = "<config>") -> CellConfig:
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{source}: not valid TOML ({exc}); fix the syntax there") from None
    except RecursionError:
        raise ConfigError(f"{source}: not valid TOML (nested too deeply); fix the syntax there") from None
    return parse_config(data, source, text)


TEMPLATE = """\
# Calibration cell configuration. Lengths in mm, angles in degrees, uncertainties in µm and
# arc seconds. 'station check THIS_FILE' connects to every device and reports what works.
# Every number has bounds, given as "lo … hi" in its comment; a value outside them, an unknown
# key or a wrong type is refused before anything moves, with the key and the fix.

[cell]
name = "cell 1"

[robot]
model = "sr800"                  # built-in robot or a robot file (docs/robot-file.md)
# Nominal pose of the robot base in the calibration-body frame: x, y, z [mm], roll, pitch, yaw [deg]
# (positions within ±10000 mm, angles within ±360 deg).
# It only has to be right to a few mm / a few tenths of a degree; the calibration identifies it.
setup = [-450.0, 0.0, -170.0, 0.0, 0.0, 0.0]

[limits]
# Soft limits the station never commands a motion beyond: [lower, upper] per joint (deg | mm),
# finite, lower < upper, inside the robot file's limits.
joints = [[-125.0, 125.0], [-140.0, 140.0], [-195.0, -5.0], [-355.0, 355.0]]

[body]
cube_edge_mm = 40.0              # > 0 … 1000
# Measuring points (cube corners) from the body's CMM report: pose of each corner frame in the
# body frame, x, y, z [mm], roll, pitch, yaw [deg]. Corner frame: origin at the top corner, cube in x>=0, y>=0, z<=0.
# 3 … 5000 points; ids are unique, 1 … 64 characters. Either the CMM report as a CSV file,
# relative to this file (docs/data-files.md, "Calibration body"; columns id, x_mm, y_mm, z_mm,
# roll_deg, pitch_deg, yaw_deg, optionally sigma_position_um, sigma_angle_arcsec):
# file = "body.csv"
# or the points inline (a point may add sigma_position_um = 2.0, sigma_angle_arcsec = 5.0):
points = [
  { id = "C1.a", pose = [-28.3, -319.7, 40.0, 0.0, 0.0, 10.0] },
  { id = "C1.b", pose = [11.1, -312.8, 40.0, 0.0, 0.0, 100.0] },
  { id = "C1.c", pose = [4.1, -273.4, 40.0, 0.0, 0.0, 190.0] },
]
# The CMM's uncertainty of a point that gives none; it goes into the identification's weights
# and σ (the measurements of one point share its error). 0: the body is taken as exact.
default_sigma_position_um = 0.0  # 0 … 1000
default_sigma_angle_arcsec = 0.0 # 0 … 3600

[devices]
probe_head = "/dev/ttyUSB0"      # serial device, or socket://host:port, rfc2217://host:port
baudrate = 38400                 # 9600, 19200, 38400, 57600 or 115200
probe_timeout_s = 0.5            # 0.01 … 60
controller = "192.168.0.10:502"  # Modbus TCP host:port
device_id = 1                    # Modbus unit id, 0 … 255
word_order = "big"               # 32-bit word order of the controller: "big" or "little"
controller_timeout_s = 1.0       # 0.01 … 60
motion_timeout_s = 60.0          # longest single motion [s], 1 … 600

[plan]
elbows = [1, -1]                 # elbow configurations to measure every point in: [1, -1] or [1]
approach_deg = 0.5               # every joint approaches its target from below by this much, > 0 … 10
approach_mm = 1.0                # > 0 … 50
clearance_mm = 20.0              # retract height above a measuring point before moving on, > 0 … 500
speed = 0.5                      # fraction of the robot's maximum speed, > 0 … 1
settle_s = 0.2                   # wait after a motion before reading the probes [s], 0 … 30
samples = 4                      # probe snapshots averaged per reading, 1 … 100
max_spread_um = 10.0             # reject a reading whose snapshots spread more than this, > 0 … 1000
both_directions = false          # also approach from above to measure the reversal error
verification_every = 4           # every 4th (point, elbow) is held out for verification, 2 … 100
verification_cycles = 3          # ISO 9283 repetitions per verification pose, 1 … 30
select = 0                       # > 0: keep only this many most informative steps (D-optimal), 0 … 5000
repeats = 2                      # visits per identification pose (robot repeatability averages out), 1 … 20
recenter_attempts = 2            # re-centre when a probe is near the end of its stroke, 0 … 10
recenter_margin_mm = 1.5         # 0 … 4 (the probes' stroke is ±5 mm)
max_residual_um = 10.0           # plane residual above which a reading is not valid, > 0 … 1000
remeasure_attempts = 1           # re-touches when a redundant head's probes disagree, 0 … 5

# [head]
# file = "head.toml"             # the probe-head file (docs/probe-head.md), relative to this file;
#                                # without it: the built-in reference 3-2-1 head (examples/heads/reference-321.toml)

[identification]
objective = "pose"               # "pose" (robot + set-up + head) or "distance" (robot only)
sigma_position_um = 15.0         # 0.01 … 1000
sigma_angle_arcsec = 20.0        # 0.01 … 3600
# prefer = ["K.x", ...]          # minimal-set preferences; default: the robot file's
# fix = []
# exclude = []

[correction]
# Grid of the correction table in the robot base frame: [start, stop, step], stop > start, the
# range a whole number of steps, step 1 … 10000 mm; with the yaw step (a divisor of 360) it must fit
# the controller's 32 000 values (nodes × elbows × joints): checked when the file is read.
x_mm = [250.0, 650.0, 40.0]
y_mm = [-350.0, 350.0, 50.0]
z_mm = [250.0, 450.0, 200.0]
yaw_step_deg = 30.0              # 1 … 180
max_interpolation_um = 15.0      # refuse a table whose interpolation bound exceeds this, > 0 … 1000

[recheck]
# 'station recheck': a short check of a few poses against the last calibration (the baseline).
# A tolerance of 0 is derived from the baseline's own accuracy.
poses = 10                       # poses measured (plus one repeat of the first), 3 … 100
tolerance_um = 0.0               # RMS position drift accepted [µm]; 0: 3× the baseline's accuracy, 0 … 10000
offset_tolerance_arcsec = 0.0    # joint offset change accepted [″]; 0: tolerance_um over 500 mm, 0 … 36000
length_tolerance_um = 0.0        # arm length change accepted [µm]; 0: tolerance_um, 0 … 10000
repeat_tolerance_um = 0.0        # first pose vs its repeat [µm], else untrusted; 0: tolerance_um, 0 … 10000

[warmup]
# Before 'calibrate' and 'recheck': cycles of a motion program over the workspace, each ended by
# a measurement of one reference pose, until the pose stops moving or for a set time.
enabled = false
until = "converged"              # "converged" or "time"
minutes = 20.0                   # longest warm-up (until = "time": its length) [min], > 0 … 600
max_cycles = 200                 # 1 … 100000
converged_um = 2.0               # remaining drift of the reference pose (extrapolated) [µm], > 0 … 1000
program_poses = 8                # poses of the motion program per cycle, 2 … 100

[conformance]
# 'station conformance': checks the robot program against the register map and handshake
# (docs/robot-program.md). Park the robot at park_joints first; the kit moves it only inside the
# park zone, park_joints ± test_move per joint. With one joint parked within test_move of its
# soft limit (here the quill near its top) the kit also checks that an out-of-limits target is
# refused, with a target that stays inside the park zone.
# park_joints = [0.0, 90.0, -6.0, 0.0]  # deg | mm, one per joint, inside [limits]: required for it
test_move = 2.0                  # half-width of the park zone (deg | mm), 0.1 … 5
move_speed = 0.05                # speed of the test motions, fraction of the maximum, 0.001 … 0.2
position_tolerance = 0.01        # arrived joints vs target (deg | mm), 0.0001 … 1

# Tools that replace the probe head after the calibration, at most 16, one [[tool]] table each:
# the station builds each tool's own correction from the identified model (docs/correction.md,
# "Tools after the head"); 'station export --tool NAME' writes its table for the controller.
# [[tool]]
# name = "gripper"               # unique; letters, digits, _ . -, 1 … 64 characters
# tcp = [50.0, 0.0, -200.0, 0.0, 0.0, 0.0]  # TCP in the flange frame from the tool's measurement:
#                                # x, y, z [mm] within ±2000, roll, pitch, yaw [deg] within ±360
# z_mm = [150.0, 350.0, 200.0]   # optional x_mm, y_mm, z_mm: the tool's own grid (default: [correction])
"""
