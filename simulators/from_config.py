"""Rehearse a cell: the simulated cell that a cell configuration describes (issue 8, point 4).

:func:`simulate_config` starts the simulators on the user's own cell, from the validated
configuration the station itself reads (``station.cell.config.cell_config.CellConfig``):

* the true robot: the configuration's robot (its robot file with the configured nominal set-up)
  plus seeded errors of the ``[simulation]`` magnitudes (:class:`SimulationPhysics`);
* the body: the configuration's nominal measuring points (its CMM report) plus seeded true
  deviations, σ per point and component (position, angle) from the CMM report where it states one
  (``cfg.body_sigma`` > 0), else the ``[simulation]`` default (a real body is never exact);
* the probe head: the configured head (``cfg.head``), else the default 3-2-1 head for the cube edge;
  its reading noise ``[simulation].probe_noise_um`` when the file sets it, else the head's stated
  ``reading_sigma_mm`` (its certificate), else 0.5 µm;
* the controller: the configured word order, and ``[limits]`` as its soft limits; unless
  ``[simulation] collision_check = false``, its own collision check of every motion
  (:mod:`simulators.collision_check`);
* drift (thermal model, step change) from the ``[simulation]`` keys of :mod:`simulators.thermal`.

It returns the running servers and the station's configuration for them: the user's, with only
``[devices]`` pointing at the simulators (and ``[simulation].seed`` the seed simulated, so that a
run's fingerprint names it). The oracle is ``servers.cell.truth``.

The simulators do not import the station's cell layer (import-linter): ``cfg`` is read by its
attributes. Units: the ``[simulation]`` keys as people write them (µm, arc seconds, degrees);
mm and rad inside.
"""

from __future__ import annotations

import dataclasses
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w

from drivers.controller_map import WordOrder
from simulators import SimulatedCellServers, start_simulated_cell
from simulators.cell import CalibrationBody, CellTruth, SimulatedCell
from station.core.units import ARCSEC

__all__ = ["SimulationPhysics", "DRIFT_KEYS", "SETUP_ERROR_KEYS", "setup_error_vector", "Rehearsal", "simulated_cell_for", "simulate_config",
           "station_config_text", "effective_seed", "toml_text", "DEFAULT_SEED", "SIMULATOR_PROBE_TIMEOUT_S"]

#: the ``[simulation]`` keys of the drift models (``simulators/thermal.py``)
DRIFT_KEYS = ("thermal_length_um", "thermal_offset_arcsec", "thermal_time_constant_s", "step_joint",
              "step_offset_deg", "step_tool_um")

#: the seed of a rehearsal when neither the command line nor ``[simulation].seed`` gives one
#: (the station's ``--seed`` default)
DEFAULT_SEED = 1

#: the simulators share the CPU with the station: a loaded machine must not turn into probe
#: timeouts, whose retries make a run stop reproducing (the built-in cell's value)
SIMULATOR_PROBE_TIMEOUT_S = 2.0
#: the same for the controller's replies and its heartbeat: [devices] controller_timeout_s and
#: controller_link_timeout_s of a simulated cell are at least this [s]
SIMULATOR_CONTROLLER_DEADLINE_S = 5.0


@dataclass(frozen=True)
class SimulationPhysics:
    """The true errors' magnitudes and the physics of a simulated cell, in the units of the
    ``[simulation]`` keys of the same names. The defaults are the built-in cell's (a realistic
    SCARA of the 800 mm class, a body from a CMM report, a head of 0.5 µm probes)."""

    length_sigma_um: float = 40.0  # σ of the true errors of the lengths (arms, head K)
    angle_sigma_arcsec: float = 150.0  # σ of the true errors of the angles (2.5′)
    setup_sigma_mm: float = 1.5  # σ of the set-up R in x, y, z
    setup_yaw_sigma_deg: float = 0.2
    setup_tilt_sigma_deg: float = 0.03
    repeatability_um: float = 5.0  # revolute: at lever_mm
    backlash_um: float = 100.0  # revolute: at lever_mm
    prismatic_backlash_um: float = 20.0
    lever_mm: float = 450.0
    probe_noise_um: float = 0.5
    body_position_sigma_um: float = 2.0
    body_angle_sigma_arcsec: float = 3.0
    capture_mm: float = 8.0
    capture_angle_deg: float = 10.0
    offset_sigma_arcsec: float | None = None  # the revolute joints' encoder offsets; None: angle_sigma_arcsec
    tilt_sigma_arcsec: float | None = None  # the axis tilts (roll, pitch); None: angle_sigma_arcsec
    joint_backlash_um: tuple[float, ...] | None = None  # per joint (revolute at lever_mm); None: the two above
    # the set-up's error planted exactly ({x_mm, y_mm, z_mm, roll_deg, pitch_deg, yaw_deg}, a key left
    # out 0); None: drawn with the three setup σ above
    setup_error: Mapping[str, float] | None = None

    @classmethod
    def from_settings(cls, settings: Mapping[str, Any] | None) -> "SimulationPhysics":
        """From a ``[simulation]`` table (other keys, the seed and the drift, are ignored; a key
        set to None keeps its default)."""
        names = {f.name for f in fields(cls)}
        kw: dict[str, Any] = {}
        for k, v in (settings or {}).items():
            if k not in names or v is None:
                continue
            if k == "joint_backlash_um":
                kw[k] = tuple(float(x) for x in v)
            elif k == "setup_error":
                kw[k] = _setup_error_table(v)
            else:
                kw[k] = float(v)
        return cls(**kw)

    def truth_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of :meth:`CellTruth.generate` (mm, rad)."""
        return {"length_sigma_mm": self.length_sigma_um / 1000.0,
                "angle_sigma_rad": self.angle_sigma_arcsec * ARCSEC,
                "setup_sigma_mm": self.setup_sigma_mm,
                "setup_yaw_sigma_rad": float(np.deg2rad(self.setup_yaw_sigma_deg)),
                "setup_tilt_sigma_rad": float(np.deg2rad(self.setup_tilt_sigma_deg)),
                "repeatability_mm": self.repeatability_um / 1000.0,
                "backlash_mm": self.backlash_um / 1000.0,
                "prismatic_backlash_mm": self.prismatic_backlash_um / 1000.0,
                "lever_mm": self.lever_mm,
                "offset_sigma_rad": None if self.offset_sigma_arcsec is None else self.offset_sigma_arcsec * ARCSEC,
                "tilt_sigma_rad": None if self.tilt_sigma_arcsec is None else self.tilt_sigma_arcsec * ARCSEC,
                "joint_backlash_mm": (None if self.joint_backlash_um is None
                                      else np.asarray(self.joint_backlash_um, dtype=float) / 1000.0),
                "setup_error": None if self.setup_error is None else setup_error_vector(self.setup_error)}

    def prior_sigma(self, model: Any) -> np.ndarray:
        """σ (n_params,) [mm, rad] of every parameter's true error as :meth:`CellTruth.generate`
        draws it with these magnitudes: the size a robot's error is expected to have."""
        k = self.truth_kwargs()
        sig = np.empty((model.n_params // 6, 6))
        sig[:, :3] = k["length_sigma_mm"]
        sig[:, 3:] = k["angle_sigma_rad"]
        if k["tilt_sigma_rad"] is not None:
            sig[:, 3:5] = k["tilt_sigma_rad"]
        if k["offset_sigma_rad"] is not None:
            for t, kind in zip(model.joint_transforms, model.joint_types):
                if kind == "revolute":
                    sig[t, 5] = k["offset_sigma_rad"]
        sig[0] = [k["setup_sigma_mm"]] * 3 + [k["setup_tilt_sigma_rad"]] * 2 + [k["setup_yaw_sigma_rad"]]
        return sig.ravel()

    def body_sigma(self) -> tuple[float, float]:
        """σ of a body point's true deviation: position [mm], angle [rad]."""
        return self.body_position_sigma_um / 1000.0, self.body_angle_sigma_arcsec * ARCSEC

    def cell_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of :class:`SimulatedCell` (mm, rad)."""
        return {"capture_mm": self.capture_mm, "capture_angle_rad": float(np.deg2rad(self.capture_angle_deg)),
                "probe_noise_mm": self.probe_noise_um / 1000.0}


#: the components of ``[simulation] setup_error`` in the order of a pose (x, y, z, roll, pitch, yaw)
SETUP_ERROR_KEYS = ("x_mm", "y_mm", "z_mm", "roll_deg", "pitch_deg", "yaw_deg")


def _setup_error_table(value: Mapping[str, Any]) -> dict[str, float]:
    """``[simulation] setup_error`` as given (file units), only its known keys."""
    unknown = set(value) - set(SETUP_ERROR_KEYS)
    if unknown:
        raise ValueError(f"setup_error: unknown keys {sorted(unknown)}; its keys are {', '.join(SETUP_ERROR_KEYS)}")
    return {k: float(value[k]) for k in SETUP_ERROR_KEYS if value.get(k) is not None}


def setup_error_vector(table: Mapping[str, float]) -> np.ndarray:
    """``[simulation] setup_error`` (file units, a key left out 0) as the set-up's error (6,) in mm and rad."""
    v = np.array([float(table.get(k) or 0.0) for k in SETUP_ERROR_KEYS])
    v[3:] = np.deg2rad(v[3:])
    return v


def _settings(cfg: Any) -> dict[str, Any]:
    """The configuration's ``[simulation]`` table as a dict (file units)."""
    sim = getattr(cfg, "simulation", None)
    if sim is None:
        return {}
    if isinstance(sim, Mapping):
        return dict(sim)
    return dict(sim.model_dump())


def effective_seed(cfg: Any, seed: int | None = None) -> int:
    """The seed simulated: ``seed`` when given (the command line), else ``[simulation].seed``,
    else :data:`DEFAULT_SEED`."""
    if seed is not None:
        return int(seed)
    given = _settings(cfg).get("seed")
    return DEFAULT_SEED if given is None else int(given)


def _drift(settings: Mapping[str, Any]) -> dict[str, Any]:
    return {k: settings[k] for k in DRIFT_KEYS if k in settings and settings[k] is not None}


def simulated_cell_for(cfg: Any, seed: int) -> SimulatedCell:
    """The :class:`SimulatedCell` of a cell configuration (see the module docstring)."""
    from simulators.probe_head_sim import ProbeHeadPhysics
    from simulators.thermal import ThermalModel, step_change
    from station.core.probe.geometry import default_probe_head

    settings = _settings(cfg)
    phys = SimulationPhysics.from_settings(settings)
    model = cfg.model
    setup = np.asarray(model.nominal, dtype=float)[model.setup_slice()]
    truth = CellTruth.generate(model=model, seed=seed, setup_nominal=setup, **phys.truth_kwargs())
    sigma = np.broadcast_to(np.array(phys.body_sigma()), (len(cfg.body_points), 2))
    stated = getattr(cfg, "body_sigma", None)  # the CMM report's σ per point; 0: not stated
    if stated is not None:
        stated = np.asarray(stated, dtype=float)
        sigma = np.where(stated > 0, stated, sigma)
    body = CalibrationBody.from_frames(cfg.body_points, cfg.cube_edge_mm, sigma, seed=seed)
    head = getattr(cfg, "head", None)
    geometry = head if head is not None else default_probe_head(cube_edge_mm=cfg.cube_edge_mm)
    cell_kw = phys.cell_kwargs()
    sim = getattr(cfg, "simulation", None)
    explicit = set(getattr(sim, "model_fields_set", settings.keys()))
    if "probe_noise_um" not in explicit and head is not None and getattr(head, "reading_sigma_mm", None):
        cell_kw["probe_noise_mm"] = float(head.reading_sigma_mm)  # what the head file's certificate states
    probe = ProbeHeadPhysics(geometry=geometry, noise_mm=cell_kw["probe_noise_mm"], seed=seed + 1)
    drift = _drift(settings)
    thermal = ThermalModel.for_model(truth.model, float(drift.get("thermal_length_um", 0.0)),
                                     float(drift.get("thermal_offset_arcsec", 0.0)),
                                     float(drift.get("thermal_time_constant_s", 600.0)))
    tool = tuple(float(v) for v in drift.get("step_tool_um", (0.0, 0.0, 0.0)))
    step = step_change(truth.model, int(drift.get("step_joint", 0)), float(drift.get("step_offset_deg", 0.0)),
                       (tool[0], tool[1], tool[2]))
    # a cell prepared for 'station conformance' has its robot parked where [conformance] says (the
    # operator jogs it there); otherwise the simulator's own start position
    conformance = getattr(cfg, "conformance", None)
    park = None if conformance is None else np.asarray(conformance.park_joints, dtype=float)
    return SimulatedCell(truth=truth, body=body, probe=probe, seed=seed, thermal=thermal, step=step,
                         initial_joints=park, joint_errors=_joint_errors(settings, truth.model, seed), **cell_kw)


def _joint_errors(settings: Mapping[str, Any], model: Any, seed: int):
    """``[simulation] joint_errors``: None, the six-axis arm's or the SCARA's (simulators/joint_errors.py)."""
    kind = settings.get("joint_errors") or "none"
    if kind == "none":
        return None
    from simulators.joint_errors import scara_joint_errors, six_axis_joint_errors
    from station.errors import ConfigError

    scale = settings.get("joint_errors_scale")
    if kind == "scara":
        if not model.is_scara:
            raise ConfigError(f"[simulation] joint_errors = \"scara\" is for a SCARA; robot {model.name!r} is not one: "
                              f"write \"six-axis\" for an arm of six revolute joints, or \"none\"")
        return scara_joint_errors(seed, 1.0 if scale is None else float(scale))
    if model.n_joints != 6 or any(t != "revolute" for t in model.joint_types):
        raise ConfigError(f"[simulation] joint_errors = {kind!r} is for a six-axis arm of revolute joints; "
                          f"robot {model.name!r} has the joints {', '.join(model.joint_types)}")
    return six_axis_joint_errors(seed, 1.0 if scale is None else float(scale))


def _collision(cfg: Any, settings: Mapping[str, Any], cell: SimulatedCell):
    """``[simulation] collision_check``: the controller's own collision check of the cell (None: off),
    on unless the key says false (issue 40: a planning slip fails the rehearsal). A robot that would
    start inside something is refused: no motion from there could be checked."""
    if settings.get("collision_check") is False:
        return None
    from simulators.collision_check import CellCollision
    from station.errors import ConfigError

    check = CellCollision.from_config(cfg)
    start = np.asarray(cell.encoder_joints(), dtype=float)
    hit = check.check_joints(start[None])
    if hit is not None:
        raise ConfigError(f"[simulation] collision_check: the simulated robot would start where {hit.a} and {hit.b} "
                          f"overlap ({hit.depth_mm:.1f} mm); set [conformance] park_joints to where the robot stands, "
                          f"clear of the body and the obstacles")
    return check


def _absolute_paths(value: Any, base: Path) -> Any:
    """Strings that name a file beside the configuration (a robot file, a head file, a body
    file) made absolute, so that the station's configuration reads the same files from anywhere."""
    if isinstance(value, dict):
        return {k: _absolute_paths(v, base) for k, v in value.items()}
    if isinstance(value, list):
        return [_absolute_paths(v, base) for v in value]
    if isinstance(value, str) and value and not Path(value).is_absolute():
        try:
            is_file = (base / value).is_file()
        except (OSError, ValueError):  # no usable file name (too long, a NUL): a plain string, kept
            is_file = False
        if is_file:
            return str((base / value).resolve())
    return value


def station_config_text(cfg: Any, servers: SimulatedCellServers, seed: int, source: str | Path | None = None,
                        instant: bool = False) -> str:
    """The station's configuration of the simulated cell as TOML: the user's (``cfg.source_text``)
    with ``[devices]`` pointing at ``servers`` and ``[simulation].seed = seed``; files named
    relative to ``source`` (the user's configuration file) made absolute. ``instant`` (motions
    take no time, time scale 0): nothing vibrates after a move, so ``[plan].settle_s`` is 0 and a
    rehearsal does not wait for nothing."""
    data: dict[str, Any] = tomllib.loads(cfg.source_text) if cfg.source_text else {}
    if source is not None:
        base = Path(source).resolve().parent
        data = {k: (v if k in ("cell", "devices") else _absolute_paths(v, base)) for k, v in data.items()}
    devices = dict(data.get("devices", {}))
    devices["probe_head"] = servers.probe_port
    devices["controller"] = f"{servers.controller_host}:{servers.controller_port}"
    # the simulated unit speaks the file's dialect at the file's line settings, and the simulated
    # robot program hosts the file's register window: only the endpoints change
    devices["probe_timeout_s"] = max(float(cfg.devices.probe_timeout_s), SIMULATOR_PROBE_TIMEOUT_S)
    for key in ("controller_timeout_s", "controller_link_timeout_s"):
        devices[key] = max(float(getattr(cfg.devices, key)), SIMULATOR_CONTROLLER_DEADLINE_S)
    if instant and servers.probe_refresh_s is not None:  # the simulated unit refreshes on every request
        devices["probe_refresh_ms"] = 1000.0 * servers.probe_refresh_s
    data["devices"] = devices
    data["simulation"] = {**data.get("simulation", {}), "seed": int(seed)}
    if instant:
        data["plan"] = {**data.get("plan", {}), "settle_s": 0.0}
    where = f" of {source}" if source is not None else ""
    return (f"# The cell{where}, simulated (seed {seed}): [devices] are the simulators' endpoints.\n"
            + toml_text(data))


def toml_text(data: Mapping[str, Any]) -> str:
    """A parsed configuration written back as TOML (``tomllib.loads`` gives ``data`` back)."""
    return tomli_w.dumps(dict(data))


@dataclass
class Rehearsal:
    """A simulated user cell: the running ``servers`` (``servers.cell.truth`` is the oracle),
    the station's configuration ``cfg`` for them (the user's with ``[devices]`` replaced) and
    its TOML ``text``."""

    servers: SimulatedCellServers
    cfg: Any
    text: str
    seed: int

    def endpoints(self) -> dict[str, Any]:
        return self.servers.endpoints()

    def stop(self) -> None:
        self.servers.stop()

    def __enter__(self) -> "Rehearsal":
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


def simulate_config(cfg: Any, seed: int | None = None, source: str | Path | None = None, time_scale: float = 0.0,
                    pace: bool = False, host: str = "127.0.0.1", port: int = 0,
                    ready_timeout: float = 10.0) -> Rehearsal:
    """Start the simulators on the cell ``cfg`` describes (a validated ``CellConfig``; ``source``
    its file, for relative file names). ``seed``: the command line's, overriding
    ``[simulation].seed`` (:func:`effective_seed`)."""
    seed = effective_seed(cfg, seed)
    cell = simulated_cell_for(cfg, seed)
    d = cfg.devices
    drift = _drift(_settings(cfg))
    settings = _settings(cfg)
    servers = start_simulated_cell(seed=seed, time_scale=time_scale, pace=pace, baudrate=d.baudrate, host=host,
                                   probe_protocol=d.probe_protocol, probe_bytesize=d.probe_bytesize,
                                   probe_parity=d.probe_parity, register_base=d.controller_register_base,
                                   register_count=int(settings.get("controller_register_count") or 128),
                                   correction_state=int(settings.get("controller_correction_state") or 0),
                                   port=port, word_order=WordOrder(d.word_order), cell=cell,
                                   ready_timeout=ready_timeout, soft_limits=np.asarray(cfg.soft_limits, dtype=float),
                                   # the program's watchdog allows what the station's heartbeat check
                                   # allows here: a loaded machine stalls both sides of one process
                                   watchdog=SIMULATOR_CONTROLLER_DEADLINE_S, collision=_collision(cfg, settings, cell),
                                   **drift)
    try:
        instant = time_scale == 0.0
        text = station_config_text(cfg, servers, seed, source, instant=instant)
        devices = dataclasses.replace(d, probe_head=servers.probe_port, controller_host=servers.controller_host,
                                      controller_port=servers.controller_port,
                                      probe_timeout_s=max(float(d.probe_timeout_s), SIMULATOR_PROBE_TIMEOUT_S),
                                      controller_timeout_s=max(float(d.controller_timeout_s),
                                                               SIMULATOR_CONTROLLER_DEADLINE_S),
                                      controller_link_timeout_s=max(float(d.controller_link_timeout_s),
                                                                    SIMULATOR_CONTROLLER_DEADLINE_S),
                                      probe_refresh_s=(servers.probe_refresh_s if instant and
                                                       servers.probe_refresh_s is not None else d.probe_refresh_s))
        plan = dataclasses.replace(cfg.plan, settle_s=0.0) if instant else cfg.plan
        station_cfg = dataclasses.replace(cfg, devices=devices, plan=plan, source_text=text, simulated_seed=seed)
    except BaseException:
        servers.stop()
        raise
    return Rehearsal(servers, station_cfg, text, seed)
