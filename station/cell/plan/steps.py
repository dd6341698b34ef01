"""Planned steps of a run: the one definition of step kinds, shared by the plan, the runner,
the run database and the reports.

A step stays typed from the plan to the run database; only there is it stored as a JSON record
(:meth:`PlannedStep.to_record` / :meth:`PlannedStep.from_record`).
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np


class StepKind(str, enum.Enum):
    """What a measurement is for (the value is what the run database stores)."""

    IDENTIFICATION = "identification"
    REVERSAL = "reversal"  # the same pose approached from the other side (reversal error)
    VERIFY_BEFORE = "verification_before"  # held-out pose, no correction active
    VERIFY_AFTER = "verification_after"  # held-out pose, the station's correction active
    # held-out pose, a simulated cell's reference correction active (simulation only: its judge,
    # station/cell/records/judge.py); stored as "oracle", as runs before issue 42 stored it
    REFERENCE = "oracle"
    RECHECK = "recheck"  # a recheck pose, compared with a baseline calibration's model (station recheck)

    @property
    def caption(self) -> str:
        """What an operator reads."""
        return _TITLES[self]

    @property
    def is_verification(self) -> bool:
        return self in (StepKind.VERIFY_BEFORE, StepKind.VERIFY_AFTER, StepKind.REFERENCE)


_TITLES = {
    StepKind.IDENTIFICATION: "identification",
    StepKind.REVERSAL: "reversal (other side)",
    StepKind.VERIFY_BEFORE: "verification before correction",
    StepKind.VERIFY_AFTER: "verification after correction",
    StepKind.REFERENCE: "verification with the reference correction (simulation)",
    StepKind.RECHECK: "recheck against the baseline",
}

#: the measurement kinds the run database accepts
MEASUREMENT_KINDS: tuple[str, ...] = tuple(k.value for k in StepKind)

#: the keys of a stored step record
_RECORD_KEYS = ("index", "kind", "point", "point_id", "elbow", "direction", "cycle", "joints")


@dataclass(frozen=True)
class PlannedStep:
    """One measurement of a run.

    ``point``: index into the configuration's body points, ``point_id`` its name; ``elbow``
    ±1; ``direction`` +1 for the normal approach, −1 from the other side; ``cycle``: the
    repetition (identification repeats, ISO 9283 verification cycles), from 0; ``joints``
    ``(n_joints,)`` [rad, mm]: the nominal-model joints of the target.
    """

    index: int
    kind: StepKind
    point: int
    point_id: str
    elbow: int
    direction: int
    cycle: int
    joints: tuple[float, ...]

    @property
    def q(self) -> np.ndarray:
        return np.array(self.joints, dtype=float)

    @property
    def label(self) -> str:
        """``C2.a elbow +1 cycle 2``: what the operator reads for this step."""
        text = f"{self.point_id} elbow {self.elbow:+d}"
        if self.direction < 0:
            text += " reverse"
        if self.cycle:
            text += f" cycle {self.cycle + 1}"
        return text

    def to_record(self) -> dict[str, Any]:
        """The JSON record the run database stores."""
        return {"index": self.index, "kind": self.kind.value, "point": self.point,
                "point_id": self.point_id, "elbow": self.elbow, "direction": self.direction,
                "cycle": self.cycle, "joints": list(self.joints)}

    @classmethod
    def from_record(cls, rec: Mapping[str, Any]) -> PlannedStep:
        missing = [k for k in _RECORD_KEYS if k not in rec and k not in ("direction", "cycle")]
        if missing:
            raise ValueError(f"stored step {dict(rec)!r} lacks {missing}")
        return cls(index=int(rec["index"]), kind=StepKind(rec["kind"]), point=int(rec["point"]),
                   point_id=str(rec["point_id"]), elbow=int(rec["elbow"]),
                   direction=int(rec.get("direction", 1)), cycle=int(rec.get("cycle", 0)),
                   joints=tuple(float(v) for v in rec["joints"]))
