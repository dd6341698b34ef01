"""The cell a command asked for, composed above the cell layer: a real cell's configuration is
read by :func:`station.cell.session.calibrate.load_cell`; ``--simulated`` starts the simulators here and
hands the session a :class:`~station.cell.session.calibrate.LoadedCell` whose ``[devices]`` point at them
(the configuration, the simulated cell's judge (``simulators.judge.CellJudge``), its endpoints).

The session functions take :func:`load_cell` as their ``load`` argument, so the cell layer
never imports the simulators (an import contract in ``pyproject.toml`` keeps it so).

Simulated, on the cell a full configuration describes (its robot, body, head, limits, word
order; the true errors from its ``[simulation]``: ``simulators/from_config.py``), or on a
built-in cell, whose configuration the simulators write. The simulators are imported only when
a simulated cell is started: a real run never loads them.
"""

from __future__ import annotations

import tomllib
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import tomli_w

from station.cell.config.cell_config import MAX_CONFIG_BYTES, parse_text, simulation_settings
from station.cell.session import calibrate as session
from station.cell.session.calibrate import CellRequest, LoadedCell
from station.errors import ConfigError
from station.io.robot.files import read_user_text

__all__ = ["BUILTIN_ROBOT_CELLS", "load_cell"]

#: the tables of a ``--simulated`` CONFIG without [robot] and [body] that the built-in simulated
#: cell's configuration takes over (besides its [simulation], which the simulators take)
_TAKEN = ("recheck", "warmup", "fleet")  # [fleet]: a rehearsal publishes where the plant's runs go

#: the built-in simulated cells besides the SCARA's: robot name -> (start servers, config text)
BUILTIN_ROBOT_CELLS = ("irb2600",)


def _judge(cell: Any) -> Any:
    """The judge of the running simulated ``cell`` (imported here: a real run never loads it)."""
    from simulators.judge import CellJudge

    return CellJudge.of(cell)


def load_cell(request: CellRequest, stack: ExitStack) -> LoadedCell:
    """The request's cell. With ``simulated`` the simulators are started (stopped when ``stack``
    closes) and the configuration is theirs: a CONFIG that describes a cell ([robot], [body]) is
    rehearsed, the station's configuration being CONFIG with [devices] pointing at the
    simulators; without CONFIG, or with one holding only [simulation], [recheck] and [warmup],
    the built-in cell is started with those. The seed: ``request.seed`` (``--seed``) when given,
    else ``[simulation].seed``, else 1. ``LoadedCell.judge`` knows the simulated robot. Without
    ``simulated``: the configuration file (:func:`station.cell.session.calibrate.load_cell`)."""
    if request.simulated and request.robot not in (None, "sr800"):  # another robot's built-in cell (issue 9)
        return _load_builtin_robot_cell(request, stack)
    if request.simulated:
        return _load_simulated(request, stack)
    return session.load_cell(request, stack)


def _read_toml(path: str) -> tuple[str, dict[str, Any]]:
    text = read_user_text(Path(path), MAX_CONFIG_BYTES, "configuration file",
                          missing=f"no such configuration file: {path}")
    try:
        return text, tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML ({exc}); fix the syntax there") from None


def _load_simulated(request: CellRequest, stack: ExitStack) -> LoadedCell:
    from simulators import start_simulated_cell
    from simulators.from_config import SIMULATOR_CONTROLLER_DEADLINE_S
    from simulators.reference_cell import cell_config_text

    text, data = _read_toml(request.config) if request.config else ("", {})
    if "robot" in data or "body" in data:  # the user's cell: rehearse it
        from simulators.from_config import simulate_config

        cfg = parse_text(text, str(request.config))
        try:
            rehearsal = simulate_config(cfg, seed=request.seed, source=request.config,
                                        time_scale=request.time_scale)
        except ValueError as exc:  # e.g. a step change on a prismatic joint
            raise ConfigError(f"{request.config}: [simulation]: {exc}") from None
        stack.callback(rehearsal.stop)
        return LoadedCell(rehearsal.cfg, _judge(rehearsal.servers.cell), rehearsal.endpoints())
    sim = simulation_settings(text, str(request.config)) if request.config else {}
    given = sim.pop("seed", None)
    if sim.pop("collision_check", None):  # the controller's check needs the cell's own files (issue 40)
        raise ConfigError(f"{request.config}: [simulation] collision_check = true checks the motions against the "
                          f"cell's robot, head, body and [[obstacle]] files; the built-in simulated cell has none of "
                          f"its own: add [robot] and [body] (e.g. examples/scara600_column/cell.toml), or remove the key")
    # joint errors beyond geometry (issue 30): the built-in cell is a SCARA, its kind is "scara"
    kind = sim.get("joint_errors") or "none"
    if kind == "six-axis":
        raise ConfigError(f"{request.config}: [simulation] joint_errors = {kind!r} is for a six-axis arm; the "
                          f"built-in simulated cell is a SCARA: write \"scara\" (its gears err once per turn), "
                          f"remove the key, or rehearse a six-axis cell (--robot irb2600, or a configuration with "
                          f"[robot] and [body])")
    seed = request.seed if request.seed is not None else (1 if given is None else int(given))
    window = {"register_count": sim.pop("controller_register_count", 128),
              "correction_state": sim.pop("controller_correction_state", 0)}
    # the program's watchdog allows what the built-in cell's heartbeat check allows (5 s): a
    # loaded machine stalls both sides of this one process
    servers = start_simulated_cell(seed=seed, time_scale=request.time_scale, watchdog=SIMULATOR_CONTROLLER_DEADLINE_S,
                                   **window, **sim)
    stack.callback(servers.stop)
    cell_text = cell_config_text(servers, seed)
    if isinstance(data.get("identification"), dict):  # e.g. model = "auto" (issue 30) on the built-in cell
        cell_text = _merge_table(cell_text, "identification", data["identification"])
    taken = {t: data[t] for t in _TAKEN if isinstance(data.get(t), dict)}
    if taken:
        cell_text += "\n" + tomli_w.dumps(taken)
    cfg = parse_text(cell_text, f"<simulated cell{' with ' + request.config if request.config else ''}>")
    return LoadedCell(cfg, _judge(servers.cell), servers.endpoints())


def _merge_table(text: str, table: str, given: dict[str, Any]) -> str:
    """``text`` (TOML with a ``[table]``) with the keys ``given`` for that table: a key it has is
    replaced, one it lacks added under the header; the rest of the text, comments included, stays."""
    lines = text.splitlines(keepends=True)
    header = f"[{table}]"
    start = next((i for i, line in enumerate(lines) if line.strip() == header), None)
    if start is None:
        return text + f"\n{header}\n" + tomli_w.dumps(given)
    end = next((i for i in range(start + 1, len(lines)) if lines[i].lstrip().startswith("[")), len(lines))
    body = lines[start + 1:end]
    for key, value in given.items():
        line = tomli_w.dumps({key: value})
        at = next((i for i, b in enumerate(body) if b.split("=", 1)[0].strip() == key and "=" in b), None)
        if at is None:
            body.insert(0, line)
        else:
            body[at] = line
    return "".join(lines[:start + 1] + body + lines[end:])


def _load_builtin_robot_cell(request: CellRequest, stack: ExitStack) -> LoadedCell:
    """``--simulated --robot NAME``: the built-in simulated cell of that robot (the six-axis cell
    for ``irb2600``, :mod:`simulators.six_axis_cell`); a CONFIG is not combined with it."""
    if request.robot not in BUILTIN_ROBOT_CELLS:
        raise ConfigError(f"--robot {request.robot}: no built-in simulated cell for this robot; the built-in cells "
                          f"are sr800 (the default) and {', '.join(BUILTIN_ROBOT_CELLS)}. Rehearse your own cell "
                          f"with --simulated CONFIG")
    if request.config:
        raise ConfigError(f"--robot {request.robot} starts a built-in simulated cell; give either it or a CONFIG "
                          f"to rehearse, not both")
    from simulators.collision_check import CellCollision
    from simulators.six_axis_cell import six_axis_config_text, start_six_axis_cell

    seed = 1 if request.seed is None else request.seed
    servers = start_six_axis_cell(seed=seed, time_scale=request.time_scale)
    stack.callback(servers.stop)
    cfg = parse_text(six_axis_config_text(servers, seed), "<simulated six-axis cell>")
    # its controller checks every motion against the cell this configuration describes, in its own
    # model (issue 40: a planning slip of a six-axis plan fails the rehearsal), before any motion
    servers.controller_server.collision = CellCollision.from_config(cfg)
    return LoadedCell(cfg, _judge(servers.cell), servers.endpoints())
