"""A correction refusal's advice, every piece checked before it is printed (issue 37).

A refusal before motion is right; advice that cannot be followed is a dead end. Each suggestion
here is a change to the cell file written as the user writes it (``[correction]
max_interpolation_um = 19``), applied to the file's own text, parsed again and run through the
same plan and correction checks ``station plan`` runs
(:func:`station.cell.correction.design.check_design`). Only the
changes that pass are printed, each with the design it gives; where none passes alone, the
combination of them is tried and printed if it passes.

Why a smaller ``[correction] region`` is never offered alone: the derived region is already the
box around the verification targets with their margins, so a smaller one leaves a target outside
the table; fewer targets (one elbow, fewer held-out points) shrink it the way the plan allows.

The advice runs the design's check (:mod:`station.cell.correction.design`) on every changed file,
so it stands above the design; the pre-motion check that prints it
(:func:`station.cell.correction.precheck.check_correction`) stands above both.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass

from station.cell.config.cell_config import CellConfig, parse_text
from station.cell.correction.design import check_design, design_for
from station.cell.plan.measurement_plan import build_plan
from station.core.table.design import TableDesign
from station.errors import StationError

__all__ = ["Change", "Checked", "apply_changes", "check_changes", "bound_advice", "coverage_advice", "advice_text"]

#: tries of a looser bound, each the worst sampled robot's bound of the previous try (or this
#: factor above it): a design and eight built tables each
BOUND_TRIES = 3
BOUND_STEP = 1.3
#: the configuration's upper limit of correction.max_interpolation_um (station/cell/config/schema.py)
MAX_BOUND_UM = 1000.0


@dataclass(frozen=True)
class Change:
    """One setting of the cell file: ``value`` as written in TOML, None to remove the key."""

    section: str
    key: str
    value: str | None

    def words(self) -> str:
        return f"[{self.section}] {self.key} = {self.value}" if self.value is not None else \
            f"remove [{self.section}] {self.key}"


@dataclass(frozen=True)
class Checked:
    """Changes that passed the pre-motion checks together, and the correction design they give."""

    changes: tuple[Change, ...]
    design: TableDesign

    def line(self) -> str:
        d = self.design
        what = " and ".join(_words(self.changes))
        return (f"{what} (checked: {'×'.join(map(str, d.counts))} nodes × {len(d.region.elbows)} elbow"
                f"{'s' if len(d.region.elbows) > 1 else ''}, {d.n_values} of {d.capacity} values, predicted bound "
                f"{d.predicted_bound_um:.1f} µm, sampled robots up to {d.worst_bound_um:.1f} µm against "
                f"{d.limit_um:g} µm)")


def _words(changes: Sequence[Change]) -> list[str]:
    """Each change in words, a section's removals in one ("remove [correction] x_mm, y_mm")."""
    out: list[str] = []
    gone: dict[str, list[str]] = {}
    for c in changes:
        if c.value is None:
            if c.section not in gone:
                out.append(c.section)  # placeholder, filled below
                gone[c.section] = []
            gone[c.section].append(c.key)
        else:
            out.append(c.words())
    return [f"remove [{w}] {', '.join(gone[w])}" if w in gone else w for w in out]


_HEADER = re.compile(r"^\s*\[([A-Za-z0-9_.]+)\]\s*(#.*)?$")


def apply_changes(text: str, changes: Sequence[Change]) -> str:
    """``text`` (a cell file) with each change made: the key's line in its section replaced
    (or removed), else added right under the section's header (the section added at the end
    when missing)."""
    lines = text.splitlines()
    for c in changes:
        start = next((i for i, ln in enumerate(lines) if (m := _HEADER.match(ln)) and m.group(1) == c.section), None)
        new = None if c.value is None else f"{c.key} = {c.value}"
        if start is None:
            if new is not None:
                lines += ["", f"[{c.section}]", new]
            continue
        end = next((i for i in range(start + 1, len(lines)) if _HEADER.match(lines[i])
                    or lines[i].lstrip().startswith("[[")), len(lines))
        at = next((i for i in range(start + 1, end) if re.match(rf"^\s*{re.escape(c.key)}\s*=", lines[i])), None)
        if at is not None:
            stop = _value_end(lines, at)
            lines[at:stop] = [] if new is None else [new]
        elif new is not None:
            lines.insert(start + 1, new)
    return "\n".join(lines) + "\n"


def _value_end(lines: list[str], at: int) -> int:
    """The line after the value that starts on line ``at`` (an array or inline table may go on
    over several lines: until its brackets close, strings and comments not counted)."""
    depth, i = 0, at
    while i < len(lines):
        text = re.sub(r'"(?:[^"\\]|\\.)*"|\'[^\']*\'', "", lines[i]).split("#", 1)[0]
        if i == at:
            text = text.split("=", 1)[-1]
        depth += text.count("[") + text.count("{") - text.count("]") - text.count("}")
        i += 1
        if depth <= 0:
            break
    return i


def check_changes(cfg: CellConfig, changes: Sequence[Change], plan: object = None) -> TableDesign | None:
    """The design the cell file with ``changes`` gets from the pre-motion checks (plan and
    correction), or None where they refuse it. ``plan``: the cell's plan when the changes leave
    it as it is (None: built again from the changed file)."""
    if not cfg.source_text:
        return None  # nothing to apply the change to (a built-in cell): no advice is printed unchecked
    try:
        changed = parse_text(apply_changes(cfg.source_text, changes), cfg.source or "<config>")
        return check_design(changed, plan if plan is not None else build_plan(changed))
    except (StationError, ValueError):
        return None


def _first_passing(cfg: CellConfig, tries: Sequence[tuple[Change, ...]], plan: object = None,
                   base: tuple[Change, ...] = ()) -> Checked | None:
    for changes in tries:
        d = check_changes(cfg, base + tuple(changes), plan)
        if d is not None:
            return Checked(base + tuple(changes), d)
    return None


def bound_advice(cfg: CellConfig, design: TableDesign, plan: object,
                 base: tuple[Change, ...] = ()) -> tuple[Checked | None, Change]:
    """The smallest looser bound tried that passes (whole µm, above the refused one), and the
    last one tried (for a combination). Starts at the worst sampled robot's table on the
    finest grid within the capacity (the median estimate, which the old advice printed, can lie
    below the refused bound)."""
    limit = float(cfg.correction.max_interpolation_um)
    worst = design.worst_bound_um if design.bounds_um else design.best_bound_um * 1.3
    value = math.ceil(max(limit + 1.0, worst if math.isfinite(worst) else limit * BOUND_STEP))
    change = Change("correction", "max_interpolation_um", f"{value:g}")
    for _ in range(BOUND_TRIES):
        if value > MAX_BOUND_UM:
            break
        change = Change("correction", "max_interpolation_um", f"{value:g}")
        got = _first_passing(cfg, [(change,)], plan, base)
        if got is not None:
            return got, change
        value = math.ceil(max(value * BOUND_STEP, value + 1))
    return None, change


def _plan_changes(cfg: CellConfig) -> list[tuple[Change, ...]]:
    """Fewer verification targets, so that the derived region shrinks: one elbow (the table
    then holds one configuration, twice the nodes), or every second held-out target dropped."""
    out: list[tuple[Change, ...]] = []
    if len(cfg.plan.elbows) > 1:
        out += [(Change("plan", "elbows", f"[{e}]"),) for e in cfg.plan.elbows]
    every = cfg.plan.verification_every
    if every * 2 <= 100:
        out.append((Change("plan", "verification_every", str(every * 2)),))
    return out


def advice_text(cfg: CellConfig, design: TableDesign, plan: object, base: tuple[Change, ...] = ()) -> str:
    """The checked suggestions for an infeasible design, as the refusal prints them (``base``:
    changes every suggestion carries, and ``cfg``'s design is the one with them made)."""
    found: list[Checked] = []
    c = cfg.correction
    if c.explicit:  # the station's own design over the same region first: the user's grid may be the problem
        grid_off = tuple(Change("correction", k, None) for k in ("x_mm", "y_mm", "z_mm", "yaw_step_deg"))
        got = _first_passing(cfg, [grid_off], plan, base)
        if got is not None:
            found.append(got)
    bound, last_bound = bound_advice(cfg, design, plan, base)
    if bound is not None:
        found.append(bound)
    tried_plan: list[tuple[Change, ...]] = []
    for changes in _plan_changes(cfg):
        tried_plan.append(changes)
        got = _first_passing(cfg, [changes], None, base)
        if got is not None:
            found.append(got)
            break
    if found:
        return ("Change one of (each checked with the same plan and design before it is printed): "
                + "; ".join(f"{k}) {f.line()}" for k, f in enumerate(found, 1)))
    combo = (last_bound, *(ch for t in tried_plan[:1] for ch in t))
    together = _first_passing(cfg, [combo], None, base) if len(combo) > 1 else None
    if together is not None:
        return "No single change passes the same checks; together they do: " + together.line()
    return ("No change the station can check passes: neither a looser bound (up to "
            f"{last_bound.value} µm) nor fewer verification targets, alone or together. Bring the body's points "
            "nearer the robot's axis 1 (the correction bends most towards the stretched and the folded arm), "
            "or name a [correction] region that holds the verification targets")


def coverage_advice(cfg: CellConfig, plan: object, widened: tuple[tuple[float, float], ...]) -> str:
    """The checked ways out of a verification target outside a named region or grid: the region
    widened to hold every target with its margin, or the region (grid) removed so that the
    station derives it."""
    c = cfg.correction
    tries: list[tuple[Change, ...]] = []
    if not c.explicit:
        box = ", ".join(f"{a}_mm = [{math.floor(lo):g}, {math.ceil(hi):g}]" for a, (lo, hi) in zip("xyz", widened))
        tries.append((Change("correction", "region", "{ " + box + " }"),))
        tries.append((Change("correction", "region", None),))
    else:
        tries.append(tuple(Change("correction", k, None) for k in ("x_mm", "y_mm", "z_mm", "yaw_step_deg", "region")))
    found = [got for t in tries if (got := _first_passing(cfg, [t], plan)) is not None]
    if found:
        return "Change one of (each checked before it is printed): " + "; ".join(
            f"{k}) {f.line()}" for k, f in enumerate(found, 1))
    # neither passes: the station's own region misses the bound too, so its advice, with the removal
    return "The region as the station derives it misses the bound too. " + _derived_advice(cfg, plan, tries[-1])


def _derived_advice(cfg: CellConfig, plan: object, removal: tuple[Change, ...]) -> str:
    try:
        changed = parse_text(apply_changes(cfg.source_text, removal), cfg.source or "<config>")
        design = design_for(changed, plan)
    except (StationError, ValueError) as exc:
        return f"With {' and '.join(_words(removal))}: {exc}"
    return advice_text(changed, design, plan, removal)
