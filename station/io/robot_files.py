"""Robot files: the built-in robots and the files users bring (TOML, DH/MDH CSV, URDF).

Reading files is I/O, so it lives here and not in the numeric core; the core's
:func:`station.core.model.robot_from_dict` turns the parsed content into a model.

A user file is read only if it is a regular file of a sane size (:func:`read_user_text`): a
device such as ``/dev/zero`` or a FIFO is refused before anything is read, so it can neither
exhaust memory nor hang the station. Every model read from a file is checked before it is used:
finite nominal parameters (a NaN names its parameter) and finite, ordered joint limits.
"""

from __future__ import annotations

import math
import os
import stat
import tomllib
from importlib import resources
from pathlib import Path

import numpy as np

from station.core.model import RobotModel, robot_from_dict
from station.errors import ConfigError

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
    return model


def load_robot(name_or_path: str | Path) -> RobotModel:
    """A built-in robot by name (``sr800``) or a robot file (.toml, .dh.csv, .mdh.csv, .urdf)."""
    s = str(name_or_path)
    if s in builtin_robots():
        text = resources.files("station.io.robots").joinpath(f"{s}.toml").read_text()
        return robot_from_dict(tomllib.loads(text), source=f"built-in robot {s}")
    path = Path(s)
    check_user_file(path, MAX_ROBOT_FILE_BYTES, "robot file",
                    missing=f"robot {s!r} is neither a built-in robot ({', '.join(builtin_robots())}) "
                            f"nor an existing file")
    if path.suffix == ".urdf" or path.name.endswith((".dh.csv", ".mdh.csv")):
        read_user_text(path, MAX_ROBOT_FILE_BYTES, "robot file")  # regular, bounded, UTF-8
        from station.io.robot_import import robot_from_dh_file, robot_from_urdf

        reader = robot_from_urdf if path.suffix == ".urdf" else robot_from_dh_file
        try:
            model = reader(path)
        except (UnicodeDecodeError, OSError) as exc:
            raise ConfigError(f"{path}: cannot read the robot file ({exc})") from None
        return check_model(model, str(path))
    text = read_user_text(path, MAX_ROBOT_FILE_BYTES, "robot file")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML ({exc}); fix the syntax at that line") from None
    except RecursionError:
        raise ConfigError(f"{path}: not valid TOML (nested too deeply); fix the syntax") from None
    return check_model(robot_from_dict(data, source=str(path)), str(path))
