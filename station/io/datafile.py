"""Measurement and joint files (CSV), as a user with a laser tracker or a CMM would have them.

Format (docs/data-files.md): optional ``#`` comment lines, then a header whose every column
carries its unit in brackets, then one row per measurement::

    # measured with tracker T-1, 2026-11-20
    q1 [deg],q2 [deg],q3 [mm],q4 [deg],x [mm],y [mm],z [mm],roll [deg],pitch [deg],yaw [deg]
    10.0,45.0,-50.0,0.0,812.331,402.118,431.072,0.0012,-0.0031,55.0004

Joint columns ``q1 … qg`` (deg | rad for revolute, mm | m for prismatic joints); measured
position ``x, y, z`` (mm | m), or the three reflectors of a nest ``x1, y1, z1 … x3, y3, z3``
(one pose); orientation ``roll, pitch, yaw`` (deg | rad | arcsec) makes the file a pose file,
without it a position file. A joints file (for ``station predict``) has only the joint columns.
Optional ``time [s|min|h]``, ``approach1 … approachg [sign]`` (±1) and ``payload [kg]`` columns time
the drift, give the backlash its sides and load the compliance term (``identify --model``, issue 30).

As instruments export them: UTF-8 (with or without a byte-order mark), UTF-16 with its mark, or
a single-byte code page (cp1252, else latin-1), each noted; names in any case (``X [mm]`` is
``x``), the unit in brackets or parentheses; ``;`` or tab separators with decimal commas; columns
of no known name (point ids, time stamps, temperatures) ignored, with a note naming them.
"""

from __future__ import annotations

import csv
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from station.core.kinematics.model import RobotModel
from station.core.kinematics.transforms import pose_to_matrix
from station.core.units import ARCSEC, DEG, UM
from station.errors import ConfigError

_SCALE = {"mm": 1.0, "m": 1000.0, "um": UM, "µm": UM, "deg": DEG, "rad": 1.0, "arcsec": ARCSEC,
          "s": 1.0, "min": 60.0, "h": 3600.0, "sign": 1.0, "kg": 1.0}
#: the time of a row (drift) and the side each joint arrived from (backlash): issue 30
_TIME_UNITS = ("s", "min", "h")
# spellings of instrument exports for the units above (after lower-casing)
_UNIT_ALIASES = {"μm": "µm", "micron": "um", "°": "deg", "degree": "deg", "degrees": "deg",
                 "radian": "rad", "radians": "rad", '"': "arcsec", "″": "arcsec"}
_LENGTH_UNITS = ("mm", "m", "um", "µm")
MAX_FILE_BYTES = 256 * 2**20
_ANGLE_UNITS = ("deg", "rad", "arcsec")
_HEADER = re.compile(r"^(?P<name>.*?)\s*[\[(]\s*(?P<unit>[^\])]*?)\s*[\])]$")
NEST_COLUMNS = tuple(f"{c}{k}" for k in (1, 2, 3) for c in "xyz")
_KNOWN = {"x", "y", "z", "roll", "pitch", "yaw", *NEST_COLUMNS}
#: the three reflectors of a nest keep their distances to each other; a row whose distances differ
#: from the file's median by more than this [mm] has a reflector mismatched or moved
NEST_TOLERANCE_MM = 1.0


#: the largest joint length (100 m) and angle (2π·10 rad) a data file may hold: beyond them a value is a
#: typo or garbage, never a measurement (issue 33). Measured positions get a looser bound (1000 km), so
#: that a file in the wrong length unit reaches the check that names the unit it looks like.
LENGTH_BOUND_MM = 100_000.0
POSITION_BOUND_MM = 1e9
ANGLE_BOUND_RAD = 20 * math.pi


def _bound_text(unit: str, bound: float) -> str:
    if unit in _ANGLE_UNITS:
        return f"±{ANGLE_BOUND_RAD / _SCALE[unit]:.6g} {unit} = 2π·10 rad"
    return f"±{bound / _SCALE[unit]:.6g} {unit} = {bound / 1e6:g} km" if bound > 1e6 else \
        f"±{bound / _SCALE[unit]:.6g} {unit} = {bound / 1000:g} m"


@dataclass(frozen=True)
class Table:
    """Parsed columns in internal units (mm, rad); ``columns`` maps name -> (n,) array.
    ``lines``: the file line of every row; ``notes``: what the reader did that the user should
    know (encoding, ignored columns)."""

    path: str
    columns: dict
    n_rows: int
    units: dict
    lines: tuple[int, ...] = ()
    notes: tuple[str, ...] = ()


def _is_known(name: str) -> bool:
    return (name in _KNOWN or (name.startswith("q") and name[1:].isdigit()) or name in ("time", "payload")
            or (name.startswith("approach") and name[8:].isdigit()))


def _decode(p: Path, raw: bytes) -> tuple[str, str | None]:
    """The text and, unless it was UTF-8, a note of the encoding it was read in."""
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")):
        try:
            return raw.decode("utf-16"), "read as UTF-16 (byte-order mark)"
        except UnicodeDecodeError as exc:
            raise ConfigError(f"{p}: starts with a UTF-16 byte-order mark but is not UTF-16 text "
                              f"(byte {exc.start}); export the data as CSV UTF-8") from None
    if b"\x00" in raw:
        raise ConfigError(f"{p}: holds NUL bytes, so it is no text file; export the data as CSV (UTF-8)")
    try:
        return raw.decode("utf-8-sig"), None  # a byte-order mark (Excel's "CSV UTF-8") is dropped
    except UnicodeDecodeError as exc:
        where = exc.start
    # instrument software on Windows writes its code page: cp1252 (µ, °, ä as one byte);
    # latin-1 takes the five bytes cp1252 leaves undefined
    for enc in ("cp1252", "latin-1"):
        try:
            return raw.decode(enc), f"not UTF-8 (byte {where}); read as {enc}"
        except UnicodeDecodeError:
            continue
    raise AssertionError("latin-1 decodes every byte")  # pragma: no cover


def _delimiter(header_line: str) -> str:
    counts = {d: header_line.count(d) for d in (",", ";", "\t")}
    if counts[","] == 0 and max(counts.values()) > 0:
        return max(counts, key=lambda d: counts[d])
    return ","


def _parse_header(p: Path, cells: list[str]) -> tuple[list[tuple[int, str, str]], list[str]]:
    """``(column, name, unit)`` of every used column, and the ignored columns' headers."""
    used, ignored = [], []
    for k, h in enumerate(cells):
        h = h.strip()
        m = _HEADER.match(h)
        name = (m.group("name") if m else h).strip().lower()
        if not _is_known(name):
            ignored.append(h or f"(column {k + 1}, no name)")
            continue
        if name == "time" and (m is None or _UNIT_ALIASES.get(m.group("unit").strip().lower(),
                                                              m.group("unit").strip().lower()) not in _TIME_UNITS):
            ignored.append(h)  # a time stamp (a date, hh:mm:ss) is not a time in s, min or h: as before, ignored
            continue
        if m is None:
            raise ConfigError(f"{p}: column {h!r} has no unit; write it like 'x [mm]' or 'q1 [deg]'")
        unit = m.group("unit").strip()
        unit = _UNIT_ALIASES.get(unit.lower(), unit.lower() if unit.lower() in _SCALE else unit)
        if unit not in _SCALE:
            raise ConfigError(f"{p}: column {name!r} has unknown unit {unit!r}; use one of {sorted(_SCALE)}")
        used.append((k, name, unit))
    names = [n for _, n, _ in used]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ConfigError(f"{p}: duplicate column names {dup} (names are read in any case: 'X' is 'x')")
    return used, ignored


def read_table(path: str | Path) -> Table:
    p = Path(path)
    if not p.exists():
        raise ConfigError(f"{p}: no such file")
    if not p.is_file():
        raise ConfigError(f"{p}: not a regular file; give the path of a CSV data file")
    with open(p, "rb") as f:
        raw = f.read(MAX_FILE_BYTES + 1)
    if len(raw) > MAX_FILE_BYTES:
        raise ConfigError(f"{p}: larger than {MAX_FILE_BYTES // 2**20} MB; split the measurements")
    text, enc_note = _decode(p, raw)
    notes = [enc_note] if enc_note else []
    lines = [(i + 1, line) for i, line in enumerate(text.splitlines())
             if line.strip() and not line.lstrip().startswith("#")]
    if not lines:
        raise ConfigError(f"{p}: empty; expected a header with units and one row per measurement")
    delim = _delimiter(lines[0][1])
    try:
        reader = list(csv.reader((line for _, line in lines), delimiter=delim))
    except csv.Error as exc:
        raise ConfigError(f"{p}: not readable as CSV ({exc}); export the data as CSV") from None
    used, ignored = _parse_header(p, reader[0])
    if ignored:
        notes.append(f"columns ignored (no known name): {', '.join(repr(h) for h in ignored)}")
    names = [n for _, n, _ in used]
    rows = reader[1:]
    data = np.empty((len(rows), len(used)))
    for r_i, ((lineno, _), row) in enumerate(zip(lines[1:], rows)):
        if len(row) != len(reader[0]):
            raise ConfigError(f"{p}, line {lineno}: {len(row)} values but {len(reader[0])} columns")
        for c, (k, name, unit) in enumerate(used):
            v = row[k].strip()
            try:
                x = float(v.replace(",", ".") if delim != "," else v)
            except ValueError:
                raise ConfigError(f"{p}, line {lineno}: {name} = {v!r} is not a number") from None
            if not math.isfinite(x):
                raise ConfigError(f"{p}, line {lineno}: {name} is {v}; remove or repair this row")
            data[r_i, c] = x * _SCALE[unit]
            bound = ANGLE_BOUND_RAD if unit in _ANGLE_UNITS else (
                LENGTH_BOUND_MM if name.startswith("q") else POSITION_BOUND_MM)
            if not abs(data[r_i, c]) <= bound:  # also 1e308 m, which overflows to inf in mm
                raise ConfigError(f"{p}, line {lineno}: {name} = {v} {unit} is beyond physical plausibility (at most "
                                  f"{_bound_text(unit, bound)}); repair this row or its unit")
    cols = {n: data[:, k] for k, n in enumerate(names)}
    for _, n, unit in used:
        kind = "angle" if unit in _ANGLE_UNITS else "length" if unit in _LENGTH_UNITS else unit
        if n == "payload" and unit != "kg":
            raise ConfigError(f"{p}: column 'payload' is the mass the robot carries: write it 'payload [kg]'")
        if n.startswith("approach") and unit != "sign":
            raise ConfigError(f"{p}: column {n!r} is the side the joint arrived from: write it '{n} [sign]', "
                              f"+1 or -1")
        if n.startswith("q") and kind not in ("angle", "length"):
            raise ConfigError(f"{p}: column {n!r} is a joint and needs deg, rad, mm or m")
        if (n in ("x", "y", "z") or n in NEST_COLUMNS) and kind != "length":
            raise ConfigError(f"{p}: column {n!r} is a position and needs a length unit (mm or m)")
        if n in ("roll", "pitch", "yaw") and kind != "angle":
            raise ConfigError(f"{p}: column {n!r} is an angle and needs deg, rad or arcsec")
    return Table(str(p), cols, len(rows), {n: u for _, n, u in used},
                 tuple(ln for ln, _ in lines[1:]), tuple(notes))


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
    if table.n_rows == 0:
        raise ConfigError(f"{table.path}: a header but no rows; add one row of joint values per pose")
    units = table.units
    for name, kind in zip(expected, model.joint_types):
        u = units[name]
        if kind == "revolute" and u not in _ANGLE_UNITS:
            raise ConfigError(f"{table.path}: {name} is a revolute joint and needs deg or rad, not {u}")
        if kind == "prismatic" and u not in _LENGTH_UNITS:
            raise ConfigError(f"{table.path}: {name} is a prismatic joint and needs mm or m, not {u}")
    return np.column_stack([table.columns[n] for n in expected])


@dataclass(frozen=True)
class MeasurementFile:
    """A measurement file read: ``kind`` pose | position, ``joints`` ``(n, g)``, ``measured``
    poses ``(n, 4, 4)`` or positions ``(n, 3)`` [mm], and the reader's ``notes``."""

    kind: str
    joints: np.ndarray
    measured: np.ndarray
    notes: tuple[str, ...] = ()
    #: ``(n,)`` [s] the time of every row (a ``time`` column), or None
    time: np.ndarray | None = None
    #: ``(n, g)`` ±1 the side every joint arrived from (``approach1 … approachg [sign]``), or None
    approach: np.ndarray | None = None
    #: ``(n,)`` [kg] the payload of every row (a ``payload [kg]`` column), or None
    payload_kg: np.ndarray | None = None


def nest_frames(points: np.ndarray, path: str = "", lines: tuple[int, ...] = ()) -> np.ndarray:
    """``(n, 4, 4)`` poses of a nest from its three reflectors ``(n, 3, 3)`` [mm] (reflector 1,
    2, 3 of every row): origin at their centroid, x towards reflector 2 from reflector 1, z normal
    to their plane (right-handed 1 → 2 → 3), y = z × x. Refuses reflectors on one line and rows
    whose reflector distances differ from the file's median by more than ``NEST_TOLERANCE_MM``."""
    P = np.asarray(points, dtype=float)

    def where(i: int) -> str:
        return f"{path}, line {lines[i]}" if lines else f"{path}, row {i + 1}"

    sides = np.stack([np.linalg.norm(P[:, 1] - P[:, 0], axis=1), np.linalg.norm(P[:, 2] - P[:, 1], axis=1),
                      np.linalg.norm(P[:, 0] - P[:, 2], axis=1)], axis=1)
    ex = P[:, 1] - P[:, 0]
    nz = np.cross(ex, P[:, 2] - P[:, 0])
    area2 = np.linalg.norm(nz, axis=1)
    # sine of the triangle's smallest angle: below 0.05 (3°) the plane, and so the orientation, is lost
    flat = area2 < 0.05 * np.max(sides, axis=1) ** 2
    if flat.any():
        i = int(np.argmax(flat))
        raise ConfigError(f"{where(i)}: the three reflectors lie on one line (or two coincide), so they give "
                          f"no orientation; check the reflector columns x1 … z3 of this row")
    dev = np.abs(sides - np.median(sides, axis=0))
    if np.any(dev > NEST_TOLERANCE_MM):
        r, k = (int(v) for v in np.unravel_index(int(np.argmax(dev)), dev.shape))
        pair = ("1–2", "2–3", "3–1")[k]
        raise ConfigError(
            f"{where(r)}: reflectors {pair} lie {sides[r, k]:.3f} mm apart, the nest's median is "
            f"{np.median(sides[:, k]):.3f} mm: a reflector was read in the wrong column or moved on the nest; "
            f"repair or remove this row")
    x = ex / np.linalg.norm(ex, axis=1)[:, None]
    z = nz / area2[:, None]
    y = np.cross(z, x)
    T = np.tile(np.eye(4), (len(P), 1, 1))
    T[:, :3, 0], T[:, :3, 1], T[:, :3, 2] = x, y, z
    T[:, :3, 3] = P.mean(axis=1)
    return T


def read_measurement_file(path, model: RobotModel) -> MeasurementFile:
    """Read a pose or position file (see the module); nest columns give a pose per row; ``time`` and
    ``approach1 … approachg`` columns, where present, as the file's time and approach signs."""
    import dataclasses

    t = read_table(path)
    mf = _measurement_file(path, model, t)
    time = t.columns.get("time")
    app = [n for n in t.columns if n.startswith("approach")]
    approach = None
    if app:
        expected = [f"approach{j}" for j in range(1, model.n_joints + 1)]
        if sorted(app, key=lambda n: int(n[8:])) != expected:
            raise ConfigError(f"{path}: the approach columns must be {', '.join(expected)} (one per joint), "
                              f"found {', '.join(app)}")
        approach = np.column_stack([t.columns[n] for n in expected])
        if not np.all(np.isin(approach, (-1.0, 1.0))):
            raise ConfigError(f"{path}: approach values must be +1 or -1 (the side the joint arrived from)")
    payload = t.columns.get("payload")
    if payload is not None and not np.all(payload >= 0):
        raise ConfigError(f"{path}: payload values must be ≥ 0 kg")
    if time is None and approach is None and payload is None:
        return mf
    return dataclasses.replace(mf, time=time, approach=approach, payload_kg=payload)


def _measurement_file(path, model: RobotModel, t: Table) -> MeasurementFile:
    q = joints_from_table(t, model)
    nest = [c for c in NEST_COLUMNS if c in t.columns]
    ori = [c for c in ("roll", "pitch", "yaw") if c in t.columns]
    if t.n_rows < 2:
        raise ConfigError(f"{path}: needs at least two measurements")
    if nest:
        if len(nest) != len(NEST_COLUMNS):
            missing = [c for c in NEST_COLUMNS if c not in t.columns]
            raise ConfigError(f"{path}: a nest of three reflectors needs x1, y1, z1, x2, y2, z2, x3, y3, z3; "
                              f"missing {', '.join(missing)}")
        extra = [c for c in ("x", "y", "z", *ori) if c in t.columns]
        if extra:
            raise ConfigError(f"{path}: give either the nest's three reflectors (x1 … z3) or one point "
                              f"(x, y, z with roll, pitch, yaw), not both; found also {', '.join(extra)}")
        P = np.stack([np.column_stack([t.columns[f"{c}{k}"] for c in "xyz"]) for k in (1, 2, 3)], axis=1)
        frames = nest_frames(P, str(path), t.lines)
        return MeasurementFile("pose", q, frames, t.notes + ("three reflectors per row read as the nest's pose "
                                                             "(origin at their centroid, x from 1 to 2)",))
    missing = [c for c in ("x", "y", "z") if c not in t.columns]
    if missing:
        raise ConfigError(f"{path}: measured position columns {missing} missing; add 'x [mm]' etc. "
                          f"(or a nest's x1 … z3)")
    pos = np.column_stack([t.columns[c] for c in ("x", "y", "z")])
    if ori and len(ori) != 3:
        raise ConfigError(f"{path}: a pose file needs all of roll, pitch, yaw; found only {ori}")
    if ori:
        pose = np.column_stack([pos] + [t.columns[c] for c in ("roll", "pitch", "yaw")])
        return MeasurementFile("pose", q, pose_to_matrix(pose), t.notes)
    return MeasurementFile("position", q, pos, t.notes)


def read_measurements(path, model: RobotModel):
    """``(kind, joints (n,g), measured)`` with measured poses (n,4,4) or positions (n,3)."""
    f = read_measurement_file(path, model)
    return f.kind, f.joints, f.measured


def write_csv(path, header: list[str], rows) -> None:
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(header)
        for r in rows:
            w.writerow([repr(float(v)) for v in r])
