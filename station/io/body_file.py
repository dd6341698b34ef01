"""The calibration body from its CMM report: a CSV of measuring points (docs/data-files.md,
"Calibration body (CMM report)").

One row per measuring point (a cube corner): its id, the pose of its corner frame in the body
frame, and optionally the CMM's uncertainty of that point::

    # body B-2, CMM report 2026-11-02, lab XY
    # certificate_id: CMM-2026-0142
    # certificate_date: 2026-11-02
    id,x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg,sigma_position_um,sigma_angle_arcsec
    C1.a,-28.3,-319.7,40.0,0.0,0.0,10.0,2.0,5.0
    C1.b,11.1,-312.8,40.0,0.0,0.0,100.0,,

Every column but ``id`` carries its unit, as a suffix (``x_mm``) or in brackets (``x [mm]``):
lengths ``mm``, ``m``, ``um`` (``µm``); angles ``deg``, ``rad``, ``arcsec``. A report in metres is
read as such when its columns say so (``x_m``); one whose columns say mm but whose points all lie
within a few mm of each other is refused as a likely unit mistake. An empty σ cell (or no σ
column) means "not given": the configuration's ``[body]`` default applies. Comment lines (``#``)
are ignored, except two optional ones the report's traceability names: ``# certificate_id: …``
and ``# certificate_date: YYYY-MM-DD`` (``=`` may stand for ``:``), each at most once.

The file is read only if it is a regular file of a sane size
(:func:`station.io.robot.files.read_user_text`). Anything malformed — a missing or unknown
column, a column without unit, a row of the wrong length, a value that is not a finite number,
a value out of bounds, an id given twice — is a :class:`~station.errors.ConfigError` naming the
file, the line and the column, and saying what to write instead.
"""

from __future__ import annotations

import csv
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from station.core.kinematics.transforms import pose_to_matrix
from station.core.units import ARCSEC, DEG, UM
from station.errors import ConfigError
from station.io.certificate import Certificate, check_certificate_date, check_certificate_id
from station.io.robot.files import read_user_text

#: a body report larger than this is refused before it is read (5 000 points are ~0.5 MB)
MAX_BODY_FILE_BYTES = 4 * 1024 * 1024
MIN_POINTS, MAX_POINTS = 3, 5000
#: positions within ±10 m of the body frame, angles within ±360 deg (as in the configuration)
MAX_POSITION_MM = 10_000.0
MAX_ANGLE_RAD = 2.0 * math.pi
#: bounds of the σ columns: position [mm], angle [rad]
MAX_SIGMA_POSITION_MM = 1.0
MAX_SIGMA_ANGLE_RAD = 3600.0 * ARCSEC
#: points of a real body lie further apart than this [mm]; closer means the numbers are in metres
MIN_BODY_EXTENT_MM = 5.0

_LENGTH = {"mm": 1.0, "m": 1000.0, "um": UM, "µm": UM}
_ANGLE = {"deg": DEG, "rad": 1.0, "arcsec": ARCSEC}
_POSE_COLUMNS = ("x", "y", "z", "roll", "pitch", "yaw")
_SIGMA_COLUMNS = ("sigma_position", "sigma_angle")
_KIND = {"x": _LENGTH, "y": _LENGTH, "z": _LENGTH, "roll": _ANGLE, "pitch": _ANGLE, "yaw": _ANGLE,
         "sigma_position": _LENGTH, "sigma_angle": _ANGLE}
_EXAMPLE = {"x": "x_mm", "y": "y_mm", "z": "z_mm", "roll": "roll_deg", "pitch": "pitch_deg", "yaw": "yaw_deg",
            "sigma_position": "sigma_position_um", "sigma_angle": "sigma_angle_arcsec"}
_HEADER_HINT = ("id,x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg and optionally "
                "sigma_position_um,sigma_angle_arcsec")
_SUFFIX = re.compile(r"^(?P<name>.+?)_(?P<unit>mm|m|um|µm|deg|rad|arcsec)$")
_BRACKET = re.compile(r"^(?P<name>[^\[]+?)\s*\[\s*(?P<unit>[^\]]*?)\s*\]$")
_CONTROL = re.compile(r"[\x00-\x1f\x7f]")
_CERTIFICATE = re.compile(r"^\s*#\s*(?P<key>certificate_id|certificate_date)\s*[:=]\s*(?P<value>.*?)\s*$")


@dataclass(frozen=True, eq=False)
class BodyReport:
    """The measuring points of a calibration body, in mm and rad.

    ``ids``: ``(n,)`` names; ``poses``: ``(n, 6)`` x, y, z [mm], roll, pitch, yaw [rad] of every
    corner frame in the body frame; ``sigma``: ``(n, 2)`` σ of every point, position [mm] (per
    coordinate) and angle [rad] (per axis), NaN where the report gives none.
    """

    path: str
    ids: tuple[str, ...]
    poses: np.ndarray
    sigma: np.ndarray
    certificate: Certificate = Certificate()  # the body's CMM certificate (empty: the file names none)

    def matrices(self) -> np.ndarray:
        """``(n, 4, 4)`` KKS←MPKS poses of the points."""
        return pose_to_matrix(self.poses)

    def sigma_with_default(self, position_mm: float, angle_rad: float) -> np.ndarray:
        """``(n, 2)`` σ with the given default where the report gives none."""
        return np.where(np.isnan(self.sigma), np.array([position_mm, angle_rad]), self.sigma)


def _ro(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


def _column(path: Path, lineno: int, header: str) -> tuple[str, float | None]:
    """(name, scale to mm | rad) of a header cell; ``id`` has no unit (scale None)."""
    h = header.strip()
    if not h:
        raise ConfigError(f"{path}: line {lineno}: a column without a name; remove the empty column (a trailing "
                          f"separator?) or name it; the header is {_HEADER_HINT}")
    if h.lower() == "id":
        return "id", None
    m = _SUFFIX.match(h) or _BRACKET.match(h)
    if m is None:
        base, _, unit = h.lower().rpartition("_")
        if base in _KIND:  # a known column with a unit that is none
            kind = "a length" if _KIND[base] is _LENGTH else "an angle"
            raise ConfigError(f"{path}: line {lineno}, column {h!r}: {unit!r} is not {kind} unit; use one of "
                              f"{', '.join(_KIND[base])} (e.g. {_EXAMPLE[base]!r})")
        base = h.lower()
        if base in _KIND:
            raise ConfigError(f"{path}: line {lineno}, column {h!r}: no unit; write it as {_EXAMPLE[base]!r} "
                              f"(or with another unit: mm, m, um for lengths; deg, rad, arcsec for angles)")
        raise ConfigError(f"{path}: line {lineno}, column {h!r}: unknown column; the header is {_HEADER_HINT}")
    name, unit = m.group("name").strip().lower(), m.group("unit").strip()
    if name not in _KIND:
        raise ConfigError(f"{path}: line {lineno}, column {h!r}: unknown column {name!r}; the header is {_HEADER_HINT}")
    units = _KIND[name]
    if unit not in units:
        kind = "a length" if units is _LENGTH else "an angle"
        raise ConfigError(f"{path}: line {lineno}, column {h!r}: {unit!r} is not {kind} unit; use one of "
                          f"{', '.join(units)} (e.g. {_EXAMPLE[name]!r})")
    return name, units[unit]


def _number(path: Path, lineno: int, col: str, text: str, decimal_comma: bool) -> float:
    s = text.strip()
    if decimal_comma:
        s = s.replace(",", ".")
    try:
        v = float(s)
    except ValueError:
        shown = repr(text.strip()) if text.strip() else "an empty cell"
        raise ConfigError(f"{path}: line {lineno}, column {col!r}: {shown} is not a number; write a decimal "
                          f"number such as 12.5") from None
    if not math.isfinite(v):
        raise ConfigError(f"{path}: line {lineno}, column {col!r}: {text.strip()!r} is not a finite number; "
                          f"give the value from the CMM report")
    return v


def _certificate(path: Path, text: str) -> Certificate:
    """The ``# certificate_id:`` and ``# certificate_date:`` comment lines (see the module)."""
    found: dict[str, tuple[int, str]] = {}
    for lineno, line in enumerate(text.splitlines(), 1):
        m = _CERTIFICATE.match(line)
        if m is None:
            continue
        key = m["key"]
        if key in found:
            raise ConfigError(f"{path}: line {lineno}: {key} was already given on line {found[key][0]}; keep one")
        check = check_certificate_id if key == "certificate_id" else check_certificate_date
        try:
            found[key] = (lineno, check(m["value"]))
        except ValueError as exc:
            raise ConfigError(f"{path}: line {lineno}: {key}: {exc}") from None
    return Certificate(found.get("certificate_id", (0, ""))[1], found.get("certificate_date", (0, ""))[1])


def read_body_file(path: str | Path) -> BodyReport:
    """The body report at ``path`` (see the module). Raises :class:`ConfigError` naming file,
    line and column for anything that cannot be used."""
    p = Path(path)
    text = read_user_text(p, MAX_BODY_FILE_BYTES, "body file",
                          missing="no such body file; give the path of the body's CMM report (CSV), "
                                  "relative to the configuration file")
    lines = [(i + 1, line) for i, line in enumerate(text.splitlines())
             if line.strip() and not line.lstrip().startswith("#")]
    if not lines:
        raise ConfigError(f"{p}: the body file is empty; it needs the header {_HEADER_HINT} and one row per point")
    head_no, head_line = lines[0]
    # a report exported with semicolons (German locale) has decimal commas: both are read
    delimiter = ";" if ";" in head_line and "," not in head_line else ","
    rows = list(csv.reader([line for _, line in lines], delimiter=delimiter))
    header = [h.strip() for h in rows[0]]
    cols = [_column(p, head_no, h) for h in header]
    names = [c[0] for c in cols]
    for k, n in enumerate(names):
        if n in names[:k]:
            raise ConfigError(f"{p}: line {head_no}, column {header[k]!r}: {n!r} appears twice in the header; "
                              f"keep one column per quantity")
    missing = [_EXAMPLE.get(n, n) for n in ("id", *_POSE_COLUMNS) if n not in names]
    if missing:
        raise ConfigError(f"{p}: line {head_no}: column{'s' if len(missing) > 1 else ''} {', '.join(missing)} "
                          f"missing; the header is {_HEADER_HINT} (got {','.join(header)})")
    n_rows = len(rows) - 1

    def count_error() -> ConfigError:
        return ConfigError(f"{p}: {n_rows} measuring points; a body file gives {MIN_POINTS} … {MAX_POINTS} "
                           f"(one row per point)")

    if n_rows > MAX_POINTS:
        raise count_error()
    ids: list[str] = []
    first_line: dict[str, int] = {}
    poses = np.empty((n_rows, 6))
    sigma = np.full((n_rows, 2), np.nan)
    for r, ((lineno, _), row) in enumerate(zip(lines[1:], rows[1:])):
        if len(row) != len(header):
            raise ConfigError(f"{p}: line {lineno}: {len(row)} values, the header has {len(header)} columns; "
                              f"give one value per column (an empty σ cell is allowed)")
        for k, ((name, scale), cell) in enumerate(zip(cols, row)):
            col = header[k]
            if name == "id":
                pid = cell.strip()
                if not pid or len(pid) > 64 or _CONTROL.search(pid):
                    raise ConfigError(f"{p}: line {lineno}, column {col!r}: the id must be 1 … 64 printable "
                                      f"characters, got {pid!r}")
                if pid in first_line:
                    raise ConfigError(f"{p}: line {lineno}, column {col!r}: id {pid!r} was already given on line "
                                      f"{first_line[pid]}; ids must be unique (rename one point)")
                first_line[pid] = lineno
                ids.append(pid)
                continue
            assert scale is not None
            if name in _SIGMA_COLUMNS and not cell.strip():
                continue  # not given: the [body] default applies
            v = _number(p, lineno, col, cell, delimiter == ";") * scale
            if name in _SIGMA_COLUMNS:
                bound = MAX_SIGMA_POSITION_MM if name == "sigma_position" else MAX_SIGMA_ANGLE_RAD
                if not 0.0 <= v <= bound:
                    limit = f"{bound / UM:g} µm" if name == "sigma_position" else f"{bound / ARCSEC:g} arc seconds"
                    raise ConfigError(f"{p}: line {lineno}, column {col!r}: {cell.strip()} is outside 0 … {limit}; "
                                      f"give the CMM's standard uncertainty of the point (0: exact)")
                sigma[r, _SIGMA_COLUMNS.index(name)] = v
            else:
                bound = MAX_POSITION_MM if name in ("x", "y", "z") else MAX_ANGLE_RAD
                if abs(v) > bound:
                    limit = "±10000 mm" if name in ("x", "y", "z") else "±360 deg"
                    hint = (" (degrees in a rad column? label it with _deg)" if scale == 1.0 and name not in ("x", "y", "z")
                            else "; check the column's unit")
                    raise ConfigError(f"{p}: line {lineno}, column {col!r}: {cell.strip()} is outside {limit}{hint}")
                poses[r, _POSE_COLUMNS.index(name)] = v
    if n_rows < MIN_POINTS:  # after the rows: a malformed row is the more useful message
        raise count_error()
    pos = poses[:, :3]
    extent = float(np.max(np.linalg.norm(pos - pos.mean(axis=0), axis=1))) * 2.0
    if extent < MIN_BODY_EXTENT_MM:
        x_col = header[names.index("x")]
        raise ConfigError(f"{p}: the {n_rows} points lie within {extent:.3g} mm of each other (column {x_col!r} "
                          f"read as given), too close for a calibration body: is the report in metres? Label the "
                          f"columns x_m, y_m, z_m or convert the numbers to mm")
    return BodyReport(str(p), tuple(ids), _ro(poses), _ro(sigma), _certificate(p, text))
