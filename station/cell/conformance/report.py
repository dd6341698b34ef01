"""What the conformance kit reports: the requirements it checks, each one's result, and the report.

:data:`REQUIREMENTS` is the list ``docs/robot-program.md`` asks of a robot program, in report
order; the kit (:mod:`station.cell.conformance.suite`) fills one :class:`Requirement` per entry and
returns them in a :class:`ConformanceReport`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from station.errors import Outcome

__all__ = ["REQUIREMENTS", "Requirement", "ConformanceReport", "PASSED", "FAILED", "NOT_CHECKED", "NOT_APPLICABLE",
           "PARTLY_CHECKED"]


PASSED, FAILED, NOT_CHECKED = "passed", "failed", "not checked"
#: a requirement this cell does not ask of its program (the table requirements on a cell whose
#: station uploads no table): it neither passes nor fails, and does not stop the kit's exit 0
NOT_APPLICABLE = "not applicable"
#: every part that was checked passed, but a part could not be checked (named in ``unchecked``):
#: not a pass - the kit cannot say the program meets the requirement - so the exit code is 7
PARTLY_CHECKED = "partly checked"

#: The requirements, in report order: (id, what the robot program must do).
REQUIREMENTS: tuple[tuple[str, str], ...] = (
    ("identification", "map_version, n_joints, watchdog_ms, order_check and the soft limits (info page 0) are "
                       "published"),
    ("word_order", "32-bit values use the link's word order"),
    ("heartbeat", "heartbeat both ways: hb_robot advances every period, hb_pc is taken from the PC"),
    ("claim", "one station per controller: a second claim is refused, a command with another token is refused "
              "with NOT_CLAIMED, the holder's release frees the controller, the watchdog frees a silent holder's "
              "claim"),
    ("ack", "every command is acknowledged with its sequence number in ack_seq"),
    ("done", "done_seq is set to the command's number only after the motion has arrived"),
    ("sequence", "a wrong sequence number is refused with SEQUENCE_ERROR, the next right one accepted; neither "
                 "moves the robot"),
    ("soft_limit", "an out-of-limits target is refused with SOFT_LIMIT, error_joint and error_bound; "
                   "the robot does not move"),
    ("error_codes", "the documented error codes: BAD_COMMAND for an unknown command and a bad speed, "
                    "TABLE_NOT_STAGED; rejections do not latch"),
    ("table", "correction table through the transfer block: header and value pages written and read back, "
              "whole-table CRC-32, TABLE_STAGE"),
    ("pages", "a page whose data do not match its page CRC is refused with PAGE_CRC_MISMATCH; an unknown "
              "operation, page number or length with PAGE_INVALID"),
    ("slot_reads", "the slot reads (READ_STAGED/ACTIVE/PREVIOUS_HEADER and _PAGE) answer with the table in "
                   "that slot"),
    ("activation", "TABLE_ACTIVATE, TABLE_DEACTIVATE and TABLE_ROLLBACK move the tables between the slots as "
                   "documented; NO_PREVIOUS_TABLE without a previous table"),
    ("discard_previous", "TABLE_DISCARD_PREVIOUS empties the previous slot"),
    ("keep_previous", "activating while no table is active keeps the previous table"),
    ("slots_restored", "the kit leaves the staged, active and previous slots as it found them (CRC-32 of each "
                       "compared)"),
)


@dataclass
class Requirement:
    """One requirement's result: ``status`` passed / failed / not checked / partly checked, what
    was seen (``detail``), the parts that could not be checked (``unchecked``) and, when it failed
    or could not be checked, what to do (``fix``)."""

    id: str
    title: str
    status: str = NOT_CHECKED
    detail: list[str] = field(default_factory=list)
    fix: list[str] = field(default_factory=list)
    unchecked: list[str] = field(default_factory=list)

    def failed(self, detail: str, fix: str) -> None:
        self.status = FAILED
        self.detail.append(detail)
        if fix not in self.fix:
            self.fix.append(fix)

    def passed(self, detail: str = "") -> None:
        if self.status != FAILED:
            self.status = PARTLY_CHECKED if self.unchecked else PASSED
        if detail:
            self.detail.append(detail)

    def not_checked(self, why: str, fix: str = "") -> None:
        if self.status != FAILED:
            self.status = NOT_CHECKED
        self.detail.append(f"not checked: {why}")
        if fix and fix not in self.fix:
            self.fix.append(fix)

    def partly(self, part: str, why: str, fix: str = "") -> None:
        """One part of the requirement (``part``: what would have been checked) was not checked:
        whatever else passes, the requirement is only partly checked."""
        self.unchecked.append(part)
        self.detail.append(f"not checked: {part}: {why}")
        if self.status == PASSED:
            self.status = PARTLY_CHECKED
        if fix and fix not in self.fix:
            self.fix.append(fix)

    def not_applicable(self, why: str) -> None:
        if self.status != FAILED:
            self.status = NOT_APPLICABLE
        self.detail.append(f"not applicable: {why}")

    def to_json(self) -> dict[str, Any]:
        return {"id": self.id, "requirement": self.title, "status": self.status, "detail": list(self.detail),
                "not_checked": list(self.unchecked), "fix": list(self.fix)}


@dataclass(frozen=True)
class ConformanceReport:
    controller: str
    configured_word_order: str
    detected_word_order: str | None
    requirements: tuple[Requirement, ...]
    notes: tuple[str, ...] = ()

    @property
    def passed(self) -> bool:
        """Every requirement passed, or does not apply to this cell."""
        return all(r.status in (PASSED, NOT_APPLICABLE) for r in self.requirements)

    @property
    def outcome(self) -> Outcome:
        """SUCCESS when every requirement that applies passed; DEVICE_FAULT otherwise (the
        controller's program does not conform, or a requirement could not be checked)."""
        return Outcome.SUCCESS if self.passed else Outcome.DEVICE_FAULT

    def requirement(self, rid: str) -> Requirement:
        return next(r for r in self.requirements if r.id == rid)

    def to_json(self) -> dict[str, Any]:
        return {"outcome": self.outcome.name, "exit_code": int(self.outcome), "controller": self.controller,
                "word_order": {"configured": self.configured_word_order, "detected": self.detected_word_order},
                "passed": self.passed,
                "requirements": [r.to_json() for r in self.requirements], "notes": list(self.notes)}

    def describe(self) -> list[str]:
        lines = [f"conformance of the robot program at {self.controller}:"]
        for r in self.requirements:
            mark = {PASSED: "passed", FAILED: "FAILED", NOT_CHECKED: "NOT CHECKED",
                    NOT_APPLICABLE: "not applicable",
                    PARTLY_CHECKED: "PARTLY CHECKED"}[r.status]
            lines.append(f"  [{mark}] {r.id}: {r.title}")
            lines += [f"      {d}" for d in r.detail]
            if r.status not in (PASSED, NOT_APPLICABLE):
                lines += [f"      what to fix: {f}" for f in r.fix]
        lines += [f"  note: {n}" for n in self.notes]
        n_ok = sum(r.status == PASSED for r in self.requirements)
        n_na = sum(r.status == NOT_APPLICABLE for r in self.requirements)
        n_part = sum(r.status == PARTLY_CHECKED for r in self.requirements)
        lines.append(f"{n_ok} of {len(self.requirements) - n_na} requirements passed"
                     + (f", {n_part} partly checked" if n_part else "")
                     + (f" ({n_na} not applicable to this cell)" if n_na else "")
                     + ("" if self.passed else "; see docs/robot-program.md"))
        return lines
