"""Simulated calibration cell: robot controller (Modbus TCP) + probe head (serial, pty).

``start_simulated_cell()`` starts both in-process and returns once both endpoints accept
traffic; ``python -m simulators`` does the same as a process and prints the endpoints as one
JSON line.
"""

from __future__ import annotations

import socket
import time
from dataclasses import dataclass, field
from typing import Any

from drivers.controller_map import MAP_VERSION, WordOrder

__all__ = ["SimulatedCellServers", "start_simulated_cell"]


def _wait_tcp(host: str, port: int, timeout: float) -> None:
    deadline = time.monotonic() + timeout
    while True:
        try:
            with socket.create_connection((host, port), timeout=0.5):
                return
        except OSError as exc:
            if time.monotonic() >= deadline:
                raise RuntimeError(f"controller simulator at {host}:{port} not accepting: {exc}") from exc
            time.sleep(0.01)


#: the simulated DL-RS1A's buffer refresh when motions take time (a few amplifiers: ~20 ms)
SIMULATED_REFRESH_S = 0.02


@dataclass
class SimulatedCellServers:
    """Running simulators. ``cell.truth`` is the oracle (true robot, set-up, body)."""

    cell: Any
    controller_server: Any
    probe_server: Any
    seed: int = 0
    drift: dict = field(default_factory=dict)  # the [simulation] drift keys it was started with
    physics: dict = field(default_factory=dict)  # the [simulation] physics keys that differ from the defaults
    _stopped: bool = field(default=False, repr=False)

    @property
    def controller_host(self) -> str:
        return self.controller_server.host

    @property
    def controller_port(self) -> int:
        return self.controller_server.port

    @property
    def probe_port(self) -> str:
        return self.probe_server.port

    @property
    def probe_refresh_s(self) -> float | None:
        """The simulated unit's buffer refresh [s] (None: its dialect buffers nothing)."""
        return getattr(getattr(self.probe_server, "unit", None), "refresh_s", None)

    def endpoints(self) -> dict:
        return {"controller": f"{self.controller_host}:{self.controller_port}",
                "probe_head": self.probe_port, "seed": self.seed}

    def stop(self) -> None:
        """Stop both servers; re-raises a failure of either (after stopping both)."""
        if self._stopped:
            return
        self._stopped = True
        errors = []
        for server in (self.probe_server, self.controller_server):
            try:
                server.stop()
            except RuntimeError as exc:
                errors.append(exc)
        if errors:
            raise errors[0]

    def __enter__(self) -> "SimulatedCellServers":
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


def start_simulated_cell(seed: int = 0, time_scale: float = 0.0, pace: bool = False,
                         baudrate: int | None = None, host: str = "127.0.0.1", port: int = 0,
                         word_order: WordOrder = WordOrder.BIG, watchdog: float = 1.0,
                         cell: Any = None, ready_timeout: float = 10.0,
                         map_version: int | None = None, thermal_length_um: float = 0.0,
                         thermal_offset_arcsec: float = 0.0, thermal_time_constant_s: float = 600.0,
                         step_joint: int = 0, step_offset_deg: float = 0.0,
                         step_tool_um: tuple[float, float, float] = (0.0, 0.0, 0.0),
                         soft_limits: Any = None, register_base: int = 0, register_count: int = 128,
                         correction_state: int = 0,
                         probe_protocol: str = "keyence-dl-rs1a", probe_bytesize: int | None = None,
                         probe_parity: str | None = None, joint_errors: str = "none", joint_errors_scale: float = 1.0,
                         collision: Any = None, **physics: float) -> SimulatedCellServers:
    """Start the controller and probe-head simulators on one :class:`SimulatedCell`.
    ``map_version``: publish another register-map version (the driver must refuse it).
    ``register_base``/``register_count``: the controller's register window (``[devices]
    controller_register_base``, ``[simulation] controller_register_count``); every address
    outside it is refused with Modbus exception 2. ``correction_state``: what the simulated program
    reports of the controller's own correction (0 none, 1 the vendor's, 2 unknown).

    Drift (``simulators/thermal.py``; the ``[simulation]`` keys of the same names): a thermal
    model (``thermal_length_um`` growth of the arm lengths, ``thermal_offset_arcsec`` of the
    revolute joint offsets when warm, time constant ``thermal_time_constant_s`` of simulated
    motion) and a step change against the seed's robot (``step_joint`` from 1 re-mastered by
    ``step_offset_deg``; the tool bumped by ``step_tool_um``).

    ``physics``: the built-in cell's true-error magnitudes and physics, the ``[simulation]`` keys
    of :class:`simulators.from_config.SimulationPhysics` (µm, arc seconds, degrees); left out, the
    built-in cell is exactly today's. With ``cell`` given, the drift and physics arguments only
    describe it (the cell already holds them). ``soft_limits`` ``(n_joints, 2)`` [rad | mm]: the
    controller's (default: the robot's joint limits). ``joint_errors``: ``"scara"`` gives the built-in
    SCARA's gears once-per-turn errors (:func:`simulators.joint_errors.scara_joint_errors`, times
    ``joint_errors_scale``; issue 30), ``"none"`` a rigid robot. ``collision``: the controller's own
    collision check (:class:`simulators.collision_check.CellCollision`), None: none. A user's cell:
    :mod:`simulators.from_config`."""
    from simulators.cell import CellTruth, SimulatedCell
    from simulators.controller_server import SimulatedController
    from simulators.probe_head_sim import ProbeHeadServer
    from simulators.thermal import ThermalModel, step_change

    recorded: dict[str, Any] = {}
    if joint_errors not in ("none", "scara"):
        raise ValueError(f"joint_errors = {joint_errors!r}: the built-in simulated cell is a SCARA; its kinds are "
                         f"\"none\" and \"scara\"")
    if cell is None:
        if physics:
            from simulators.cell import CalibrationBody
            from simulators.from_config import SimulationPhysics

            phys = SimulationPhysics.from_settings(physics)
            default = SimulationPhysics()
            recorded = {k: getattr(phys, k) for k in physics if getattr(phys, k) != getattr(default, k)}
            truth = CellTruth.generate(seed=seed, **phys.truth_kwargs())
            pos_sigma, ang_sigma = phys.body_sigma()
            body = CalibrationBody.generate(seed=seed, position_sigma_mm=pos_sigma, angle_sigma_rad=ang_sigma)
            cell_kw: dict[str, Any] = {"truth": truth, "body": body, **phys.cell_kwargs()}
        else:
            truth, cell_kw = CellTruth.generate(seed=seed), {}
        model = truth.model
        thermal = ThermalModel.for_model(model, thermal_length_um, thermal_offset_arcsec, thermal_time_constant_s)
        step = step_change(model, step_joint, step_offset_deg, tuple(step_tool_um))  # type: ignore[arg-type]
        if joint_errors == "scara":  # a different robot, recorded with the run as physics (not drift)
            from simulators.joint_errors import scara_joint_errors

            cell_kw["joint_errors"] = scara_joint_errors(seed, float(joint_errors_scale))
            recorded.update(joint_errors="scara", **({"joint_errors_scale": float(joint_errors_scale)}
                                                     if joint_errors_scale != 1.0 else {}))
        cell = SimulatedCell(seed=seed, thermal=thermal, step=step, **cell_kw)
    ctrl = SimulatedController(cell=cell, host=host, port=port, word_order=word_order,
                               time_scale=time_scale, watchdog=watchdog, soft_limits=soft_limits,
                               map_version=MAP_VERSION if map_version is None else map_version,
                               register_base=register_base, register_count=register_count,
                               correction_state=correction_state, collision=collision
                               ).start(ready_timeout)
    try:
        _wait_tcp(ctrl.host, ctrl.port, ready_timeout)
        # the simulated probe unit's own line settings: [devices] probe_protocol, baudrate,
        # probe_bytesize, probe_parity (a station at other settings gets garbled replies)
        # at time scale 0 nothing takes time: the unit refreshes its buffer on every request, as
        # the station's configuration of the simulated cell says (reference_cell.devices_toml)
        probe = ProbeHeadServer(snapshot_source=cell.probe_values, baudrate=baudrate, pace=pace,
                                protocol=probe_protocol, bytesize=probe_bytesize, parity=probe_parity,
                                refresh_s=SIMULATED_REFRESH_S if time_scale > 0 else 0.0).start()
    except BaseException:
        ctrl.stop()
        raise
    drift: dict[str, Any] = {k: v for k, v in (("thermal_length_um", thermal_length_um), ("thermal_offset_arcsec", thermal_offset_arcsec),
                               ("step_joint", step_joint), ("step_offset_deg", step_offset_deg)) if v}
    if thermal_length_um or thermal_offset_arcsec:
        drift["thermal_time_constant_s"] = thermal_time_constant_s
    if any(step_tool_um):
        drift["step_tool_um"] = [float(v) for v in step_tool_um]
    return SimulatedCellServers(cell, ctrl, probe, seed, drift, recorded)
