"""The configuration file's schema (stage 1 of :mod:`station.cell.config.cell_config`): the pydantic v2
sections in strict mode, with the types, bounds and unknown keys of every table, and the
messages that turn a validation error into the key, what is wrong, and the fix.

Every numeric key has bounds; an integer is never a bool or a float, a float is finite. The
bounds are the one source: the error messages (:func:`bounds_text`) and the test that reads the
template's comments (:mod:`station.cell.config.template`) take them from here.
"""

from __future__ import annotations

import difflib
import re
import reprlib
from typing import Annotated, Any, Literal

import annotated_types
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator
from pydantic.fields import FieldInfo

from station.errors import ConfigError

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
RegionAxis = Annotated[tuple[Mm, Mm], Field(strict=False)]

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
    # keys are refused so that a typo never silently falls back to a default; each section's
    # validator is built when first used, not at import (issue 42: 23 models, ~45 ms of every
    # station process's start, also of those that read no cell file)
    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False, frozen=True, defer_build=True)


class _Cell(_Section):
    name: Text = Field("calibration cell", description="the cell's name in reports, 1 … 256 characters")
    # traceability in the report (docs/station.md, "The report"): what the QA record names
    robot_serial: Text | None = _absent(description="the robot's serial number from its plate, 1 … 256 characters")
    controller: Text | None = _absent(description="the robot controller's make, model and serial number, "
                                                  "1 … 256 characters")
    operator: Text | None = _absent(description="who runs the station (the report's operator unless "
                                                "--operator names another), 1 … 256 characters")

    @field_validator("robot_serial")
    @classmethod
    def _serial_names_a_page(cls, serial: str | None) -> str | None:
        # the serial is the robot's key in the fleet and its dashboard page /robots/KEY: '.' or '..'
        # alone is a path segment every browser resolves away (WHATWG URL, encoded or not)
        if serial is not None and set(serial.strip()) <= {"."}:
            raise ValueError("is dots only: give the serial number from the robot's plate")
        return serial


class _Robot(_Section):
    model: PathText = Field(description='a built-in robot ("sr800") or a robot file (docs/robot-file.md)')
    setup: Pose = Field((0.0,) * 6, description=f"nominal pose of the robot base in the body frame: {_POSE_WHAT}")
    # how far a measuring point may lie from where setup puts it: the body is located within it (issue 37)
    setup_uncertainty_mm: float = _num(5.0, gt=0.0, le=100.0, what="how far [mm] a measuring point may lie from "
                                       "where setup puts it (the station locates the body within this)")


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
    # the probe interface's dialect (drivers/probe_dialects): its commands, replies and the line
    # settings its unit offers; the line settings below are checked against it before anything opens
    probe_protocol: Literal["keyence-dl-rs1a", "station-ascii", "mitutoyo-ga"] = Field(
        "keyence-dl-rs1a", description='"keyence-dl-rs1a" (Keyence DL-RS1A with GT2 amplifiers), "mitutoyo-ga" '
        '(Mitutoyo RS-232C indicators, GA requests) or "station-ascii" (a custom interface speaking the station\'s own)')
    baudrate: Literal[2400, 4800, 9600, 19200, 38400, 57600, 115200] | None = Field(
        None, description="the rate set on the probe unit (2400 … 115200 as its dialect allows; "
        "absent: the unit's factory default, 9600 for the DL-RS1A)")
    probe_bytesize: Literal[7, 8] | None = Field(None, description="data bits set on the probe unit, 7 or 8 "
                                                 "(absent: the unit's factory default)")
    probe_parity: Literal["none", "even", "odd"] | None = Field(
        None, description='parity set on the probe unit: "none", "even" or "odd" (absent: the factory default)')
    probe_timeout_s: float = _num(0.5, ge=0.01, le=60.0, what="seconds to wait for a probe reply")
    # a DL-RS1A answers from a buffer it refreshes every ~7 ms (one amplifier) to ~50 ms (ten),
    # behind each amplifier's response-time filter: a reading is taken as two replies this far apart
    probe_refresh_ms: float | None = _num(None, ge=0.0, le=10000.0, what="the probe unit's buffer refresh "
                                          "time [ms] (absent: the dialect's, 50 ms for a DL-RS1A)")
    controller: str = Field("127.0.0.1:502", max_length=300,
                            description='Modbus TCP host:port, e.g. "192.168.0.10:502" (port 1 … 65535)')
    device_id: int = _num(1, ge=0, le=255, what="Modbus unit id of the controller")
    word_order: Literal["big", "little"] = Field(
        "big", description='"big" or "little" (how the controller orders 32-bit words)')
    controller_timeout_s: float = _num(1.0, ge=0.01, le=60.0, what="seconds to wait for a controller reply")
    # the station declares the link lost when the robot program's heartbeat stands still this long
    controller_link_timeout_s: float = _num(1.0, ge=0.2, le=60.0, what="seconds the controller's heartbeat "
                                            "may stand still before the link counts as lost")
    motion_timeout_s: float = _num(60.0, ge=1.0, le=600.0, what="seconds one motion may take")
    # the robot program's register window (docs/robot-program.md): 0, or 128 for the general-purpose
    # registers of a Universal Robots controller
    controller_register_base: int = _num(0, ge=0, le=65535 - 128, what="first holding register of the robot "
                                         "program's 128-register window")

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
    locate_steps: int = _num(3, ge=0, le=20, what="search steps per face normal when locating the body "
                             "beyond the probes' stroke")
    collision_margin_mm: float = _num(2.0, gt=0.0, le=200.0, what="least clearance between any two shapes of the "
                                      "cell at every pose and along every path [mm] (docs/collision.md)")

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
    # the error terms beyond geometry (issue 30, docs/error-terms.md): what `identify --model` takes
    model: Text = Field("geometric", description='"geometric", "auto", or terms joined by "+" such as '
                                                 '"compliance+cyclic"')

    @field_validator("model")
    @classmethod
    def _model_terms(cls, v: str) -> str:
        names = [n.strip() for n in v.split("+")]
        if v.strip() == "auto" or all(_TERM.match(n) for n in names):
            return v
        raise ValueError('write "geometric", "auto", or terms joined by "+": compliance, cyclic, cyclic2, '
                         'cyclic.q<j>, cyclic2.q<j>, drift, backlash (with [plan] both_directions = true) '
                         '(e.g. "compliance+cyclic")')


#: one term family of ``[identification] model`` (backlash: where the plan approaches from both sides,
#: checked in cell_config._check_terms)
_TERM = re.compile(r"^(geometric|compliance|cyclic2?|cyclic2?\.q[1-9][0-9]?|drift|backlash)$")


class _Region(_Section):
    """``[correction] region``: the TCP's working box in the robot base frame (the head frame's origin)."""

    x_mm: RegionAxis = Field(description="[low, high] in mm")
    y_mm: RegionAxis = Field(description="[low, high] in mm")
    z_mm: RegionAxis = Field(description="[low, high] in mm")

    @model_validator(mode="after")
    def _ordered(self) -> "_Region":
        for key in ("x_mm", "y_mm", "z_mm"):
            lo, hi = getattr(self, key)
            if not lo < hi:
                raise ValueError(f"region {key} = [{lo:g}, {hi:g}]: write [low, high] with low < high")
        return self


class _Correction(_Section):
    # Without x_mm, y_mm and z_mm the station designs the grid (station/cell/correction/design.py);
    # given, all three together, they are the grid.
    x_mm: GridAxis | None = _absent(description="[start, stop, step] in mm, step 1 … 10000 (absent: designed)")
    y_mm: GridAxis | None = _absent(description="[start, stop, step] in mm, step 1 … 10000 (absent: designed)")
    z_mm: GridAxis | None = _absent(description="[start, stop, step] in mm, step 1 … 10000 (absent: designed)")
    yaw_step_deg: float = _num(None, ge=1.0, le=180.0, what="yaw step of the table [deg], a divisor of 360 "
                               "(absent: designed; 30 with x_mm, y_mm, z_mm)")
    max_interpolation_um: float = _num(15.0, gt=0.0, le=1000.0, what="largest interpolation bound accepted [µm]")
    region: _Region | None = _absent(description="the TCP's working box in the robot base frame: "
                                     "{ x_mm = [low, high], y_mm = [low, high], z_mm = [low, high] }")

    @model_validator(mode="after")
    def _whole_grid(self) -> "_Correction":
        given = [k for k in ("x_mm", "y_mm", "z_mm") if getattr(self, k) is not None]
        if given and len(given) < 3:
            missing = ", ".join(k for k in ("x_mm", "y_mm", "z_mm") if k not in given)
            raise ValueError(f"the grid is given by x_mm, y_mm and z_mm together: add {missing}, or remove "
                             f"{', '.join(given)} to let the station design the grid")
        if given and self.region is not None:
            raise ValueError("give either region (the station designs the grid over it) or x_mm, y_mm, z_mm "
                             "(the grid itself), not both")
        return self


class _SetupError(_Section):
    """``[simulation] setup_error``: the true set-up's error against ``[robot].setup``, planted
    exactly instead of drawn (a rehearsal with a set-up off by a chosen amount, e.g. ≥ 1 mm in z
    for issue 36's base-frame check). A component left out is 0."""

    x_mm: float = _num(0.0, ge=-100.0, le=100.0, what="the true set-up's error along x [mm]")
    y_mm: float = _num(0.0, ge=-100.0, le=100.0, what="the true set-up's error along y [mm]")
    z_mm: float = _num(0.0, ge=-100.0, le=100.0, what="the true set-up's error along z [mm]")
    roll_deg: float = _num(0.0, ge=-5.0, le=5.0, what="the true set-up's error in roll [deg]")
    pitch_deg: float = _num(0.0, ge=-5.0, le=5.0, what="the true set-up's error in pitch [deg]")
    yaw_deg: float = _num(0.0, ge=-10.0, le=10.0, what="the true set-up's error in yaw [deg]")


class _Simulation(_Section):
    """``[simulation]``: what ``--simulated CONFIG`` and ``python -m simulators --config`` simulate.
    The defaults are the built-in cell's (``simulators/from_config.py``, :class:`SimulationPhysics`
    holds the same numbers): a realistic SCARA of the 800 mm class and a CMM-measured body."""

    seed: int = _num(None, ge=0, le=2**32 - 1, what="seed of the simulated cell")
    # the simulated robot program's register window (docs/robot-program.md): every address outside
    # [devices] controller_register_base + 0 … count-1 is refused with Modbus exception 2
    controller_register_count: int = _num(128, ge=1, le=65536, what="holding registers the simulated "
                                          "controller hosts from [devices] controller_register_base")
    # what the simulated program reports in correction_state: 0 none, 1 the vendor's correction, 2 unknown
    controller_correction_state: int = _num(0, ge=0, le=2, what="the simulated controller's own correction "
                                            "state (0 none, 1 vendor correction on, 2 unknown)")
    # the true errors of the simulated robot (seeded; σ of a normal distribution each)
    length_sigma_um: float = _num(40.0, ge=0.0, le=5000.0,
                                  what="σ of the true errors of the robot's lengths (arms, head) [µm]")
    angle_sigma_arcsec: float = _num(150.0, ge=0.0, le=36000.0,
                                     what="σ of the true errors of the robot's angles (offsets, axis tilts) [arc seconds]")
    offset_sigma_arcsec: float | None = _num(None, ge=0.0, le=36000.0, what="σ of the true encoder (zero) "
                                             "offsets of the revolute joints [arc seconds]; not given: angle_sigma_arcsec")
    tilt_sigma_arcsec: float | None = _num(None, ge=0.0, le=36000.0, what="σ of the true axis tilts (roll, pitch "
                                           "of every transform) [arc seconds]; not given: angle_sigma_arcsec")
    setup_sigma_mm: float = _num(1.5, ge=0.0, le=100.0,
                                 what="σ of the true set-up against the nominal [robot].setup, x, y, z [mm]")
    setup_yaw_sigma_deg: float = _num(0.2, ge=0.0, le=10.0, what="σ of the true set-up's yaw [deg]")
    setup_tilt_sigma_deg: float = _num(0.03, ge=0.0, le=5.0, what="σ of the true set-up's roll and pitch [deg]")
    # planted, not drawn: the robot's errors are the seed's draws either way (the set-up is drawn last)
    setup_error: _SetupError | None = _absent(description="the true set-up's error against [robot].setup, exact: "
                                              "{ x_mm, y_mm, z_mm within ±100, roll_deg, pitch_deg within ±5, "
                                              "yaw_deg within ±10 }, a component left out 0; not given: drawn "
                                              "with setup_sigma_mm, setup_yaw_sigma_deg, setup_tilt_sigma_deg")
    # the physics of the simulated robot, probe head and body
    repeatability_um: float = _num(5.0, ge=0.0, le=1000.0,
                                   what="σ of a joint's position per move [µm] (revolute: at lever_mm)")
    backlash_um: float = _num(100.0, ge=0.0, le=5000.0,
                              what="reversal error of a revolute joint at lever_mm [µm]")
    prismatic_backlash_um: float = _num(20.0, ge=0.0, le=5000.0, what="reversal error of a prismatic joint [µm]")
    joint_backlash_um: list[Annotated[float, Field(ge=0.0, le=5000.0)]] | None = _absent(
        max_length=64, strict=False, description="reversal error per joint [µm] (revolute: at lever_mm), one per "
        "joint; not given: backlash_um and prismatic_backlash_um")
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
    # joint errors beyond geometry (issue 30, simulators/joint_errors.py): "six-axis" is a 1.6 m arm's
    # compliance under gravity and once-per-turn gear errors; "scara" a SCARA's gears erring once per
    # turn (joints 1, 2, 4); "none" (the default, as the source chapter finds for the SCARA) none
    joint_errors: Literal["none", "six-axis", "scara"] = Field(
        "none", description='"six-axis": the joints bend under gravity and err once per turn (a 1.6 m arm\'s '
        'values, docs/error-terms.md); "scara": a SCARA\'s joints 1, 2, 4 err once per turn; "none": a rigid robot')
    joint_errors_scale: float = _num(1.0, ge=0.0, le=10.0, what="factor on every joint error of joint_errors")
    # the simulated controller's own collision check (issue 40, simulators/collision_check.py): on by
    # default wherever the simulator has the cell's files, so that a planning slip fails a rehearsal
    # and the end-to-end tests; None (the key absent) is that default, which the built-in cell (no
    # files of its own to check against) leaves off, while its explicit true is refused
    collision_check: bool | None = Field(None, description="true (the default for a cell with its robot and body "
                                         "files): the simulated controller refuses (error COLLISION) a motion whose "
                                         "target or joint-space path collides in its own model of the cell (links, "
                                         "head, body, [[obstacle]]); false: it checks nothing")


class _Verification(_Section):
    """``[verification]``: the accuracy specification the report judges the held-out poses
    against (ISO 9283 AP and RP after correction), and the test conditions it states."""

    max_ap_um: float | None = _num(None, gt=0.0, le=10000.0, what="largest ISO 9283 pose accuracy AP accepted "
                                   "after correction, per pose [µm] (absent: not judged)")
    max_rp_um: float | None = _num(None, gt=0.0, le=10000.0, what="largest ISO 9283 pose repeatability RP "
                                   "accepted after correction, per pose [µm] (absent: not judged)")
    temperature_c: float | None = _num(None, ge=-40.0, le=80.0, what="the cell's air temperature during the "
                                       "test [°C], as the report states it (absent: not recorded)")
    load_kg: float | None = _num(None, ge=0.0, le=2000.0, what="the mass on the flange during the test (probe "
                                 "head and adapter) [kg] (absent: not recorded)")


class _Recheck(_Section):
    poses: int = _num(10, ge=3, le=100, what="poses a recheck measures")
    tolerance_um: float = _num(0.0, ge=0.0, le=10000.0,
                               what="RMS position drift accepted [µm]; 0: 3× the baseline's accuracy")
    offset_tolerance_arcsec: float = _num(0.0, ge=0.0, le=36000.0,
                                          what="joint offset change accepted [arc seconds]; 0: tolerance_um over 500 mm")
    length_tolerance_um: float = _num(0.0, ge=0.0, le=10000.0, what="arm length change accepted [µm]; 0: tolerance_um")
    repeat_tolerance_um: float = _num(0.0, ge=0.0, le=10000.0,
                                      what="first pose against its repeat at the end [µm]; 0: tolerance_um")
    interval_days: int = _num(0, ge=0, le=3650, what="days between rechecks (the fleet's due date); 0: [fleet] "
                              "recheck_interval_days")


class SecretInput(ValueError):
    """A refusal whose message must not show the value refused (it may hold a password)."""


class _Fleet(_Section):
    """[fleet]: the plant's central fleet store (issue 31). No credentials here: the libpq service
    file, ~/.pgpass or PG* environment variables supply them."""

    url: Text | None = _absent(description="the fleet store: postgresql://host/dbname or service=NAME (no "
                                           "password; STATION_FLEET_URL overrides)")
    station: Text | None = _absent(description="this station's name in the fleet (default: the host name)")
    recheck_interval_days: int = _num(30, ge=1, le=3650, what="days between rechecks where [recheck] "
                                                              "interval_days is 0")

    @field_validator("url")
    @classmethod
    def _no_password(cls, url: str | None) -> str | None:
        # read as libpq reads it (psycopg's conninfo_to_dict is libpq's PQconninfoParse): a
        # password in any spelling (user:pw@, ?password=, ?pass%77ord=, password = …) is found;
        # the refusal never shows the value (SecretInput)
        if url is None:
            return url
        from psycopg import Error
        from psycopg.conninfo import conninfo_to_dict

        try:
            keys = conninfo_to_dict(url)
        except Error:  # libpq's message may quote the string: not shown
            raise SecretInput("is not a connection string libpq reads: give postgresql://host/dbname or "
                              "service=NAME") from None
        if keys.get("password") or keys.get("sslpassword"):
            raise SecretInput("holds a password: put credentials in ~/.pgpass, the libpq service file or "
                              "PGPASSWORD, never in the cell file (the value is not shown)")
        return url


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

    @model_validator(mode="after")
    def _whole_steps(self) -> "_Tool":
        """Its own axes, whole steps from start to stop (with a designed [correction] its capacity
        is checked with the design, before the first motion)."""
        for key in ("x_mm", "y_mm", "z_mm"):
            v = getattr(self, key)
            if v is None:
                continue
            n = (v[1] - v[0]) / v[2]
            if not v[1] > v[0] or abs(n - round(n)) > 1e-9 * max(1.0, n):
                raise ValueError(f"tool {self.name!r}: correction.{key} = [{v[0]:g}, {v[1]:g}, {v[2]:g}]: stop > start "
                                 f"and a whole number of steps from start to stop, e.g. step {(v[1] - v[0]) / max(1, round(n)):.6g}")
        return self

    @field_validator("name")
    @classmethod
    def _name_chars(cls, v: str) -> str:
        if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_.-]*", v):
            raise ValueError('use letters, digits, "_", "." and "-", starting with a letter or digit (the name goes '
                             'into the run database and onto the command line)')
        return v


class _Obstacle(_Section):
    """A fixed obstacle of the cell (issue 40; docs/collision.md): a box or a cylinder (axis along its
    own z), centred at ``pose`` in the body frame or the robot's base frame."""

    name: ToolName = Field(description='the obstacle\'s name (it names the obstacle in a refusal), e.g. "column"')
    shape: Literal["box", "cylinder"] = Field(description='"box" or "cylinder"')
    frame: Literal["body", "base"] = Field("body", description='"body" (the body frame KKS) or "base" (the robot base)')
    pose: Pose = Field(description="pose of the obstacle's centre: " + _POSE_WHAT)
    size_mm: Annotated[tuple[float, float, float], Field(strict=False)] | None = _absent(
        description="a box's edges x, y, z [mm], each within (0, 10000]")
    radius_mm: float | None = _absent(gt=0.0, le=MAX_MM, description="a cylinder's radius [mm], within (0, 10000]")
    height_mm: float | None = _absent(gt=0.0, le=MAX_MM, description="a cylinder's height [mm], within (0, 10000]")

    @model_validator(mode="after")
    def _dimensions(self) -> "_Obstacle":
        """A box has size_mm and nothing else; a cylinder radius_mm and height_mm."""
        if self.shape == "box":
            if self.size_mm is None or self.radius_mm is not None or self.height_mm is not None:
                raise ValueError(f"obstacle {self.name!r}: a box takes size_mm = [x, y, z] (mm) and no radius or height")
            if not all(0.0 < v <= MAX_MM for v in self.size_mm):
                raise ValueError(f"obstacle {self.name!r}: size_mm: each edge within (0, {MAX_MM:g}] mm")
        elif self.radius_mm is None or self.height_mm is None or self.size_mm is not None:
            raise ValueError(f"obstacle {self.name!r}: a cylinder takes radius_mm and height_mm (mm) and no size_mm")
        return self


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
    verification: _Verification = Field(default_factory=lambda: _Verification.model_validate({}),
                                        description="a table [verification]")
    recheck: _Recheck = Field(default_factory=lambda: _Recheck.model_validate({}), description="a table [recheck]")
    warmup: _Warmup = Field(default_factory=lambda: _Warmup.model_validate({}), description="a table [warmup]")
    fleet: _Fleet = Field(default_factory=lambda: _Fleet.model_validate({}), description="a table [fleet]")
    conformance: _Conformance = Field(default_factory=lambda: _Conformance.model_validate({}), description="a table [conformance]")
    head: _Head = Field(default_factory=lambda: _Head.model_validate({}), description="a table [head] with file = \"head.toml\"")
    obstacle: list[_Obstacle] = Field([], max_length=64, description="[[obstacle]] tables, at most 64: the "
                                      "cell's fixed obstacles (docs/collision.md)")
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
        known = list(parent.model_fields) if parent is not None and not isinstance(loc[-1], int) else []
        # the nearest known name first: a typo is the usual cause (issue 33, as for robot files)
        close = difflib.get_close_matches(str(loc[-1]), known, n=1, cutoff=0.6)
        hint = f"did you mean {close[0]!r}? " if close else ""
        return (f"{where}: unknown key {loc[-1]!r}; {hint}allowed: {', '.join(known)} (check the spelling: "
                f"an unknown key would otherwise be ignored)")
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
        secret = isinstance(ctx.get("error"), SecretInput)
        shown = f" = {_short.repr(v)}" if isinstance(v, (str, int, float)) and not secret else ""
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
