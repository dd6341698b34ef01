"""The fleet table and a robot's history as CSV and JSON, for the quality department's own tools.

Both say their units: JSON in a ``units`` object beside the rows, CSV in its header (``rms_after_um
[µm]``). Times are ISO 8601 in UTC. A text cell that a spreadsheet would run as a formula (it
starts with = + - @, a tab or a carriage return: a serial is whatever the station's file said) is
written with a leading apostrophe (OWASP, "CSV Injection"); numbers are written as numbers.
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Iterable, Mapping, Sequence
from datetime import date, datetime, timezone
from decimal import Decimal
from typing import Any

#: the units of the exported columns (by name; the rest are names, dates or counts without one)
_UNIT_SUFFIXES = (("_um_per_30d", "µm per 30 days"), ("_um", "µm"), ("_utc", "ISO 8601, UTC"), ("_days", "days"))
_UNITS_BY_NAME = {"gain": "ratio (RMS before / RMS after)"}
_FORMULA_START = ("=", "+", "-", "@", "\t", "\r")


def unit_of(column: str) -> str | None:
    if column in _UNITS_BY_NAME:
        return _UNITS_BY_NAME[column]
    return next((unit for suffix, unit in _UNIT_SUFFIXES if column.endswith(suffix)), None)


def _plain(v: Any) -> Any:
    """A value as JSON holds it: times in ISO 8601 UTC, non-finite numbers as null."""
    if isinstance(v, datetime):
        return (v if v.tzinfo else v.replace(tzinfo=timezone.utc)).astimezone(timezone.utc).isoformat()
    if isinstance(v, date):
        return v.isoformat()
    if isinstance(v, Decimal):
        v = float(v)
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def rows_json(rows: Sequence[Mapping[str, Any]], columns: Sequence[str], what: str, **about: Any) -> str:
    units = {c: u for c in columns if (u := unit_of(c)) is not None}
    body = {"what": what, **about, "units": units, "rows": [{c: _plain(r.get(c)) for c in columns} for r in rows]}
    return json.dumps(body, ensure_ascii=False, indent=1)


def _cell(v: Any) -> Any:
    v = _plain(v)
    if v is None:
        return ""
    if isinstance(v, str) and v.startswith(_FORMULA_START):
        return "'" + v
    return v


def rows_csv(rows: Iterable[Mapping[str, Any]], columns: Sequence[str]) -> str:
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\r\n")  # RFC 4180
    writer.writerow([f"{c} [{u}]" if (u := unit_of(c)) else c for c in columns])
    for r in rows:
        writer.writerow([_cell(r.get(c)) for c in columns])
    return out.getvalue()
