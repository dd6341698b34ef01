"""Robot files: the built-in robots and the files users bring (TOML, DH/MDH CSV, URDF).

Reading files is I/O, so it lives here and not in the numeric core; the core's
:func:`station.core.model.robot_from_dict` turns the parsed content into a model.
"""

from __future__ import annotations

import tomllib
from importlib import resources
from pathlib import Path

from station.core.model import RobotModel, robot_from_dict
from station.errors import ConfigError


def builtin_robots() -> tuple[str, ...]:
    return tuple(sorted(p.name[:-5] for p in resources.files("station.io.robots").iterdir()
                        if p.name.endswith(".toml")))


def load_robot(name_or_path: str | Path) -> RobotModel:
    """A built-in robot by name (``sr800``) or a robot file (.toml, .dh.csv, .mdh.csv, .urdf)."""
    s = str(name_or_path)
    if s in builtin_robots():
        text = resources.files("station.io.robots").joinpath(f"{s}.toml").read_text()
        return robot_from_dict(tomllib.loads(text), source=f"built-in robot {s}")
    path = Path(s)
    if not path.exists():
        raise ConfigError(
            f"robot {s!r} is neither a built-in robot ({', '.join(builtin_robots())}) nor an "
            f"existing file"
        )
    if path.suffix == ".urdf":
        from station.io.robot_import import robot_from_urdf

        return robot_from_urdf(path)
    if path.name.endswith((".dh.csv", ".mdh.csv")):
        from station.io.robot_import import robot_from_dh_file

        return robot_from_dh_file(path)
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML ({exc}); fix the syntax at that line") from None
    return robot_from_dict(data, source=str(path))
