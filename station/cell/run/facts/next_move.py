"""The next move's clearance (issue 40): what the plan's collision check found for each planned
step's moves, carried to the views as an event, so that the TUI shows it without computing a
distance (:func:`station.cell.plan.collision.check_path` computes it once, before the first motion).

A step's moves are the travel to it from the step before (its vias), its approach, the pose above
the point, the touch and the retract, as the plan checked them; the clearance is the least distance
[mm] of any pair held to ``[plan] collision_margin_mm`` along them, and the pair that sets it. Pairs
farther than twice the margin are not measured exactly (the check's screen proves them clear): then
the clearance is "over" that. A step the check did not see (a simulated run's reference steps, a
resumed run whose stored plan differs from today's) gets no event: the view says nothing rather
than something untrue.

Once a correction's path is checked as the controller will move it (a table's shifted touches, an
arm's compensated targets: :mod:`station.cell.pipeline.shifted`), its steps' events are that check's
(``check`` names it) and the line says so: "next move, with the correction: clearance …"; an arm's
plain targets before correction, checked at the joints they are commanded at, "next move, before
correction: …".
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from station.cell.plan.collision import CollisionReport
from station.cell.plan.steps import PlannedStep
from station.cell.run.facts.events import Event

__all__ = ["NextMove", "next_moves"]


@dataclass(frozen=True)
class NextMove(Event):
    """The clearance of plan step ``index``'s moves: ``clearance_mm`` [mm] between ``a`` and ``b``
    (None: no pair within ``watch_mm`` [mm], the check proved them all farther), the margin [mm];
    ``check``: the check that found it, "" the pre-motion check of the plan (else e.g. "after (shifted)")."""

    index: int
    clearance_mm: float | None
    a: str
    b: str
    watch_mm: float
    margin_mm: float
    check: str = ""

    def text(self) -> str:
        """What an operator reads, e.g. "next move: clearance 12.3 mm (link A3 ↔ obstacle 'column')"."""
        # an arm's plain targets before correction (check "before (plain)") carry no correction
        head = "next move" + ("" if not self.check else ", before correction" if self.check.startswith("before")
                              else ", with the correction")
        if self.clearance_mm is None:
            return f"{head}: clearance over {self.watch_mm:g} mm"
        return f"{head}: clearance {self.clearance_mm:.1f} mm ({self.a} ↔ {self.b})"


def next_moves(report: CollisionReport | None, checked: Sequence[PlannedStep],
               steps: Sequence[PlannedStep], check: str = "") -> dict[int, NextMove]:
    """Per step of ``steps`` (the run's) the event of its moves, for the steps the plan's check
    ``report`` saw: the same index, kind and joints in ``checked`` (the steps it checked); ``check``:
    which check it is ("": the plan's)."""
    if report is None:
        return {}
    seen = {st.index: st for st in checked}
    found = dict(report.by_step)
    out = {}
    for st in steps:
        same = seen.get(st.index)
        if same is None or st.index not in found or (same.kind, same.joints) != (st.kind, st.joints):
            continue
        c = found[st.index]
        out[st.index] = NextMove(st.index, None if c is None else c.clearance_mm, "" if c is None else c.a,
                                 "" if c is None else c.b, 2 * report.margin_mm, report.margin_mm, check)
    return out
