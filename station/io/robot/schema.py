"""The TOML robot file's schema (docs/robot-file.md), as strict as the cell configuration's
(:mod:`station.cell.config.schema`: pydantic v2 sections in strict mode, unknown keys refused):
an unknown table or key is refused with the nearest known name (``lenght_unit`` → "did you mean
'length_unit'?"), so a typo never silently falls back to a default. The semantics (units, limits,
the joint map's joints) stay with :func:`station.core.kinematics.model.robot_from_dict` and
:mod:`station.io.robot.files`; physical plausibility (:mod:`station.io.robot.bounds`) holds for
every robot file format. Imported only where a TOML robot file is read (pydantic's import is not
free: ``station --help`` and the built-in robots do without it).
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from station.errors import ConfigError
from station.io.robot.bounds import nearest

_NO_CONTROL = r"^[^\x00-\x1f\x7f]*$"

Name = Annotated[str, Field(min_length=1, max_length=128, pattern=_NO_CONTROL)]
Number = float  # strict: an int or a finite float, never a bool or a string


class _Section(BaseModel):
    # as the cell configuration's sections: strict types, finite numbers, unknown keys refused
    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False, frozen=True)


class _Robot(_Section):
    name: Name
    description: str = Field("", max_length=4096)
    angle_unit: Literal["deg", "rad"] = "deg"
    length_unit: Literal["mm", "m"] = "mm"
    prefer: list[Name] = Field(default_factory=list, max_length=1024)
    # the data sheet's ISO 9283 pose repeatability RP [mm] (its value is checked, with the fix,
    # by station.core.kinematics.model.check_repeatability)
    repeatability_mm: Any = None


class _Transform(_Section):
    name: Name
    joint: Literal["revolute", "prismatic"] | None = None
    limits: Annotated[tuple[Number, Number], Field(strict=False)] | None = None
    max_speed: Number | None = Field(None, gt=0)
    x: Number = 0.0
    y: Number = 0.0
    z: Number = 0.0
    roll: Number = 0.0
    pitch: Number = 0.0
    yaw: Number = 0.0


class _MapEntry(_Section):
    sign: Number = 1.0
    offset: Number = 0.0
    coupled_to: Name | None = None
    k: Number | None = None


class _Tool(_Section):
    unknown: bool = False


class _ErrorTerms(_Section):
    # the error terms beyond geometry an identification kept (issue 30; docs/error-terms.md)
    families: list[Name] = Field(default_factory=list, max_length=256)
    values: dict[str, Number] = Field(default_factory=dict)
    sigma: dict[str, Number] = Field(default_factory=dict)
    units: dict[str, str] = Field(default_factory=dict)
    effect_on_fit_um: Number | None = None
    geometric_params: list[Number] | None = Field(default=None, max_length=6 * 258)


class _Gravity(_Section):
    # what the compliance term's gravity torques come from (issue 30; docs/error-terms.md)
    masses_kg: list[Number] | None = Field(default=None, max_length=64)
    com_mm: list[Annotated[tuple[Number, Number, Number], Field(strict=False)]] | None = Field(default=None,
                                                                                             max_length=64)
    payload_kg: Number = 0.0
    payload_com_mm: Annotated[tuple[Number, Number, Number], Field(strict=False)] = (0.0, 0.0, 0.0)
    direction: Annotated[tuple[Number, Number, Number], Field(strict=False)] = (0.0, 0.0, -1.0)


class _Gears(_Section):
    # the gear ratio of every joint: the cyclic terms cycle with the motor angle (issue 30)
    ratios: list[Number] = Field(default_factory=list, max_length=64)


class _Collision(_Section):
    # the links' collision capsules (issue 40; docs/robot-file.md "Collision shapes")
    radius_mm: list[Number] | None = Field(default=None, max_length=257)
    allowed_pairs: list[Annotated[tuple[Name, Name], Field(strict=False)]] = Field(default_factory=list, max_length=1024)


class _RobotFile(_Section):
    robot: _Robot
    transform: list[_Transform] = Field(min_length=3, max_length=256)
    joint_map: dict[str, _MapEntry] = Field(default_factory=dict)
    tool: _Tool = Field(default_factory=_Tool)
    error_terms: _ErrorTerms = Field(default_factory=_ErrorTerms)
    gravity: _Gravity = Field(default_factory=_Gravity)
    gears: _Gears = Field(default_factory=_Gears)
    collision: _Collision = Field(default_factory=_Collision)


_NOTES = {"tool": "the tool itself is the last [[transform]]"}
_TABLES = {"robot": "[robot]", "transform": "[[transform]]", "joint_map": "[joint_map]", "tool": "[tool]",
           "error_terms": "[error_terms]", "gravity": "[gravity]", "gears": "[gears]",
           "collision": "[collision]"}


def validate_robot_toml(data: dict, source: str) -> None:
    """Refuse a robot file whose tables or keys the station does not know, with the nearest known
    name; the first five are named. A wrong value is left to the readers that know its fix."""
    try:
        _RobotFile.model_validate(data)
    except ValidationError as exc:
        errors = exc.errors(include_url=False)
        # unknown names first: the readers after this one name a wrong value with its own fix
        # (robot_from_dict, the joint map's and the tool's readers), so only they are left to them
        if not any(e["type"] == "extra_forbidden" for e in errors):
            return
        msgs = list(dict.fromkeys(_describe(dict(e), data) for e in errors if e["type"] == "extra_forbidden"))
        more = f" (and {len(msgs) - 5} more)" if len(msgs) > 5 else ""
        raise ConfigError(f"{source}: " + "; ".join(msgs[:5]) + more) from None


def _where(loc: tuple, data: dict) -> str:
    """``[robot]``, ``[[transform]] 'A2'``, ``[joint_map.A3]``: the table a location points into."""
    if not loc:
        return "the file"
    if loc[0] == "transform" and len(loc) > 1 and isinstance(loc[1], int):
        entries = data.get("transform")
        entry = entries[loc[1]] if isinstance(entries, list) and loc[1] < len(entries) else None
        name = entry.get("name") if isinstance(entry, dict) else None
        return f"[[transform]] {name!r}" if isinstance(name, str) else f"[[transform]] number {loc[1] + 1}"
    if loc[0] == "joint_map" and len(loc) > 1:
        return f"[joint_map.{loc[1]}]"
    return _TABLES.get(str(loc[0]), f"[{loc[0]}]")


def _fields_at(loc: tuple) -> tuple[str, ...]:
    model: Any = _RobotFile
    for part in loc:
        if isinstance(part, int) or model is None:
            continue
        if model is _RobotFile and part == "joint_map":
            model = "map"
            continue
        if model == "map":
            model = _MapEntry
            continue
        info = model.model_fields.get(part)
        model = _section(info.annotation) if info is not None else None
    return tuple(model.model_fields) if isinstance(model, type) and issubclass(model, BaseModel) else ()


def _section(annotation: Any) -> Any:
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for arg in getattr(annotation, "__args__", ()):
        found = _section(arg)
        if found is not None:
            return found
    return None


def _describe(err: dict, data: dict) -> str:
    """An unknown table or key, where it is, the nearest known name and the allowed ones."""
    loc = tuple(err["loc"])
    key = str(loc[-1])
    if len(loc) == 1:
        return (f"unknown table [{key}]{nearest(key, tuple(_TABLES))}; a robot file has "
                f"{', '.join(_TABLES.values())} (an unknown table would otherwise be ignored)")
    known = _fields_at(loc[:-1])
    note = _NOTES.get(str(loc[0]), "an unknown key would otherwise be ignored")
    return f"{_where(loc[:-1], data)}: unknown key {key!r}{nearest(key, known)}; allowed: {', '.join(known)} ({note})"
