"""The probe-head file (TOML, ``docs/probe-head.md``): the head a user built, as its CMM report
and the probes' certificates describe it.

Checked in three stages, each failure a :class:`ConfigError` naming the key and the fix:

1. the schema (pydantic v2, strict, unknown keys refused, every number bounded);
2. each probe: a unit measuring direction (normalised; a length off by more than 1 % is a typo),
   unique ids and channels;
3. the arrangement (:func:`station.core.probe.check.check_arrangement`): the probes must fix all
   six degrees of freedom of the cube corner at the nominal touch, and every nominal reading
   must lie inside its probe's stroke with a margin (:class:`ProbeHeadGeometry`).
"""

from __future__ import annotations

import reprlib
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from station.core.kinematics.transforms import pose_to_matrix
from station.core.probe.check import ArrangementReport, check_arrangement, check_head
from station.core.probe.geometry import ProbeHeadGeometry
from station.core.units import DEG
from station.errors import ConfigError
from station.io.certificate import Certificate, check_certificate_date, check_certificate_id
from station.io.robot.files import read_user_text

__all__ = ["HeadFile", "load_head", "parse_head", "MAX_HEAD_BYTES", "FACES", "head_to_toml"]

MAX_HEAD_BYTES = 256 * 1024
FACES = {"top": 0, "x": 1, "y": 2}
_NO_CONTROL = r"^[^\x00-\x1f\x7f]*$"
_MM = 2000.0  # a head is smaller than 2 m

Mm = Annotated[float, Field(ge=-_MM, le=_MM)]
Deg = Annotated[float, Field(ge=-360.0, le=360.0)]
Pose = Annotated[tuple[Mm, Mm, Mm, Deg, Deg, Deg], Field(strict=False)]
Vec = Annotated[tuple[Mm, Mm, Mm], Field(strict=False)]
Unit = Annotated[tuple[float, float, float], Field(strict=False)]


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False, frozen=True)


class _Head(_Section):
    name: str = Field("probe head", min_length=1, max_length=256, pattern=_NO_CONTROL,
                      description="the head's name, 1 … 256 characters")
    frame_in_flange: Pose = Field(
        description="pose of the head frame MKKS in the flange frame from the head's CMM report: "
                    "[x, y, z] mm within ±2000, [roll, pitch, yaw] deg within ±360")
    nominal_contact: Pose = Field(
        description="pose of the cube corner frame MPKS in MKKS at the nominal touch: "
                    "[x, y, z] mm within ±2000, [roll, pitch, yaw] deg within ±360")
    reading_sigma_um: float = Field(0.5, gt=0.0, le=100.0,
                                    description="σ of one probe reading [µm] (certificate repeatability), > 0 … 100")
    # the head's CMM certificate, for the report's traceability (optional)
    certificate_id: str | None = Field(None, description='the ID of the head\'s CMM certificate, e.g. "CMM-2026-0142"')
    certificate_date: str | None = Field(None, description="the date of the head's CMM measurement, YYYY-MM-DD")

    @field_validator("certificate_id", mode="before")
    @classmethod
    def _cert_id(cls, v: Any) -> Any:
        return None if v is None else check_certificate_id(v)

    @field_validator("certificate_date", mode="before")
    @classmethod
    def _cert_date(cls, v: Any) -> Any:  # a TOML date (2026-11-02) or a string of that form
        return None if v is None else check_certificate_date(v)


class _Probe(_Section):
    id: str = Field(min_length=1, max_length=32, pattern=_NO_CONTROL,
                    description='the probe\'s name on the head drawing, e.g. "P3", 1 … 32 characters')
    channel: int = Field(ge=1, le=64, description="its channel on the interface unit, 1 … 64 (1-based)")
    mount_mm: Vec = Field(description="tip-sphere centre at reading 0 in MKKS: [x, y, z] mm within ±2000")
    direction: Unit = Field(description="measuring direction in MKKS, a unit vector [x, y, z] pointing "
                                        "from the probe body towards the surface")
    face: Literal["top", "x", "y"] = Field(description='the cube face it touches: "top", "x" or "y"')
    stroke_mm: float = Field(gt=0.0, le=100.0, description="measuring range [mm], > 0 … 100")
    tip_radius_mm: float = Field(ge=0.0, le=20.0, description="tip-sphere radius [mm], 0 … 20")
    scale: float = Field(1.0, ge=0.5, le=2.0, description="certificate scale factor, 0.5 … 2 (1: none)")

    @field_validator("direction")
    @classmethod
    def _unit(cls, v: tuple[float, float, float]) -> tuple[float, float, float]:
        n = float(np.linalg.norm(v))
        if not np.isfinite(n) or abs(n - 1.0) > 0.01:
            hint = (f"e.g. [{', '.join(f'{c / n:.4f}' for c in v)}]" if np.isfinite(n) and n > 0
                    else "e.g. [0.0, 0.0, -1.0]")
            raise ValueError(f"has length {n:.4g}; give a unit vector ({hint})")
        return v


class _HeadFile(_Section):
    head: _Head = Field(description="a table [head] with frame_in_flange and nominal_contact")
    probe: list[_Probe] = Field(min_length=1, max_length=15,
                                description="6 … 15 [[probe]] tables (id, channel, mount_mm, direction, face, "
                                            "stroke_mm, tip_radius_mm, optional scale)")

    @field_validator("probe")
    @classmethod
    def _unique(cls, probes: list[_Probe]) -> list[_Probe]:
        for key in ("id", "channel"):
            seen: set[Any] = set()
            for p in probes:
                v = getattr(p, key)
                if v in seen:
                    raise ValueError(f"two probes have {key} {v!r}; each probe needs its own {key}")
                seen.add(v)
        return probes


@dataclass(frozen=True, eq=False)
class HeadFile:
    """A loaded head: the geometry (``geometry.nominal_pose`` = MPKS in MKKS at the nominal
    touch), ``frame_in_flange (4,4)`` MKKS in the flange frame, ``frame_pose (6,)`` the same as
    [mm, rad], and the load-time ``report`` (rank, condition, sensitivity)."""

    geometry: ProbeHeadGeometry
    frame_in_flange: np.ndarray
    frame_pose: np.ndarray
    report: ArrangementReport
    source: str
    certificate: Certificate = Certificate()  # the head's CMM certificate (empty: the file gives none)


_short = reprlib.Repr()
_short.maxstring, _short.maxother, _short.maxlist = 60, 60, 8


def _field(loc: tuple) -> Any:
    model: Any = _HeadFile
    info = None
    for part in loc:
        if isinstance(part, int):
            continue
        fields = getattr(model, "model_fields", {})
        if part not in fields:
            return None
        info = fields[part]
        ann = info.annotation
        model = next((a for a in (ann, *getattr(ann, "__args__", ())) if isinstance(a, type)
                      and issubclass(a, BaseModel)), None)
    return info


def _key(loc: tuple) -> str:
    out = ""
    for part in loc:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out


def _describe(err: dict, probes: list) -> str:
    loc, typ = tuple(err["loc"]), err["type"]
    if typ == "missing" and loc and isinstance(loc[-1], int):  # a list too short for a tuple
        loc, typ = loc[:-1], "too_short"
    key = _key(loc)
    if len(loc) >= 2 and loc[0] == "probe" and isinstance(loc[1], int) and loc[1] < len(probes):
        pid = probes[loc[1]].get("id") if isinstance(probes[loc[1]], dict) else None
        if isinstance(pid, str):
            key += f" (probe {pid!r})"
    info = _field(loc)
    what = info.description if info is not None and info.description else ""
    if typ == "extra_forbidden":
        return f"{_key(loc[:-1]) or 'the file'}: unknown key {loc[-1]!r} (check the spelling; see docs/probe-head.md)"
    if typ == "missing":
        return f"{key} is missing; add {what or 'it'} (docs/probe-head.md)"
    if typ == "value_error":
        return f"{key}: {str(err['msg']).removeprefix('Value error, ')}"
    value = _short.repr(err.get("input", "?"))
    problem = {"finite_number": "not a finite number", "int_type": "expected an integer",
               "float_type": "expected a number", "string_type": "expected a string in quotes",
               "literal_error": "not one of the allowed values", "too_short": "has too few items",
               "too_long": "has too many items", "tuple_type": "expected a list [ … ]",
               "list_type": "expected a list", "model_type": "expected a table"}.get(typ, str(err["msg"]))
    if typ in ("greater_than", "greater_than_equal", "less_than", "less_than_equal"):
        problem = "out of range"
    return f"{key} = {value}: {problem}; expected {what}" if what else f"{key} = {value}: {problem}"


def parse_head(data: Any, source: str = "<head>", cube_edge_mm: float = 40.0) -> HeadFile:
    """A checked :class:`HeadFile` from parsed TOML (``cube_edge_mm``: the body's cube edge)."""
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: a head file is a TOML document with [head] and [[probe]] tables")
    try:
        f = _HeadFile.model_validate(data)
    except ValidationError as exc:
        raw = data.get("probe")
        probes: list = raw if isinstance(raw, list) else []
        msgs = list(dict.fromkeys(_describe(dict(e), probes) for e in exc.errors(include_url=False)))
        more = f" (and {len(msgs) - 5} more)" if len(msgs) > 5 else ""
        raise ConfigError(f"{source}: " + "; ".join(msgs[:5]) + more) from None
    h = f.head
    frame = np.array([*h.frame_in_flange[:3], *(a * DEG for a in h.frame_in_flange[3:])])
    contact = pose_to_matrix(np.array([*h.nominal_contact[:3], *(a * DEG for a in h.nominal_contact[3:])]))
    pts = np.array([p.mount_mm for p in f.probe], dtype=float)
    dirs = np.array([p.direction for p in f.probe], dtype=float)
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    faces = np.array([FACES[p.face] for p in f.probe])
    tips = np.array([p.tip_radius_mm for p in f.probe])
    labels = [f"{p.id} (channel {p.channel})" for p in f.probe]
    try:
        check_arrangement(pts, dirs, faces, tips, contact, cube_edge_mm, labels)
    except ConfigError as exc:
        raise ConfigError(f"{source}: [[probe]]: {exc}") from None
    if len(f.probe) < 6:  # (the arrangement check already named the unfixed motion)
        raise ConfigError(f"{source}: [[probe]]: {len(f.probe)} probes; a head needs 6 … 15")
    try:
        geom = ProbeHeadGeometry(
            pts, dirs, faces, tip_radius_mm=tips, stroke_mm=np.array([p.stroke_mm for p in f.probe]),
            cube_edge_mm=cube_edge_mm, nominal_pose=contact, ids=tuple(p.id for p in f.probe),
            channels=np.array([p.channel for p in f.probe]), scales=np.array([p.scale for p in f.probe]),
            name=h.name, reading_sigma_mm=h.reading_sigma_um * 1e-3)
        report = check_head(geom)
    except ConfigError as exc:
        raise ConfigError(f"{source}: [[probe]]: {exc}") from None
    except ValueError as exc:
        raise ConfigError(f"{source}: [[probe]] / head.nominal_contact: {exc}") from None
    T = pose_to_matrix(frame)
    T.flags.writeable = False
    frame.flags.writeable = False
    return HeadFile(geom, T, frame, report, source, Certificate(h.certificate_id or "", h.certificate_date or ""))


def load_head(path: str | Path, cube_edge_mm: float = 40.0) -> HeadFile:
    """Read and check a head file (a regular UTF-8 file of at most :data:`MAX_HEAD_BYTES`)."""
    p = Path(path)
    text = read_user_text(p, MAX_HEAD_BYTES, "probe-head file",
                          missing="no such probe-head file; see docs/probe-head.md and examples/heads/")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{p}: not valid TOML ({exc}); fix the syntax there") from None
    except RecursionError:
        raise ConfigError(f"{p}: not valid TOML (nested too deeply); fix the syntax there") from None
    return parse_head(data, str(p), cube_edge_mm)


def head_to_toml(geom: ProbeHeadGeometry, frame_in_flange: np.ndarray) -> str:
    """A head file for ``geom`` (``frame_in_flange`` (6,) [mm, rad]): how the examples are made."""
    from station.core.kinematics.transforms import matrix_to_pose

    def nums(v: Any, digits: int = 6) -> str:
        return "[" + ", ".join(f"{float(x):.{digits}g}" if abs(float(x)) >= 1e-12 else "0.0" for x in v) + "]"

    fr = np.asarray(frame_in_flange, dtype=float)
    c = matrix_to_pose(geom.nominal_contact_pose())
    face_name = {v: k for k, v in FACES.items()}
    out = [f'[head]\nname = "{geom.name}"',
           f"frame_in_flange = {nums([*fr[:3], *np.degrees(fr[3:])], 9)}",
           f"nominal_contact = {nums([*c[:3], *np.degrees(c[3:])], 9)}",
           f"reading_sigma_um = {geom.reading_sigma_mm * 1e3:g}", ""]
    for i in range(geom.n_probes):
        out += ["[[probe]]", f'id = "{geom.probe_ids[i]}"', f"channel = {int(geom.probe_channels[i])}",
                f"mount_mm = {nums(geom.mount_points[i], 9)}", f"direction = {nums(geom.directions[i], 9)}",
                f'face = "{face_name[int(geom.faces[i])]}"', f"stroke_mm = {float(geom.strokes[i]):g}",
                f"tip_radius_mm = {float(geom.tip_radii[i]):g}"]
        if geom.probe_scales[i] != 1.0:
            out.append(f"scale = {float(geom.probe_scales[i]):g}")
        out.append("")
    return "\n".join(out)
