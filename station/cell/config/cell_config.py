"""Cell configuration (TOML): robot, calibration body, probe head, devices, limits, plan,
identification and correction settings. ``station init`` writes :data:`TEMPLATE`.

Validation names the key and the fix. Inside, everything is mm and rad; the file holds degrees
where people write angles (keys ending in ``_deg``), µm and arc seconds for uncertainties.

Every key is checked before anything moves, in two stages:

1. The file's schema (:class:`_CellFile`, pydantic v2 in strict mode, in
   :mod:`station.cell.config.schema`): types, bounds and unknown keys. Every numeric key has
   bounds (the template states them); an integer is never a bool or a float, a float is finite.
   The bounds are the one source: the error messages and the test that reads the template's
   comments take them from the schema.
2. What needs the robot: the robot file, ``[limits]`` (one finite, ordered pair per joint, inside
   the robot's limits), the parameter names of ``prefer``/``fix``/``exclude``, and the correction
   grid (whole number of steps, the controller's capacity for this robot's joints).

Every failure is a :class:`ConfigError` (exit code 2); a malformed file never gives a traceback.

This module holds the validated configuration (:class:`CellConfig`), stage 2 and the loading; the
sections' dataclasses are :mod:`station.cell.config.sections`, the template
:mod:`station.cell.config.template`. Their names stay importable from here.
"""

from __future__ import annotations

import dataclasses
import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import ValidationError

# The schema's names stay importable from here (tests and tools read the schema through this
# module); the loading below uses only a few of them.
from drivers.controller_map import MAX_TABLE_VALUES
from station.cell.config.schema import (
    _Body,
    _Conformance,
    _describe,
    _short,
    _Simulation,
    _Tool,
    _validate_schema,
)
from station.cell.config.sections import (
    CellIdentity,
    ConformanceConfig,
    CorrectionConfig,
    DeviceConfig,
    FleetConfig,
    IdentificationConfig,
    ObstacleConfig,
    PlanConfig,
    RecheckConfig,
    ToolConfig,
    VerificationConfig,
    WarmupConfig,
)
from station.core.kinematics.model import RobotModel
from station.core.kinematics.transforms import pose_to_matrix
from station.core.table.grid import GridSpec
from station.core.units import ARCSEC, DEG, UM
from station.errors import ConfigError
from station.io.certificate import Certificate
from station.io.robot.files import load_robot, read_user_text

#: a configuration file larger than this is refused before it is read (a real one is a few kB;
#: a body of 5 000 points is ~0.5 MB)
MAX_CONFIG_BYTES = 4 * 1024 * 1024



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
    obstacles: tuple[ObstacleConfig, ...] = ()  # the cell's fixed obstacles ([[obstacle]], issue 40)
    robot_collision: Any = None  # the robot file's [collision] (station.io.robot.collision.CollisionSpec)
    simulation: Any = None  # the validated [simulation] table (what --simulated CONFIG simulates)
    source: str = ""  # the file it was read from (or a label such as "<simulated cell>")
    verification: VerificationConfig = VerificationConfig()  # [verification]: the report's specification
    identity: CellIdentity = CellIdentity()  # [cell] robot_serial, controller, operator (the report's)
    head_certificate: Certificate = Certificate()  # the [head] file's CMM certificate (empty: none given)
    body_certificate: Certificate = Certificate()  # the [body] file's CMM certificate (empty: none given)
    fleet: FleetConfig = FleetConfig()  # [fleet]: the plant's fleet store (issue 31)


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


def _body_points(b: _Body, source: str) -> tuple[tuple[str, ...], np.ndarray, np.ndarray, Certificate]:
    """ids, ``(n, 6)`` poses [mm, rad] and ``(n, 2)`` σ [mm, rad] of the body's measuring points,
    and the CMM certificate the file names: from ``[body] file`` (the CMM report, relative to the
    configuration file) or inline (no certificate); a point without σ takes ``default_sigma_*``."""
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
        return report.ids, np.array(report.poses), report.sigma_with_default(*default), report.certificate
    assert b.points is not None  # the schema allows exactly one of the two
    ids = tuple(pt.id for pt in b.points)
    poses = np.array([_pose_deg(pt.pose) for pt in b.points])
    sigma = np.array([[default[0] if pt.sigma_position_um is None else pt.sigma_position_um * UM,
                       default[1] if pt.sigma_angle_arcsec is None else pt.sigma_angle_arcsec * ARCSEC]
                      for pt in b.points])
    return ids, poses, sigma, Certificate()


def _head(file: str | None, cube_edge_mm: float, model: RobotModel,
          source: str) -> tuple[Any, np.ndarray, RobotModel, Certificate]:
    """``[head] file``: the head's geometry, MKKS in the flange (4,4), the robot model with the
    head frame as its nominal K, and the head's CMM certificate. Without it: the built-in
    reference head on the robot file's K (no certificate)."""
    from station.core.probe.geometry import default_probe_head
    from station.io.head_file import load_head

    if file is None:
        return default_probe_head(cube_edge_mm=cube_edge_mm), pose_to_matrix(model.nominal[-6:]), model, Certificate()
    path = file if Path(file).is_absolute() else str(Path(source).parent / file)
    try:
        h = load_head(path, cube_edge_mm)
    except ConfigError as exc:
        raise ConfigError(f"{source}: head.file: {exc}") from None
    return h.geometry, h.frame_in_flange, model.with_tool(h.frame_pose), h.certificate


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
    """The configured (explicit) correction grid (robot base frame) for the given plan elbows."""
    c = correction
    if c.x_mm is None or c.y_mm is None or c.z_mm is None:
        raise ConfigError("correction: the grid is designed by the station (no x_mm, y_mm, z_mm given)")
    return GridSpec(x_range=(c.x_mm[0], c.x_mm[1]), x_step=c.x_mm[2], y_range=(c.y_mm[0], c.y_mm[1]),
                    y_step=c.y_mm[2], z_range=(c.z_mm[0], c.z_mm[1]), z_step=c.z_mm[2],
                    yaw_step=float(np.deg2rad(c.yaw_step_deg or DEFAULT_YAW_STEP_DEG)), elbows=tuple(elbows))

DEFAULT_YAW_STEP_DEG = 30.0  # the yaw step of an explicit grid that gives none [deg]

_GRID_KEY = {"x": "correction.x_mm", "y": "correction.y_mm", "z": "correction.z_mm", "yaw": "correction.yaw_step_deg"}


def _check_grid(corr: CorrectionConfig, elbows: tuple[int, ...], n_joints: int, source: str) -> None:
    """The grid's ranges and steps and the controller's capacity, before anything moves (the
    same :class:`GridSpec` the pipeline builds the table on)."""
    yaw, n = corr.yaw_step_deg, 360.0 / (corr.yaw_step_deg or 30.0)
    if yaw is not None and abs(n - round(n)) > 1e-9 * n:
        steps = [360.0 / k for k in range(2, 361) if (3600 % k) == 0]  # divisors to 0.1 deg
        lower, upper = max((v for v in steps if v < yaw), default=1.0), min((v for v in steps if v > yaw), default=180.0)
        raise ConfigError(f"{source}: correction.yaw_step_deg = {yaw:g}: must divide 360 deg ({n:.4g} steps); "
                          f"use e.g. {lower:g} or {upper:g}")
    if not corr.explicit:  # designed: checked with the plan, before the first motion (design.py)
        return
    for key in ("x_mm", "y_mm", "z_mm"):
        lo, hi, step = getattr(corr, key)
        if not hi > lo:
            raise ConfigError(f"{source}: correction.{key} = [{lo:g}, {hi:g}, {step:g}]: [start, stop, step] needs "
                              f"stop > start")
    try:
        correction_grid(corr, elbows).check_capacity(n_joints, MAX_TABLE_VALUES)
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
                             yaw_step_deg=corr.yaw_step_deg, max_interpolation_um=corr.max_interpolation_um,
                             region=corr.region)
        if c != corr and c.explicit:  # else its missing axes come from the head's designed grid (tools.py)
            _check_grid(c, elbows, n_joints, f"{source}: tool {t.name!r} (its x_mm, y_mm, z_mm replace [correction]'s)")
        out.append(ToolConfig(t.name, _pose_deg(t.tcp), c))
    return tuple(out)


def _probe_line(d: Any, source: str) -> Any:
    """The probe port's line settings: the file's, each absent one the dialect's factory default,
    refused (naming what the unit offers) where the dialect's unit does not offer them."""
    from drivers.probe_dialects import check_line_settings
    from drivers.probe_protocol import ProbeConfigError

    try:
        return check_line_settings(d.probe_protocol, d.baudrate, d.probe_bytesize, d.probe_parity)
    except ProbeConfigError as exc:
        raise ConfigError(f"{source}: [devices]: {exc}") from None


def _check_terms(ident: IdentificationConfig, model: RobotModel, source: str, robot_file: str,
                 both_directions: bool = False) -> IdentificationConfig:
    """``[identification] model``: the error terms beyond geometry are fitted to poses (an
    articulated arm's compensated targets and a SCARA's correction table carry them). With terms,
    the robot file's ``[gravity]`` and ``[gears]`` (TOML; docs/error-terms.md) join it. A SCARA's
    compliance is refused when named: gravity along its vertical axes loads none of them.
    ``backlash`` named needs the plan to approach every pose from both sides
    (``both_directions``): from one side the lost motion merges with the joint zeros."""
    if ident.terms == ("geometric",):
        return ident
    where = f"{source}: identification.model = {ident.model!r}"
    if ident.objective != "pose":
        raise ConfigError(f"{where}: the error terms are fitted to poses; the distance objective (distances between "
                          f"measured points, robot only) is fitted geometric only, the terms are not identified "
                          f"from it. Write objective = \"pose\" or model = \"geometric\"")
    if "backlash" in ident.terms and not both_directions:
        raise ConfigError(f"{where}: backlash (lost motion) is identified where the data show each joint arriving "
                          f"from both sides, and the plan approaches every pose from one side; set [plan] "
                          f"both_directions = true (a SCARA: every identification pose is then also measured from "
                          f"the other side), or leave backlash out (model = \"auto\" tries it only then)")
    if ident.terms != ("auto",):
        from station.core.terms.selection import expand_families

        try:  # backlash (checked above) takes the session's approach sides (pipeline_results.run_term_rows)
            expand_families(model, tuple(t for t in ident.terms if t != "backlash"))
        except ConfigError as exc:
            raise ConfigError(f"{where}: {exc}") from None
    from station.io.robot.terms import read_gear_ratios, read_gravity

    gravity = read_gravity(robot_file, model.n_joints)
    if model.is_scara and "compliance" in ident.terms:
        g = (0.0, 0.0, -1.0) if gravity is None else gravity.gravity
        if math.hypot(g[0], g[1]) <= 1e-6 * math.hypot(*g):
            raise ConfigError(f"{where}: a SCARA's compliance is not identifiable: its joints 1, 2 and 4 turn about "
                              f"vertical axes, so gravity puts no torque on them, and the quill carries the same "
                              f"load in every pose, so its give merges with its zero. Leave compliance out "
                              f"(e.g. model = \"cyclic\" or \"auto\")")
    return dataclasses.replace(ident, gravity=gravity, gear_ratios=read_gear_ratios(robot_file, model.n_joints))


def parse_config(data: dict, source: str = "<config>", text: str = "") -> CellConfig:
    """A validated :class:`CellConfig` from parsed TOML; :class:`ConfigError` names the key."""
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: a configuration is a TOML document of tables, got {type(data).__name__}")
    f = _validate_schema(data, source)

    model = load_robot(_robot_path(f.robot.model, source)).with_setup(_pose_deg(f.robot.setup))
    head, head_in_flange, model, head_cert = _head(f.head.file, f.body.cube_edge_mm, model, source)  # [head]
    soft = _soft_limits(f.limits.joints, model, source)

    d = f.devices
    host, _, port = d.controller.rpartition(":")
    line = _probe_line(d, source)
    devices = DeviceConfig(
        probe_head=d.probe_head, baudrate=line.baudrate, probe_timeout_s=d.probe_timeout_s,
        controller_host=host, controller_port=int(port), device_id=d.device_id, word_order=d.word_order,
        controller_timeout_s=d.controller_timeout_s, motion_timeout_s=d.motion_timeout_s,
        probe_protocol=d.probe_protocol, probe_bytesize=line.bytesize, probe_parity=line.parity,
        controller_register_base=d.controller_register_base,
        probe_refresh_s=None if d.probe_refresh_ms is None else d.probe_refresh_ms / 1000.0,
        controller_link_timeout_s=d.controller_link_timeout_s)
    p = f.plan
    plan = PlanConfig(
        elbows=tuple(p.elbows), approach_deg=p.approach_deg, approach_mm=p.approach_mm,
        clearance_mm=p.clearance_mm, speed=p.speed, settle_s=p.settle_s, samples=p.samples,
        max_spread_um=p.max_spread_um, both_directions=p.both_directions,
        verification_every=p.verification_every, verification_cycles=p.verification_cycles,
        select=p.select, repeats=p.repeats, recenter_attempts=p.recenter_attempts,
        recenter_margin_mm=p.recenter_margin_mm, max_residual_um=p.max_residual_um,
        remeasure_attempts=p.remeasure_attempts, setup_uncertainty_mm=f.robot.setup_uncertainty_mm,
        locate_steps=p.locate_steps, collision_margin_mm=p.collision_margin_mm)

    i = f.identification
    ident = IdentificationConfig(
        objective=i.objective, sigma_position_um=i.sigma_position_um,
        sigma_angle_arcsec=i.sigma_angle_arcsec,
        prefer=tuple(model.prefer if i.prefer is None else i.prefer), fix=tuple(i.fix), exclude=tuple(i.exclude),
        model=i.model.strip(), repeatability_mm=model.repeatability_mm)
    ident = _check_terms(ident, model, source, _robot_path(f.robot.model, source), plan.both_directions)
    for key in ("prefer", "fix", "exclude"):
        for n in getattr(ident, key):
            try:
                model.param_index(n)
            except ConfigError as exc:
                raise ConfigError(f"{source}: identification.{key}: {exc}") from None

    c = f.correction
    corr = CorrectionConfig(x_mm=c.x_mm, y_mm=c.y_mm, z_mm=c.z_mm, yaw_step_deg=DEFAULT_YAW_STEP_DEG
                            if c.x_mm is not None and c.yaw_step_deg is None else c.yaw_step_deg,
                            max_interpolation_um=c.max_interpolation_um,
                            region=None if c.region is None else (c.region.x_mm, c.region.y_mm, c.region.z_mm))
    if model.is_scara:  # an articulated arm gets compensated targets, not a table (issue 9)
        _check_grid(corr, plan.elbows, model.n_joints, source)

    ids, poses, body_sigma, body_cert = _body_points(f.body, source)
    r, w = f.recheck, f.warmup
    recheck = RecheckConfig(poses=r.poses, tolerance_um=r.tolerance_um, offset_tolerance_arcsec=r.offset_tolerance_arcsec,
                            length_tolerance_um=r.length_tolerance_um, repeat_tolerance_um=r.repeat_tolerance_um)
    warmup = (WarmupConfig(until=w.until, minutes=w.minutes, max_cycles=w.max_cycles, converged_um=w.converged_um,
                           program_poses=w.program_poses) if w.enabled else None)
    sim = f.simulation
    if sim.step_joint > model.n_joints:
        raise ConfigError(f"{source}: simulation.step_joint = {sim.step_joint}: the robot has {model.n_joints} joints")
    if sim.joint_backlash_um is not None and len(sim.joint_backlash_um) != model.n_joints:
        raise ConfigError(f"{source}: simulation.joint_backlash_um has {len(sim.joint_backlash_um)} values: give one "
                          f"per joint of the robot ({model.n_joints})")
    from station.io.robot.collision import read_collision

    links = tuple(t.name for t in model.transforms if t.joint is not None or t is model.transforms[0])
    robot_collision = read_collision(_robot_path(f.robot.model, source), links)
    return CellConfig(
        f.cell.name, model, soft, ids, pose_to_matrix(poses), f.body.cube_edge_mm,
        devices, plan, ident, corr, text, f.simulation.seed, recheck, warmup,
        conformance=_conformance(f.conformance, model, soft, source),
        head=head,  # ProbeHeadGeometry of the [head] file, or the built-in reference head
        head_in_flange=head_in_flange,  # (4,4) MKKS in the flange frame (the robot model's nominal K)
        body_sigma=body_sigma,  # (n, 2) [mm, rad] from the CMM report or the inline points (0: exact)
        tools=_tools(f.tool, corr, plan.elbows, model.n_joints, source),  # [[tool]] (station/cell/correction/robot_tools.py)
        obstacles=tuple(ObstacleConfig(o.name, o.shape, o.frame, pose_to_matrix(_pose_deg(o.pose)),
                                       tuple(float(v) for v in (o.size_mm or (o.radius_mm, o.height_mm)) if v is not None))
                       for o in f.obstacle),
        robot_collision=robot_collision,  # the links' capsules (station/cell/plan/collision.py)
        simulation=f.simulation,  # the validated [simulation] table (simulators/from_config.py reads it)
        source=source,  # where it was read: relative robot, head and body files resolve beside it
        verification=VerificationConfig(**f.verification.model_dump()),  # [verification] (the report's)
        identity=CellIdentity(f.cell.robot_serial or "", f.cell.controller or "", f.cell.operator or ""),
        head_certificate=head_cert, body_certificate=body_cert,  # the CMM certificates, for the report
        fleet=FleetConfig(f.fleet.url, f.fleet.station, r.interval_days or f.fleet.recheck_interval_days),
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


__all__ = [
    "MAX_CONFIG_BYTES", "CellConfig", "correction_grid", "parse_config", "simulation_settings", "load_config",
    "parse_text",
]
