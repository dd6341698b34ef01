"""The acceptance limits a verified run missed (``TARGET_MISSED``), as facts a script can read.

A TARGET_MISSED run's notes say in words which limit it missed; its JSON (``station calibrate
--json`` and the stored run summary) carries the same facts structured, as its ``failure`` object
(:func:`failure_json`): each limit missed with the measured value and the limit in their unit, the
setting that governs the limit, and what to do. The limits are those of the outcome
(:func:`station.cell.pipeline.results.verified_outcome`): the improvement ratio RMS before / RMS
after against the station's required gain, and ISO 9283 AP and RP of the worst held-out pose after
correction against ``[verification] max_ap_um`` / ``max_rp_um``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

__all__ = ["MissedLimit", "failure_json", "missed_from_json", "FAILURE_KIND"]

#: the ``failure`` object's ``kind`` for a run that finished but missed its target (a run that
#: stopped early has a ``failure`` with ``error_type`` instead)
FAILURE_KIND = "target_missed"


@dataclass(frozen=True)
class MissedLimit:
    """One acceptance limit missed: ``id`` names the limit (``min_gain``, ``max_ap_um``,
    ``max_rp_um``), ``quantity`` what was measured, ``measured`` and ``limit`` in ``unit``
    (µm, or × for a ratio), ``setting`` the setting that governs the limit, ``hint`` what to do."""

    id: str
    quantity: str
    measured: float
    limit: float
    unit: str
    setting: str
    hint: str
    #: True where the measured value must reach the limit (a gain), False where it must stay within it
    at_least: bool = False

    @property
    def note(self) -> str:
        """The limit in words, as the run's notes state it."""
        return (f"{self.quantity} reaches {self.measured:.1f} {self.unit}, "
                f"{'below' if self.at_least else 'above'} {self.setting} = {self.limit:g} {self.unit}")


def failure_json(missed: Sequence[MissedLimit]) -> dict[str, Any]:
    """The ``failure`` object of a TARGET_MISSED run's JSON: the limits missed, each with its
    measured value, limit, unit, setting and hint; ``message`` and ``hint`` the same in words."""
    hints = list(dict.fromkeys(m.hint for m in missed))
    return {"kind": FAILURE_KIND, "message": "; ".join(m.note for m in missed),
            "limits": [asdict(m) for m in missed], "hint": "; ".join(hints)}


def missed_from_json(failure: Mapping[str, Any] | None) -> tuple[MissedLimit, ...]:
    """The limits of a stored :func:`failure_json` object; () for any other ``failure``."""
    if not failure or failure.get("kind") != FAILURE_KIND:
        return ()
    return tuple(MissedLimit(**m) for m in failure.get("limits", ()))
