"""A CMM certificate's identity, as the head file and the body file give it for the report's
traceability: the certificate's ID and the date of the measurement it reports.

Both are optional in their files (docs/probe-head.md, docs/data-files.md); given, they are
checked here: an ID of 1 … 128 printable characters, a date as ``YYYY-MM-DD`` (a real date).
"""

from __future__ import annotations

import datetime as dt
import re
from dataclasses import dataclass

__all__ = ["Certificate", "check_certificate_id", "check_certificate_date"]

MAX_ID_CHARS = 128
_CONTROL = re.compile(r"[\x00-\x1f\x7f]")
_DATE = re.compile(r"^\d{4}-\d{2}-\d{2}$")


@dataclass(frozen=True)
class Certificate:
    """``id``: the certificate's number; ``date``: ``YYYY-MM-DD`` of its measurement, or "" where
    the file gives an ID without a date (and the other way round)."""

    id: str = ""
    date: str = ""

    def __bool__(self) -> bool:
        return bool(self.id or self.date)


def check_certificate_id(value: object) -> str:
    """The ID as given; :class:`ValueError` (with what to write) for anything else."""
    if not isinstance(value, str):
        raise ValueError(f"expected the certificate's ID as a string in quotes, got {type(value).__name__}")
    text = value.strip()
    if not text or len(text) > MAX_ID_CHARS or _CONTROL.search(text):
        raise ValueError(f"the certificate ID must be 1 … {MAX_ID_CHARS} printable characters, got {value!r}")
    return text


def check_certificate_date(value: object) -> str:
    """``YYYY-MM-DD`` from a string of that form or a TOML date; :class:`ValueError` otherwise."""
    if isinstance(value, dt.datetime):
        value = value.date()
    if isinstance(value, dt.date):
        return value.isoformat()
    if isinstance(value, str) and _DATE.match(value.strip()):
        try:
            return dt.date.fromisoformat(value.strip()).isoformat()
        except ValueError:  # the form but no such day (2026-02-30): the same message as any other
            pass
    raise ValueError(f"the certificate date must be a date written YYYY-MM-DD, e.g. 2026-11-02, got {value!r}")
