"""What a run's "before" figure is measured on, said wherever it is shown (issue 29: "before" read
3243.6 µm in one run and 821.2 µm in another of one simulated cell, with only ``[plan] repeats``
and ``verification_cycles`` changed, and the report did not say why).

"Before" is the position error at the held-out poses with no correction table active (a table
the controller had is set aside first), the targets commanded through the robot's nominal model
and the set-up R.* that this run identified. So it changes with:

* the held-out poses: every ``[plan] verification_every``-th (point, elbow) that passes the soft-limit
  check, and that check covers the last repetition's approach, which ``repeats`` and
  ``verification_cycles`` widen (the built-in cell holds out 11 poses at 4 repeats / 5 cycles and
  8 at 20 / 30);
* the cycles per pose (``verification_cycles``): RMS and max run over every cycle;
* the set-up R.* of this run's identification (its poses and repeats).

Imports: :mod:`station.cell.records.summary` only (the CLI's text summary uses it too).
"""

from __future__ import annotations

from station.cell.records.summary import ErrorStats


def _poses(before: ErrorStats) -> str:
    if not before.n_poses:  # a summary stored before poses and cycles were counted
        return f"{before.n} readings at the held-out poses"
    per_pose = "" if before.n == before.n_poses * before.cycles else "up to "
    return (f"{before.n_poses} held-out pose{'s' if before.n_poses != 1 else ''} × {per_pose}{before.cycles} "
            f"cycle{'s' if before.cycles != 1 else ''} ({before.n} readings)")


def before_basis(before: ErrorStats | None) -> str | None:
    """One sentence for the report: what "before" was measured on and what changes it; None
    when the run measured no "before"."""
    if before is None or not before.n:
        return None
    return (f"'Before' is measured on {_poses(before)}, with no correction table active, the targets commanded "
            f"through the robot's nominal model and the set-up R.* identified in this run. It changes with "
            f"each: the held-out poses are every [plan] verification_every-th (point, elbow) that passes the "
            f"soft-limit check of its widest approach, which [plan] repeats and verification_cycles widen; the "
            f"cycles are [plan] verification_cycles; R.* comes from this run's identification. Compare 'before' "
            f"between runs only on the same poses and cycles.")


def before_basis_line(before: ErrorStats | None) -> str | None:
    """The same, short, for the text summary."""
    if before is None or not before.n:
        return None
    return (f"before: {_poses(before)}, no correction table active, targets through the nominal model and this "
            f"run's set-up R; other poses or cycles measure another 'before'")
