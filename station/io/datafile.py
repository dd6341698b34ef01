"""Measurement and joint files (CSV), as a user with a laser tracker or a CMM would have them.

Format (docs/data-files.md): optional ``#`` comment lines, then a header whose every column
carries its unit in brackets, then one row per measurement::

    # measured with tracker T-1, 2026-11-20
    q1 [deg],q2 [deg],q3 [mm],q4 [deg],x [mm],y [mm],z [mm],roll [deg],pitch [deg],yaw [deg]
    10.0,45.0,-50.0,0.0,812.331,402.118,431.072,0.0012,-0.0031,55.0004

Joint columns ``q1 … qg`` (deg | rad for revolute, mm | m for prismatic joints); measured
position ``x, y, z`` (mm | m); orientation ``roll, pitch, yaw`` (deg | rad | arcsec) makes the
file a pose file, without it a position file. A joints file (for ``station predict``) has only
the joint columns.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from station.core.model import RobotModel
from station.core.transforms import pose_to_matrix
from station.core.units import ARCSEC, DEG, UM
from station.errors import ConfigError

_SCALE = {"mm": 1.0, "m": 1000.0, "um": UM, "µm": UM, "deg": DEG, "rad": 1.0, "arcsec": ARCSEC}
_LENGTH_UNITS = ("mm", "m", "um", "µm")
MAX_FILE_BYTES = 256 * 2**20
_ANGLE_UNITS = ("deg", "rad", "arcsec")


@dataclass(frozen=True)
class Table:
    """Parsed columns in internal units (mm, rad); ``columns`` maps name -> (n,) array."""

    path: str
    columns: dict
    n_rows: int
    units: dict


def read_table(path: str | Path) -> Table:
    p = Path(path)
    if not p.exists():
        raise ConfigError(f"{p}: no such file")
    if not p.is_file():
        raise ConfigError(f"{p}: not a regular file; give the path of a CSV data file")
    # utf-8-sig: a byte-order mark (Excel's "CSV UTF-8") is read as such, not as part of 'q1'
    try:
        with open(p, newline="", encoding="utf-8-sig") as f:
            text = f.read(MAX_FILE_BYTES + 1)
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{p}: not UTF-8 text ({exc.reason} at byte {exc.start}); export the data as CSV UTF-8") from None
    if len(text) > MAX_FILE_BYTES:
        raise ConfigError(f"{p}: larger than {MAX_FILE_BYTES // 2**20} MB; split the measurements")
    lines = [(i + 1, line) for i, line in enumerate(text.splitlines(keepends=True))
             if line.strip() and not line.lstrip().startswith("#")]
    if not lines:
        raise ConfigError(f"{p}: empty; expected a header with units and one row per measurement")
    reader = list(csv.reader(line for _, line in lines))
    header = [h.strip() for h in reader[0]]
    names, scales = [], []
    for h in header:
        if "[" not in h or not h.endswith("]"):
            raise ConfigError(f"{p}: column {h!r} has no unit; write it like 'x [mm]' or 'q1 [deg]'")
        name, unit = h[: h.index("[")].strip(), h[h.index("[") + 1: -1].strip()
        if unit not in _SCALE:
            raise ConfigError(f"{p}: column {name!r} has unknown unit {unit!r}; use one of {sorted(_SCALE)}")
        names.append(name)
        scales.append((unit, _SCALE[unit]))
    if len(set(names)) != len(names):
        raise ConfigError(f"{p}: duplicate column names in {names}")
    rows = reader[1:]
    data = np.empty((len(rows), len(names)))
    for r_i, ((lineno, _), row) in enumerate(zip(lines[1:], rows)):
        if len(row) != len(names):
            raise ConfigError(f"{p}, line {lineno}: {len(row)} values but {len(names)} columns")
        for k, v in enumerate(row):
            try:
                x = float(v)
            except ValueError:
                raise ConfigError(f"{p}, line {lineno}: {names[k]} = {v!r} is not a number") from None
            if not math.isfinite(x):
                raise ConfigError(f"{p}, line {lineno}: {names[k]} is {v.strip()}; remove or repair this row")
            data[r_i, k] = x * scales[k][1]
    cols = {n: data[:, k] for k, n in enumerate(names)}
    for n, (unit, _) in zip(names, scales):
        kind = "angle" if unit in _ANGLE_UNITS else "length"
        if n in ("x", "y", "z") and kind != "length":
            raise ConfigError(f"{p}: column {n!r} is a position and needs a length unit (mm or m)")
        if n in ("roll", "pitch", "yaw") and kind != "angle":
            raise ConfigError(f"{p}: column {n!r} is an angle and needs deg, rad or arcsec")
    return Table(str(p), cols, len(rows), dict(zip(names, (u for u, _ in scales))))


def joints_from_table(table: Table, model: RobotModel) -> np.ndarray:
    """``(n, g)`` joint values; checks the count and each joint's unit kind."""
    g = model.n_joints
    present = [n for n in table.columns if n.startswith("q") and n[1:].isdigit()]
    expected = [f"q{i}" for i in range(1, g + 1)]
    if sorted(present, key=lambda s: int(s[1:])) != expected:
        raise ConfigError(
            f"{table.path}: robot {model.name!r} has {g} joints; expected columns "
            f"{', '.join(expected)} with units, found {', '.join(present) or 'none'}"
        )
    units = table.units
    for name, kind in zip(expected, model.joint_types):
        u = units[name]
        if kind == "revolute" and u not in _ANGLE_UNITS:
            raise ConfigError(f"{table.path}: {name} is a revolute joint and needs deg or rad, not {u}")
        if kind == "prismatic" and u not in _LENGTH_UNITS:
            raise ConfigError(f"{table.path}: {name} is a prismatic joint and needs mm or m, not {u}")
    return np.column_stack([table.columns[n] for n in expected])


def read_measurements(path, model: RobotModel):
    """``(kind, joints (n,g), measured)`` with measured poses (n,4,4) or positions (n,3)."""
    t = read_table(path)
    q = joints_from_table(t, model)
    missing = [c for c in ("x", "y", "z") if c not in t.columns]
    if missing:
        raise ConfigError(f"{path}: measured position columns {missing} missing; add 'x [mm]' etc.")
    pos = np.column_stack([t.columns[c] for c in ("x", "y", "z")])
    ori = [c for c in ("roll", "pitch", "yaw") if c in t.columns]
    if ori and len(ori) != 3:
        raise ConfigError(f"{path}: a pose file needs all of roll, pitch, yaw; found only {ori}")
    if t.n_rows < 2:
        raise ConfigError(f"{path}: needs at least two measurements")
    if ori:
        pose = np.column_stack([pos] + [t.columns[c] for c in ("roll", "pitch", "yaw")])
        return "pose", q, pose_to_matrix(pose)
    return "position", q, pos


def write_csv(path, header: list[str], rows) -> None:
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(header)
        for r in rows:
            w.writerow([repr(float(v)) for v in r])
