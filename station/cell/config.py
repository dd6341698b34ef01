"""Cell configuration (TOML): robot, calibration body, probe head, devices, limits, plan,
identification and correction settings. ``station init`` writes :data:`TEMPLATE`.

Validation names the key and the fix. Inside, everything is mm and rad; the file holds degrees
where people write angles (keys ending in ``_deg``), µm and arc seconds for uncertainties.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from station.core.model import RobotModel
from station.core.transforms import pose_to_matrix
from station.core.units import ARCSEC, DEG
from station.errors import ConfigError
from station.io.robot_files import load_robot


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


def _get(d: dict, key: str, path: str, kind, default=None, required=False):
    if key not in d:
        if required:
            raise ConfigError(f"{path}.{key} is missing; add it (see 'station init' for the template)")
        return default
    v = d[key]
    if kind is float and isinstance(v, int) and not isinstance(v, bool):
        v = float(v)
    if not isinstance(v, kind) or (kind is float and not math.isfinite(v)):
        raise ConfigError(f"{path}.{key} = {v!r}: expected {getattr(kind, '__name__', kind)}")
    return v


def _vec(d, key, path, n, default=None):
    v = d.get(key, default)
    if v is None:
        raise ConfigError(f"{path}.{key} is missing; add it as a list of {n} numbers")
    if not (isinstance(v, list) and len(v) == n and all(isinstance(x, (int, float)) and math.isfinite(x) for x in v)):
        raise ConfigError(f"{path}.{key} must be a list of {n} finite numbers, got {v!r}")
    return [float(x) for x in v]


def _check_keys(d: dict, allowed: set, path: str):
    unknown = set(d) - allowed
    if unknown:
        raise ConfigError(f"{path}: unknown key(s) {sorted(unknown)}; allowed: {sorted(allowed)}")


def _pose_deg(v) -> np.ndarray:
    return np.array(v[:3] + [a * DEG for a in v[3:]])


def parse_config(data: dict, source: str = "<config>", text: str = "") -> CellConfig:
    _check_keys(data, {"cell", "robot", "body", "devices", "limits", "plan", "identification",
                       "correction", "simulation"}, source)
    cell = data.get("cell", {})
    _check_keys(cell, {"name"}, "cell")
    name = _get(cell, "name", "cell", str, "calibration cell")

    rob = data.get("robot")
    if not isinstance(rob, dict):
        raise ConfigError(f"{source}: [robot] table missing; add model = \"sr800\" (or a robot file)")
    _check_keys(rob, {"model", "setup"}, "robot")
    model_name = _get(rob, "model", "robot", str, required=True)
    if not Path(model_name).is_absolute() and Path(source).parent.joinpath(model_name).exists():
        model_name = str(Path(source).parent / model_name)
    model = load_robot(model_name)
    setup = _vec(rob, "setup", "robot", 6, [0.0] * 6)
    model = model.with_setup(_pose_deg(setup))

    lim = data.get("limits", {})
    _check_keys(lim, {"joints"}, "limits")
    if "joints" in lim:
        raw = lim["joints"]
        if not (isinstance(raw, list) and len(raw) == model.n_joints and all(isinstance(r, list) and len(r) == 2 for r in raw)):
            raise ConfigError(f"limits.joints must list [lower, upper] for each of the {model.n_joints} joints (deg for revolute, mm for prismatic)")
        soft = np.array([[float(a), float(b)] for a, b in raw])
        for j, kind in enumerate(model.joint_types):
            if kind == "revolute":
                soft[j] *= DEG
        if np.any(soft[:, 0] >= soft[:, 1]):
            raise ConfigError("limits.joints: every joint needs lower < upper")
        outside = (soft[:, 0] < model.joint_limits[:, 0] - 1e-9) | (soft[:, 1] > model.joint_limits[:, 1] + 1e-9)
        if np.any(outside):
            j = int(np.argmax(outside)) + 1
            raise ConfigError(f"limits.joints: joint {j}'s soft limits exceed the robot's limits; narrow them")
    else:
        soft = np.array(model.joint_limits)

    body = data.get("body")
    if not isinstance(body, dict):
        raise ConfigError(f"{source}: [body] table missing; list the measuring points from the CMM report")
    _check_keys(body, {"cube_edge_mm", "points"}, "body")
    edge = _get(body, "cube_edge_mm", "body", float, 40.0)
    pts = body.get("points")
    if not isinstance(pts, list) or len(pts) < 3:
        raise ConfigError("body.points needs at least 3 measuring points: { id = \"C1.a\", pose = [x, y, z, roll, pitch, yaw] } in mm and deg")
    ids, poses = [], []
    for k, p in enumerate(pts):
        if not isinstance(p, dict) or "id" not in p or "pose" not in p:
            raise ConfigError(f"body.points[{k}] needs an id and a pose = [x, y, z, roll, pitch, yaw] (mm, deg)")
        ids.append(str(p["id"]))
        poses.append(_pose_deg(_vec(p, "pose", f"body.points[{k}]", 6)))
    if len(set(ids)) != len(ids):
        raise ConfigError("body.points: ids must be unique")

    dev = data.get("devices", {})
    _check_keys(dev, {"probe_head", "baudrate", "probe_timeout_s", "controller", "device_id",
                      "word_order", "controller_timeout_s", "motion_timeout_s"}, "devices")
    ctrl = _get(dev, "controller", "devices", str, "127.0.0.1:502")
    host, _, port = ctrl.rpartition(":")
    if not host or not port.isdigit():
        raise ConfigError(f"devices.controller = {ctrl!r}: write it as host:port, e.g. \"192.168.0.10:502\"")
    wo = _get(dev, "word_order", "devices", str, "big")
    if wo not in ("big", "little"):
        raise ConfigError("devices.word_order must be \"big\" or \"little\" (how the controller orders 32-bit words)")
    baud = _get(dev, "baudrate", "devices", int, 38400)
    if baud not in (9600, 19200, 38400, 57600, 115200):
        raise ConfigError(f"devices.baudrate = {baud}: use the rate set on the probe unit (9600 … 115200)")
    devices = DeviceConfig(
        probe_head=_get(dev, "probe_head", "devices", str, "/dev/ttyUSB0"), baudrate=baud,
        probe_timeout_s=_get(dev, "probe_timeout_s", "devices", float, 0.5),
        controller_host=host, controller_port=int(port),
        device_id=_get(dev, "device_id", "devices", int, 1), word_order=wo,
        controller_timeout_s=_get(dev, "controller_timeout_s", "devices", float, 1.0),
        motion_timeout_s=_get(dev, "motion_timeout_s", "devices", float, 60.0))

    pl = data.get("plan", {})
    allowed = {f.name for f in PlanConfig.__dataclass_fields__.values()}
    _check_keys(pl, allowed, "plan")
    elbows = tuple(pl.get("elbows", [1, -1]))
    if not elbows or any(e not in (1, -1) for e in elbows):
        raise ConfigError("plan.elbows must list +1 and/or -1")
    plan = PlanConfig(
        elbows=elbows,
        approach_deg=_get(pl, "approach_deg", "plan", float, 0.5),
        approach_mm=_get(pl, "approach_mm", "plan", float, 1.0),
        clearance_mm=_get(pl, "clearance_mm", "plan", float, 20.0),
        speed=_get(pl, "speed", "plan", float, 0.5),
        settle_s=_get(pl, "settle_s", "plan", float, 0.2),
        samples=_get(pl, "samples", "plan", int, 4),
        max_spread_um=_get(pl, "max_spread_um", "plan", float, 10.0),
        both_directions=_get(pl, "both_directions", "plan", bool, False),
        verification_every=_get(pl, "verification_every", "plan", int, 4),
        verification_cycles=_get(pl, "verification_cycles", "plan", int, 3),
        select=_get(pl, "select", "plan", int, 0),
        repeats=_get(pl, "repeats", "plan", int, 2),
        recenter_attempts=_get(pl, "recenter_attempts", "plan", int, 2),
        recenter_margin_mm=_get(pl, "recenter_margin_mm", "plan", float, 1.5),
        max_residual_um=_get(pl, "max_residual_um", "plan", float, 10.0),
    )
    if not 0 < plan.speed <= 1:
        raise ConfigError("plan.speed is a fraction of the maximum speed: 0 < speed <= 1")
    if plan.samples < 1 or plan.verification_cycles < 1 or plan.verification_every < 2 or plan.repeats < 1:
        raise ConfigError("plan.samples, plan.repeats and plan.verification_cycles must be >= 1, "
                          "plan.verification_every >= 2")
    if plan.approach_deg <= 0 or plan.approach_mm <= 0 or plan.clearance_mm <= 0:
        raise ConfigError("plan.approach_deg, plan.approach_mm and plan.clearance_mm must be > 0")

    idc = data.get("identification", {})
    _check_keys(idc, {"objective", "sigma_position_um", "sigma_angle_arcsec", "prefer", "fix", "exclude"}, "identification")
    obj = _get(idc, "objective", "identification", str, "pose")
    if obj not in ("pose", "distance"):
        raise ConfigError("identification.objective must be \"pose\" or \"distance\"")
    ident = IdentificationConfig(
        objective=obj,
        sigma_position_um=_get(idc, "sigma_position_um", "identification", float, 15.0),
        sigma_angle_arcsec=_get(idc, "sigma_angle_arcsec", "identification", float, 20.0),
        prefer=tuple(idc.get("prefer", model.prefer)), fix=tuple(idc.get("fix", ())),
        exclude=tuple(idc.get("exclude", ())))
    for n in (*ident.prefer, *ident.fix, *ident.exclude):
        model.param_index(n)

    co = data.get("correction", {})
    _check_keys(co, {"x_mm", "y_mm", "z_mm", "yaw_step_deg", "max_interpolation_um"}, "correction")
    corr = CorrectionConfig(
        x_mm=tuple(_vec(co, "x_mm", "correction", 3, [250.0, 650.0, 40.0])),
        y_mm=tuple(_vec(co, "y_mm", "correction", 3, [-350.0, 350.0, 50.0])),
        z_mm=tuple(_vec(co, "z_mm", "correction", 3, [250.0, 450.0, 200.0])),
        yaw_step_deg=_get(co, "yaw_step_deg", "correction", float, 30.0),
        max_interpolation_um=_get(co, "max_interpolation_um", "correction", float, 15.0))
    for key in ("x_mm", "y_mm", "z_mm"):
        lo, hi, step = getattr(corr, key)
        if not (hi > lo and step > 0):
            raise ConfigError(f"correction.{key} = [start, stop, step] needs stop > start and step > 0")

    sim = data.get("simulation", {})
    _check_keys(sim, {"seed"}, "simulation")
    seed = _get(sim, "seed", "simulation", int, None)
    return CellConfig(name, model, soft, tuple(ids), pose_to_matrix(np.array(poses)), edge, devices,
                      plan, ident, corr, text, seed)


def load_config(path: str | Path) -> CellConfig:
    p = Path(path)
    if not p.exists():
        raise ConfigError(f"{p}: no such configuration file; 'station init {p}' writes a template")
    text = p.read_text(encoding="utf-8")
    return parse_text(text, str(p))


def parse_text(text: str, source: str = "<config>") -> CellConfig:
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{source}: not valid TOML ({exc}); fix the syntax there") from None
    return parse_config(data, source, text)


TEMPLATE = """\
# Calibration cell configuration. Lengths in mm, angles in degrees, uncertainties in µm and
# arc seconds. 'station check THIS_FILE' connects to every device and reports what works.

[cell]
name = "cell 1"

[robot]
model = "sr800"                  # built-in robot or a robot file (docs/robot-file.md)
# Nominal pose of the robot base in the calibration-body frame: x, y, z [mm], roll, pitch, yaw [deg].
# It only has to be right to a few mm / a few tenths of a degree; the calibration identifies it.
setup = [-450.0, 0.0, -170.0, 0.0, 0.0, 0.0]

[limits]
# Soft limits the station never commands a motion beyond: [lower, upper] per joint (deg | mm).
joints = [[-125.0, 125.0], [-140.0, 140.0], [-195.0, -5.0], [-355.0, 355.0]]

[body]
cube_edge_mm = 40.0
# Measuring points (cube corners) from the body's CMM report: pose of each corner frame in the
# body frame, x, y, z [mm], roll, pitch, yaw [deg]. Corner frame: origin at the top corner, cube in x>=0, y>=0, z<=0.
points = [
  { id = "C1.a", pose = [-28.3, -319.7, 40.0, 0.0, 0.0, 10.0] },
  { id = "C1.b", pose = [11.1, -312.8, 40.0, 0.0, 0.0, 100.0] },
  { id = "C1.c", pose = [4.1, -273.4, 40.0, 0.0, 0.0, 190.0] },
]

[devices]
probe_head = "/dev/ttyUSB0"      # serial device, or socket://host:port, rfc2217://host:port
baudrate = 38400
probe_timeout_s = 0.5
controller = "192.168.0.10:502"  # Modbus TCP host:port
device_id = 1
word_order = "big"               # 32-bit word order of the controller: "big" or "little"
controller_timeout_s = 1.0
motion_timeout_s = 60.0

[plan]
elbows = [1, -1]                 # elbow configurations to measure every point in
approach_deg = 0.5               # every joint approaches its target from below by this much
approach_mm = 1.0
clearance_mm = 20.0              # retract height above a measuring point before moving on
speed = 0.5                      # fraction of the robot's maximum speed
settle_s = 0.2                   # wait after a motion before reading the probes
samples = 4                      # probe snapshots averaged per reading
max_spread_um = 10.0             # reject a reading whose snapshots spread more than this
both_directions = false          # also approach from above to measure the reversal error
verification_every = 4           # every 4th (point, elbow) is held out for verification
verification_cycles = 3          # ISO 9283 repetitions per verification pose
select = 0                       # > 0: keep only this many most informative steps (D-optimal)
repeats = 2                      # visits per identification pose (robot repeatability averages out)
recenter_attempts = 2            # re-centre when a probe is near the end of its stroke
recenter_margin_mm = 1.5
max_residual_um = 10.0           # plane residual above which a reading is not valid

[identification]
objective = "pose"               # "pose" (robot + set-up + head) or "distance" (robot only)
sigma_position_um = 15.0
sigma_angle_arcsec = 20.0
# prefer = ["K.x", ...]          # minimal-set preferences; default: the robot file's
# fix = []
# exclude = []

[correction]
# Grid of the correction table in the robot base frame: [start, stop, step].
x_mm = [250.0, 650.0, 40.0]
y_mm = [-350.0, 350.0, 50.0]
z_mm = [250.0, 450.0, 200.0]
yaw_step_deg = 30.0
max_interpolation_um = 15.0      # refuse a table whose interpolation bound exceeds this
"""
