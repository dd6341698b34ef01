"""Robot files: the built-in robots and the files users bring (TOML, DH/MDH CSV, URDF).

Reading files is I/O, so it lives here and not in the numeric core; the core's
:func:`station.core.kinematics.model.robot_from_dict` turns the parsed content into a model.

A user file is read only if it is a regular file of a sane size (:func:`read_user_text`): a
device such as ``/dev/zero`` or a FIFO is refused before anything is read, so it can neither
exhaust memory nor hang the station. Every model read from a file is checked before it is used:
finite nominal parameters (a NaN names its parameter) and finite, ordered joint limits.

A robot file may map the controller's joints onto the model's (``[joint_map]``, or the DH
table's ``sign``, ``offset``, ``coupled_to``, ``k`` columns; :mod:`station.core.kinematics.joint_map`):
:func:`load_mapped_robot` gives it to the commands that apply it to data files' joints, and
:func:`load_robot`, which the cell uses, refuses a file that has one.

A TOML robot file may mark its tool (marker, reflector) point unknown (``[tool] unknown = true``):
:func:`tool_marked_unknown` tells ``identify`` to fit it, as ``--tool unknown`` does.
"""

from __future__ import annotations

import math
import os
import stat
import tomllib
from importlib import resources
from pathlib import Path

import numpy as np

from station.core.kinematics.joint_map import JointMap, joint_map_from_file_units
from station.core.kinematics.model import RobotModel, robot_from_dict
from station.errors import ConfigError
from station.io.robot.bounds import check_map_plausible, check_plausible
from station.io.robot.units import check_toml_units

#: a robot file larger than this is refused before it is read (a URDF with inline meshes is
#: rarely above a few MB; the DH and TOML files are a few kB)
MAX_ROBOT_FILE_BYTES = 16 * 1024 * 1024


def builtin_robots() -> tuple[str, ...]:
    return tuple(sorted(p.name[:-5] for p in resources.files("station.io.robots").iterdir()
                        if p.name.endswith(".toml")))


def check_user_file(path: Path, max_bytes: int, what: str, missing: str | None = None) -> None:
    """Refuse ``path`` unless it is an existing regular file of at most ``max_bytes`` (it is
    only stat-ed: a device or a FIFO is never opened)."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise ConfigError(f"{path}: {missing or f'no such {what}'}") from None
    except (OSError, ValueError) as exc:  # too long a name, a NUL byte, no permission, a loop
        why = getattr(exc, "strerror", None) or exc
        raise ConfigError(f"{path}: cannot open the {what} ({why}); give the path of a readable file") from None
    if not stat.S_ISREG(st.st_mode):
        kind = "a directory" if stat.S_ISDIR(st.st_mode) else "a device, FIFO or socket"
        raise ConfigError(f"{path}: the {what} is {kind}, not a regular file; give the path of a file")
    if st.st_size > max_bytes:
        raise ConfigError(f"{path}: the {what} has {st.st_size} bytes, more than the {max_bytes} accepted; "
                          f"is this the right file?")


def read_user_text(path: Path, max_bytes: int, what: str, missing: str | None = None) -> str:
    """The UTF-8 text of a file the user gave: only a regular file of at most ``max_bytes``
    (checked on the opened descriptor too, and never read past the limit); a byte-order mark
    is dropped. Any failure is a :class:`ConfigError` that names the file."""
    check_user_file(path, max_bytes, what, missing)
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))  # a FIFO swapped in never blocks
        with os.fdopen(fd, "rb") as f:
            if not stat.S_ISREG(os.fstat(f.fileno()).st_mode):
                raise ConfigError(f"{path}: the {what} is not a regular file; give the path of a file")
            raw = f.read(max_bytes + 1)
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read the {what} ({exc.strerror or exc}); check the path and "
                          f"its permissions") from None
    if len(raw) > max_bytes:
        raise ConfigError(f"{path}: the {what} is larger than the {max_bytes} bytes accepted")
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{path}: the {what} is not UTF-8 text (byte {exc.start}); save it as UTF-8") from None


def check_model(model: RobotModel, source: str) -> RobotModel:
    """Refuse a model with a non-finite nominal parameter (named) or joint limits that are not
    finite and ordered (joint named): NaN limits would switch the soft-limit check off."""
    bad = ~np.isfinite(model.nominal)
    if np.any(bad):
        k = int(np.argmax(bad))
        raise ConfigError(f"{source}: parameter {model.param_names[k]} is {model.nominal[k]} (NaN or infinite); "
                          f"give a finite value")
    for j, (lo, hi) in enumerate(np.asarray(model.joint_limits, dtype=float)):
        if not (math.isfinite(lo) and math.isfinite(hi)):
            raise ConfigError(f"{source}: joint {j + 1} has limits [{lo}, {hi}]; give finite limits")
        if not lo < hi:
            raise ConfigError(f"{source}: joint {j + 1} has limits [{lo}, {hi}]; lower must be < upper")
    check_plausible(model, source)
    return model


def load_robot(name_or_path: str | Path, base: str | None = None, tip: str | None = None) -> RobotModel:
    """A built-in robot by name (``sr800``) or a robot file (.toml, .dh.csv, .mdh.csv, .urdf);
    ``base``/``tip``: the links of a URDF's chain.

    A file that maps the controller's joints onto the model's (sign, offset, coupling) is
    refused: the callers of this function (the cell) command and read joints as the model
    counts them. :func:`load_mapped_robot` gives the map to those that apply it."""
    model, jmap = load_mapped_robot(name_or_path, base, tip)
    if not jmap.is_identity:
        raise ConfigError(f"{name_or_path}: the robot file maps the controller's joints onto the model's "
                          f"({'; '.join(jmap.describe())}), and a cell sends and reads joints as the model counts "
                          f"them: for a cell, give a robot file without [joint_map] (or sign, offset, coupled_to "
                          f"columns) whose joints are the controller's; the map is for identify, validate, "
                          f"predict and compensate")
    return model


def load_mapped_robot(name_or_path: str | Path, base: str | None = None,
                      tip: str | None = None) -> tuple[RobotModel, JointMap]:
    """:func:`load_robot`'s model and the file's joint map (identity when it has none)."""
    s = str(name_or_path)
    if s in builtin_robots():
        _refuse_chain_choice(s, base, tip)
        text = resources.files("station.io.robots").joinpath(f"{s}.toml").read_text()
        source = f"built-in robot {s}"
        # the same finiteness and plausibility checks as a user's file: a unit slip in a built-in
        # robot (revolute limits left in degrees, 57× too wide) is refused, not carried into every
        # built-in cell (42); its schema is checked by the tests (pydantic's import is not free)
        model = check_model(robot_from_dict(tomllib.loads(text), source=source), source)
        return model, JointMap.identity(_joint_names(model))
    path = Path(s)
    check_user_file(path, MAX_ROBOT_FILE_BYTES, "robot file",
                    missing=f"robot {s!r} is neither a built-in robot ({', '.join(builtin_robots())}) "
                            f"nor an existing file")
    if path.suffix != ".urdf":
        _refuse_chain_choice(s, base, tip)
    if path.suffix == ".urdf" or path.name.endswith((".dh.csv", ".mdh.csv")):
        read_user_text(path, MAX_ROBOT_FILE_BYTES, "robot file")  # regular, bounded, UTF-8
        from station.io.robot.formats import read_dh_file, robot_from_urdf

        try:
            if path.suffix == ".urdf":
                model = robot_from_urdf(path, base=base, tip=tip)
                jmap = JointMap.identity(_joint_names(model))
            else:
                model, jmap = read_dh_file(path)
        except (UnicodeDecodeError, OSError) as exc:
            raise ConfigError(f"{path}: cannot read the robot file ({exc})") from None
        return check_model(model, str(path)), _plausible_map(jmap, model, str(path))
    data = _read_toml(path)
    from station.io.robot.schema import validate_robot_toml  # pydantic: only for a TOML file

    validate_robot_toml(data, str(path))  # unknown tables and keys: the nearest known name
    model = robot_from_dict(data, source=str(path))
    check_toml_units(data, str(path))  # on the numbers as written: a slip of unit is named where it was made
    model = check_model(model, str(path))
    _toml_tool_unknown(data, str(path))  # a typo in [tool] is refused by every command, not only identify
    return model, _plausible_map(_toml_joint_map(data, model, str(path)), model, str(path))


def _plausible_map(jmap: JointMap, model: RobotModel, source: str) -> JointMap:
    check_map_plausible(jmap.offset, jmap.k, jmap.names, model.joint_types, source)
    return jmap


def tool_marked_unknown(name_or_path: str | Path) -> bool:
    """Whether the TOML robot file marks its tool point unknown (``[tool] unknown = true``): its
    K's x, y, z are then only a start, and ``identify`` fits them (``--tool unknown``). Built-in
    robots, DH/MDH tables and URDFs have no such mark (False)."""
    s = str(name_or_path)
    path = Path(s)
    if s in builtin_robots() or path.suffix == ".urdf" or path.name.endswith((".dh.csv", ".mdh.csv")):
        return False
    check_user_file(path, MAX_ROBOT_FILE_BYTES, "robot file")
    return _toml_tool_unknown(_read_toml(path), s)


def _read_toml(path: Path) -> dict:
    text = read_user_text(path, MAX_ROBOT_FILE_BYTES, "robot file")
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML ({exc}); fix the syntax at that line") from None
    except RecursionError:
        raise ConfigError(f"{path}: not valid TOML (nested too deeply); fix the syntax") from None


def _toml_tool_unknown(data: dict, source: str) -> bool:
    """The ``[tool]`` table's ``unknown`` (default false); any other key or value is refused."""
    raw = data.get("tool", {})
    if not isinstance(raw, dict):
        raise ConfigError(f"{source}: tool must be a table, e.g. [tool] with unknown = true")
    extra = sorted(set(raw) - {"unknown"})
    if extra:
        raise ConfigError(f"{source}: [tool] has unknown keys {extra}; allowed: unknown (true: identify fits the "
                          f"tool point; the tool itself is the last [[transform]])")
    v = raw.get("unknown", False)
    if not isinstance(v, bool):
        raise ConfigError(f"{source}: [tool].unknown must be true or false, got {v!r}")
    return v


def _refuse_chain_choice(robot: str, base: str | None, tip: str | None) -> None:
    if base is not None or tip is not None:
        raise ConfigError(f"--base/--tip choose the chain of a URDF; robot {robot!r} is not a .urdf file: "
                          f"leave them out")


def _joint_names(model: RobotModel) -> tuple[str, ...]:
    return tuple(model.transforms[i].name for i in model.joint_transforms)


_MAP_KEYS = ("sign", "offset", "coupled_to", "k")


def _toml_joint_map(data: dict, model: RobotModel, source: str) -> JointMap:
    """The ``[joint_map]`` table: per joint transform ``sign``, ``offset`` (the file's angle or
    length unit), ``coupled_to`` (another joint transform) and ``k``."""
    names = _joint_names(model)
    raw = data.get("joint_map", {})
    if not isinstance(raw, dict):
        raise ConfigError(f"{source}: [joint_map] must be a table of joints, e.g. [joint_map.A3]")
    entries: dict[int, dict] = {}
    for name, e in raw.items():
        if name not in names:
            raise ConfigError(f"{source}: [joint_map.{name}]: no joint transform {name!r}; the joints are "
                              f"{', '.join(names)}")
        if not isinstance(e, dict):
            raise ConfigError(f"{source}: [joint_map].{name} must be a table with {', '.join(_MAP_KEYS)}")
        unknown = sorted(set(e) - set(_MAP_KEYS))
        if unknown:
            raise ConfigError(f"{source}: [joint_map.{name}] has unknown keys {unknown}; allowed: "
                              f"{', '.join(_MAP_KEYS)}")
        entry: dict = {}
        for key in ("sign", "offset", "k"):
            if key in e:
                v = e[key]
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                    raise ConfigError(f"{source}: [joint_map.{name}].{key} must be a finite number, got {v!r}")
                entry[key] = float(v)
        if "sign" in entry and entry["sign"] not in (1.0, -1.0):
            raise ConfigError(f"{source}: [joint_map.{name}].sign must be 1 or -1, got {e['sign']!r}")
        if "coupled_to" in e:
            other = e["coupled_to"]
            if other not in names or other == name:
                raise ConfigError(f"{source}: [joint_map.{name}].coupled_to = {other!r}: give another joint "
                                  f"transform, one of {', '.join(n for n in names if n != name)}")
            entry["other"] = names.index(other)
        entries[names.index(name)] = entry
    head = data["robot"]
    a_scale = math.pi / 180.0 if head.get("angle_unit", "deg") == "deg" else 1.0
    l_scale = 1000.0 if head.get("length_unit", "mm") == "m" else 1.0
    try:
        return joint_map_from_file_units(names, model.joint_types, entries, a_scale, l_scale)
    except ConfigError as exc:
        raise ConfigError(f"{source}: {exc}") from None


def joint_map_toml(jmap: JointMap, model: RobotModel, angle_unit: str = "rad") -> str:
    """The ``[joint_map]`` table of ``jmap`` for a robot file written in ``angle_unit`` and mm
    (appended to :func:`station.core.kinematics.model.robot_to_toml`'s text; empty for the identity)."""
    import tomli_w

    if jmap.is_identity:
        return ""
    a = 180.0 / math.pi if angle_unit == "deg" else 1.0
    scale = [a if t == "revolute" else 1.0 for t in model.joint_types]
    table: dict = {}
    for j, name in enumerate(jmap.names):
        e: dict = {}
        if jmap.sign[j] != 1.0:
            e["sign"] = int(jmap.sign[j])
        if jmap.offset[j] != 0.0:
            e["offset"] = jmap.offset[j] * scale[j]
        o = jmap.other[j]
        if o is not None:
            e["coupled_to"] = jmap.names[o]
            e["k"] = jmap.k[j] * scale[j] / scale[o]
        if e:
            table[name] = e
    return "\n" + tomli_w.dumps({"joint_map": table})
