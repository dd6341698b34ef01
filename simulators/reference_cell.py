"""The cell configuration (TOML) of the built-in simulated reference cell.

The simulators know the cell they simulate: the calibration body's nominal points (its CMM
report), the nominal set-up of the robot and the endpoints the servers listen on. The station
reads the text like any other cell configuration (``docs/station.md``, "Cell configuration").
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Protocol

import numpy as np

from simulators import SimulatedCellServers
from simulators.cell import DEFAULT_SETUP, SimulatedCell
from simulators.truth_kinematics import matrix_pose

__all__ = ["cell_config_text", "body_and_devices_toml", "CellEndpoints"]


def _toml(key: str, v: Any) -> str:
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(repr(float(x)) for x in v) + "]"
    if isinstance(v, Mapping):  # an inline table ([simulation] setup_error)
        return "{ " + ", ".join(f"{k} = {repr(float(x))}" for k, x in v.items()) + " }"
    return repr(int(v)) if key == "step_joint" else repr(float(v))


class CellEndpoints(Protocol):
    """What the configuration text reads of running servers (:class:`SimulatedCellServers`)."""

    @property
    def cell(self) -> SimulatedCell: ...
    @property
    def probe_port(self) -> str: ...
    @property
    def controller_host(self) -> str: ...
    @property
    def controller_port(self) -> int: ...


def devices_toml(servers: CellEndpoints) -> str:
    """The ``[devices]`` lines that reach running simulators: endpoints, the simulated probe
    unit's dialect and line settings (and, where it buffers, its refresh time), the simulated
    robot program's register base. Servers that do not say (a test's stand-in) get the built-in
    cell's: a DL-RS1A at its factory 9600 8N1, the window at 0."""
    probe = getattr(servers, "probe_server", None)
    line = getattr(probe, "line", None)
    dialect = getattr(getattr(probe, "dialect", None), "name", "keyence-dl-rs1a")
    refresh = getattr(getattr(probe, "unit", None), "refresh_s", None)
    base = getattr(getattr(servers, "controller_server", None), "register_base", 0)
    out = [f'probe_head = "{servers.probe_port}"', f'probe_protocol = "{dialect}"']
    if line is not None:
        out += [f"baudrate = {line.baudrate}", f"probe_bytesize = {line.bytesize}", f'probe_parity = "{line.parity}"']
    if refresh is not None:
        out.append(f"probe_refresh_ms = {1000.0 * refresh!r}")
    out += [f'controller = "{servers.controller_host}:{servers.controller_port}"',
            f"controller_register_base = {int(base)}"]
    return "\n".join(out) + "\n"


def body_and_devices_toml(servers: CellEndpoints, word_order_line: str = "") -> str:
    """The ``[body]`` (the simulated body's CMM report: its nominal corner frames, named
    ``C<cube>.<a-d>``) and ``[devices]`` (the simulators' endpoints) tables of a simulated cell."""
    body = servers.cell.body
    lines = []
    for (cube, corner), T in zip(body.labels, body.nominal):
        p = matrix_pose(T)
        vals = [*p[:3], *np.degrees(p[3:])]
        lines.append(f'  {{ id = "C{cube + 1}.{"abcd"[corner]}", pose = [{", ".join(repr(float(v)) for v in vals)}] }},')
    return f"""[body]
cube_edge_mm = {body.cube_edge_mm!r}
points = [
{chr(10).join(lines)}
]

[devices]
{devices_toml(servers)}{word_order_line}motion_timeout_s = 30.0
# The simulators share the CPU with the station (and, in CI, with the tests): a loaded machine
# must not turn into probe timeouts, whose retries make a run stop reproducing, nor into a
# controller link declared lost (SIMULATOR_DEADLINES_S in simulators/from_config.py).
probe_timeout_s = 2.0
controller_timeout_s = 5.0
controller_link_timeout_s = 5.0
"""


def cell_config_text(servers: SimulatedCellServers, seed: int, word_order: str = "big") -> str:
    """A cell configuration for the built-in simulated cell (its CMM body report, endpoints).

    ``word_order`` must be the one the controller simulator was started with (``"big"`` or
    ``"little"``); only a little word order is written out, big being the configuration's default.
    """
    if word_order not in ("big", "little"):
        raise ValueError(f'word_order must be "big" or "little", got {word_order!r}')
    setup = [*DEFAULT_SETUP[:3], *np.degrees(DEFAULT_SETUP[3:])]
    word_order_line = "" if word_order == "big" else f'word_order = "{word_order}"\n'
    # the drift the simulator was started with, recorded with every run (a baseline check ignores it)
    drift = "".join(f"{k} = {_toml(k, v)}\n" for k, v in getattr(servers, "drift", {}).items())
    # and the physics it was started with where it differs from the defaults (another cell)
    drift += "".join(f"{k} = {_toml(k, v)}\n" for k, v in getattr(servers, "physics", {}).items())
    return f"""# Built-in simulated reference cell (seed {seed}).
[cell]
name = "simulated reference cell"

[robot]
model = "sr800"
setup = [{", ".join(repr(float(v)) for v in setup)}]

[limits]
joints = [[-125.0, 125.0], [-140.0, 140.0], [-195.0, -5.0], [-355.0, 355.0]]

{body_and_devices_toml(servers, word_order_line)}
[plan]
settle_s = 0.0
repeats = 4
verification_cycles = 5

[identification]
# The simulated head: 0.5 µm probe noise over ~25 mm probe spacing (≈ 4″) on top of the robot's
# ≈ 5 µm repeatability; weights follow the measurement, not the data sheet.
sigma_position_um = 6.0
sigma_angle_arcsec = 6.0

[simulation]
seed = {seed}
{drift}"""
