"""A run's identified parameters as the dashboard shows them: one source, each value with its unit.

The publication carries, per identified parameter, its name, nominal, value and σ in the model's
units and that unit (``mm`` or ``rad``; station/cell/publication/payload.py). A run published
before that (schema < 4) carried the names of the chosen parameters beside the *whole* model's
vector: pairing them by position put ``R.roll`` beside −100 (issue 39). For such a run the
summary's own estimates (name, value, σ) are read instead, and the unit follows from the name's
suffix (the model's six per transform: x, y, z in mm; roll, pitch, yaw in rad).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from station.core.kinematics.model import PARAM_SUFFIXES
from station.core.units import ARCSEC, DEG, UM

__all__ = ["ParameterRow", "parameter_rows"]

@dataclass(frozen=True)
class ParameterRow:
    """Display strings: lengths identified in mm, Δ and σ in µm; angles in °, Δ and σ in ″."""

    name: str
    value: str
    unit: str
    delta: str  # identified − nominal; "—" where the nominal was not published
    sigma: str
    small_unit: str


def _num(v: Any) -> float | None:
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) else None


def _unit_of(name: str) -> str | None:
    suffix = name.rpartition(".")[2]
    if suffix not in PARAM_SUFFIXES:
        return None
    return "rad" if PARAM_SUFFIXES.index(suffix) >= 3 else "mm"


def _row(name: Any, unit: Any, value: Any, sigma: Any, nominal: Any) -> ParameterRow | None:
    v, s, n = _num(value), _num(sigma), _num(nominal)
    if not isinstance(name, str) or unit not in ("mm", "rad") or v is None:
        return None
    big, small, shown, small_unit, digits = ((1 / DEG, 1 / ARCSEC, "°", "″", 5) if unit == "rad"
                                             else (1.0, 1 / UM, "mm", "µm", 4))
    return ParameterRow(name=name, value=f"{v * big:.{digits}f}", unit=shown,
                        delta="—" if n is None else f"{(v - n) * small:.1f}",
                        sigma="—" if s is None else f"{s * small:.1f}", small_unit=small_unit)


def parameter_rows(detail: Any) -> tuple[list[ParameterRow], str | None]:
    """The rows of a stored run's detail, and a note where some could not be shown (None: all)."""
    if not isinstance(detail, Mapping):
        return [], None
    ident = detail.get("identification")
    published = ident.get("parameters") if isinstance(ident, Mapping) else None
    if isinstance(published, list):
        entries = [(p.get("name"), p.get("unit"), p.get("value"), p.get("sigma"), p.get("nominal"))
                   for p in published if isinstance(p, Mapping)]
    else:
        summary = detail.get("summary")
        sid = summary.get("identification") if isinstance(summary, Mapping) else None
        listed = sid.get("parameters") if isinstance(sid, Mapping) else None
        entries = [(p.get("name"), _unit_of(str(p.get("name"))), p.get("value"), p.get("sigma"), None)
                   for p in (listed if isinstance(listed, list) else []) if isinstance(p, Mapping)]
    rows = [r for r in (_row(*e) for e in entries) if r is not None]
    missing = len(entries) - len(rows)
    return rows, (f"{missing} parameter(s) without a readable name, unit or value are not shown" if missing else None)
