"""The ``[error_terms]`` table of a TOML robot file (issue 30): the terms beyond geometry that an
identification kept, with their values, σ and units (docs/error-terms.md).

    [error_terms]
    families = ["compliance", "cyclic.q1"]

    [error_terms.values]           # each in its unit below
    "compliance.q2" = 1.467e-05
    "cyclic.q1.cos1" = -0.001283

    [error_terms.sigma]
    …
    [error_terms.units]
    "compliance.q2" = "rad per N·m of the lumped term"

``geometric_params``: the geometric fit of the same data (mm, rad, transform by transform), what a
format that cannot hold the terms (MDH, DH, URDF) is given; ``effect_on_fit_um``: the RMS distance
between it and the full model at the poses they were fitted on, what such a format loses there.

Only TOML robot files hold them; DH, MDH and URDF files have no place for them.

The ``[gravity]`` table says what the compliance term's gravity torques come from (without it: the
lumped unit masses of :mod:`station.core.terms.error_model`)::

    [gravity]
    masses_kg = [0, 120, 60, 20, 8, 2]        # the link each joint moves, one per joint
    com_mm = [[0, 0, 0], [0, -350, 0], …]     # each link's centre of mass in its frame after the joint
    payload_kg = 12.0                         # at payload_com_mm in the tool frame
    payload_com_mm = [0, 0, 80]
    direction = [0, 0, -1]                    # gravity in the robot base frame (default −z)

The ``[gears]`` table gives every joint's gear ratio, so that the cyclic terms cycle with the motor
angle (``ratios = [147, 153, 153, 76, 80, 51]``; without it, with the joint angle).
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

from station.core.terms.error_model import STANDARD_GRAVITY, GravityModel
from station.errors import ConfigError

__all__ = ["StoredTerms", "read_error_terms", "error_terms_toml", "read_gravity", "gravity_toml", "read_gear_ratios",
           "gears_toml"]


@dataclass(frozen=True)
class StoredTerms:
    """``families``; ``names``/``values``/``sigma``/``units``: per term, in the file's order."""

    families: tuple[str, ...]
    names: tuple[str, ...]
    values: tuple[float, ...]
    sigma: tuple[float, ...]
    units: tuple[str, ...]
    #: RMS [µm] between the full model and the geometric fit of the same data at the poses they were
    #: fitted on: what a format without the terms loses there (None: not stated)
    effect_on_fit_um: float | None = None
    #: the geometric fit of the same data [mm, rad], transform by transform: what a format without the
    #: terms is given (None: not stated)
    geometric_params: tuple[float, ...] | None = None


def read_error_terms(name_or_path: str | Path) -> StoredTerms | None:
    """The ``[error_terms]`` of a TOML robot file, or None (another format, a built-in robot, or no
    such table). Values must be finite numbers, one per named term."""
    path = Path(str(name_or_path))
    if path.suffix != ".toml" or not path.is_file():
        return None
    with path.open("rb") as f:
        try:
            raw = tomllib.load(f).get("error_terms")
        except tomllib.TOMLDecodeError:
            return None  # the robot file's own reader has refused it with the line by now
    if raw is None:
        return None
    src = f"{path}: [error_terms]"
    if not isinstance(raw, dict):
        raise ConfigError(f"{src} must be a table")
    fams = raw.get("families", [])
    vals = raw.get("values", {})
    if not (isinstance(fams, list) and all(isinstance(x, str) for x in fams)) or not isinstance(vals, dict):
        raise ConfigError(f"{src}: families must be a list of names and values a table of name = number")
    sig, units = raw.get("sigma", {}), raw.get("units", {})
    for name, v in vals.items():
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise ConfigError(f"{src}.values: {name} must be a finite number, got {v!r}")
    if vals and not fams:
        raise ConfigError(f"{src}: values are given but no families")
    names = tuple(vals)
    effect = raw.get("effect_on_fit_um")
    if effect is not None and (isinstance(effect, bool) or not isinstance(effect, (int, float))
                               or not math.isfinite(effect)):
        raise ConfigError(f"{src}.effect_on_fit_um must be a finite number [µm], got {effect!r}")
    geo = raw.get("geometric_params")
    if geo is not None and not (isinstance(geo, list) and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in geo)):
        raise ConfigError(f"{src}.geometric_params must be a list of finite numbers [mm, rad]")
    return StoredTerms(tuple(fams), names, tuple(float(vals[n]) for n in names),
                       tuple(float(sig.get(n, math.nan)) if isinstance(sig, dict) else math.nan for n in names),
                       tuple(str(units.get(n, "")) if isinstance(units, dict) else "" for n in names),
                       None if effect is None else float(effect),
                       None if geo is None else tuple(float(v) for v in geo))


def error_terms_toml(families, names, values, sigma, units, effect_on_fit_um: float | None = None,
                     geometric_params=None) -> str:
    """The ``[error_terms]`` table for a robot file (appended after its transforms)."""
    import tomli_w

    table: dict = {"families": list(families),
             "values": {n: float(v) for n, v in zip(names, values)},
             "sigma": {n: float(s) for n, s in zip(names, sigma)},
             "units": {n: str(u) for n, u in zip(names, units)}}
    if effect_on_fit_um is not None:
        table["effect_on_fit_um"] = float(effect_on_fit_um)
    if geometric_params is not None:
        table["geometric_params"] = [float(v) for v in geometric_params]
    return ("\n# error terms beyond geometry (docs/error-terms.md): the joints stand at q + Δq(q) before the "
            "transforms\n" + tomli_w.dumps({"error_terms": table}))


def _vec3(v, what: str) -> tuple[float, float, float]:
    if not (isinstance(v, list) and len(v) == 3 and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                          and math.isfinite(x) for x in v)):
        raise ConfigError(f"{what} must be three finite numbers [x, y, z], got {v!r}")
    return float(v[0]), float(v[1]), float(v[2])


def read_gravity(name_or_path: str | Path, n_joints: int) -> GravityModel | None:
    """The ``[gravity]`` table of a TOML robot file as a :class:`GravityModel` (None: no table)."""
    path = Path(str(name_or_path))
    if path.suffix != ".toml" or not path.is_file():
        return None
    with path.open("rb") as f:
        try:
            raw = tomllib.load(f).get("gravity")
        except tomllib.TOMLDecodeError:
            return None
    if raw is None:
        return None
    src = f"{path}: [gravity]"
    if not isinstance(raw, dict):
        raise ConfigError(f"{src} must be a table")
    masses = raw.get("masses_kg")
    com = raw.get("com_mm")
    if masses is not None:
        if not (isinstance(masses, list) and len(masses) == n_joints
                and all(isinstance(m, (int, float)) and not isinstance(m, bool) and math.isfinite(m) and m >= 0
                        for m in masses)):
            raise ConfigError(f"{src}.masses_kg must give one mass ≥ 0 [kg] per joint ({n_joints}), got {masses!r}")
        if com is not None and not (isinstance(com, list) and len(com) == n_joints):
            raise ConfigError(f"{src}.com_mm must give one centre [x, y, z] per joint ({n_joints})")
    elif com is not None:
        raise ConfigError(f"{src}: com_mm without masses_kg")
    payload = raw.get("payload_kg", 0.0)
    if isinstance(payload, bool) or not isinstance(payload, (int, float)) or not (math.isfinite(payload) and payload >= 0):
        raise ConfigError(f"{src}.payload_kg must be a number ≥ 0, got {payload!r}")
    d = _vec3(raw.get("direction", [0.0, 0.0, -1.0]), f"{src}.direction")
    norm = math.sqrt(sum(x * x for x in d))
    if norm == 0:
        raise ConfigError(f"{src}.direction must not be zero")
    return GravityModel(
        gravity=(d[0] / norm * STANDARD_GRAVITY, d[1] / norm * STANDARD_GRAVITY, d[2] / norm * STANDARD_GRAVITY),
        masses=None if masses is None else tuple(float(m) for m in masses),
        com=None if com is None else tuple(_vec3(c, f"{src}.com_mm") for c in com),
        payload_kg=float(payload), payload_com=_vec3(raw.get("payload_com_mm", [0.0, 0.0, 0.0]),
                                                     f"{src}.payload_com_mm"))


def gravity_toml(gm: GravityModel | None) -> str:
    """The ``[gravity]`` table of ``gm`` for a robot file ('' for None)."""
    if gm is None:
        return ""
    import tomli_w

    g = math.sqrt(sum(x * x for x in gm.gravity)) or 1.0
    table: dict = {"direction": [x / g for x in gm.gravity], "payload_kg": float(gm.payload_kg),
                   "payload_com_mm": [float(x) for x in gm.payload_com]}
    if gm.masses is not None:
        table["masses_kg"] = [float(m) for m in gm.masses]
        if gm.com is not None:
            table["com_mm"] = [[float(x) for x in c] for c in gm.com]
    return "\n" + tomli_w.dumps({"gravity": table})


def read_gear_ratios(name_or_path: str | Path, n_joints: int) -> tuple[float, ...] | None:
    """The ``[gears] ratios`` of a TOML robot file, one per joint, or None."""
    path = Path(str(name_or_path))
    if path.suffix != ".toml" or not path.is_file():
        return None
    with path.open("rb") as f:
        try:
            raw = tomllib.load(f).get("gears")
        except tomllib.TOMLDecodeError:
            return None
    if raw is None:
        return None
    ratios = raw.get("ratios") if isinstance(raw, dict) else None
    if not (isinstance(ratios, list) and len(ratios) == n_joints and all(
            isinstance(r, (int, float)) and not isinstance(r, bool) and math.isfinite(r) and r != 0 for r in ratios)):
        raise ConfigError(f"{path}: [gears].ratios must give one finite, non-zero gear ratio per joint ({n_joints}), "
                          f"got {ratios!r}")
    return tuple(float(r) for r in ratios)


def gears_toml(ratios) -> str:
    """The ``[gears]`` table ('' for None)."""
    if ratios is None:
        return ""
    import tomli_w

    return "\n" + tomli_w.dumps({"gears": {"ratios": [float(r) for r in ratios]}})
