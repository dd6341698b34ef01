"""The order in which ``--model auto`` tries the error terms (issue 38): by physics first, then by
evidence. Pure functions of the model and the data's joints and rows.

A robot engineer who finds a model's error above the noise tries, in this order:

1. **gravity compliance** — every serial arm bends under its own weight; its shape (the gravity
   torques) comes from the robot file's masses, or the lumped shape where the file has none, and
   then the shape fitted to the arm's mass distribution (``mass_shape``,
   :mod:`station.core.terms.mass_shape`) once compliance is in;
2. **backlash and drift** — only where the data carry what tells them apart: the side each joint
   arrived from (backlash), a time of every row (drift: a row number is not a time, and a drift over
   row order is a set-up that moved, which the geometry's set-up already takes);
3. **a joint's harmonics** — only of a joint that the data move over at least
   :data:`HARMONIC_MIN_SPAN` (150°) of the angle its error cycles with (the joint angle times its
   gear ratio), then its second harmonic once its first is in.

Each tier is tried family by family (forward selection, a Bonferroni division by the candidates of
the step) before the next; a tier where nothing passes hands over to the next rather than ending
the selection, so a robot without compliance can still show a gear's eccentricity.

Why 150°. Over a span Δ of the cycle angle, what of a first harmonic the joint zero (a constant)
and a line through the span cannot take — the part the data can tell from geometry — is, at the
worst phase, 0.8 % of its amplitude (RMS) at Δ = 80°, 3.5 % at 130°, 5.2 % at 150° and 8.6 % at
180° (45 % over a full turn). The rule asks for 5 %: below it the fitted amplitude is fixed by a few
per cent of the signal and the harmonic's value outside the span is an extrapolation. On the FANUC
R-2000iC data (J2 swept over 80°) the J2 harmonic chosen in place of compliance gave 1 058 µm at a
held-out end of the sweep where compliance gave 582 µm; the simulated SCARA's plan moves joint 1
over 153° and its 25″ once-per-turn gear error is found there (tests/cell/test_session_terms.py).
"""

from __future__ import annotations

import numpy as np

from station.core.kinematics.model import RobotModel
from station.core.terms.error_model import TermRows, available_families

__all__ = ["HARMONIC_MIN_SPAN", "cycle_span", "candidate_tiers"]

#: the least span of a joint's cycle angle (r_j · q_j) [rad] over the data for its harmonic to be a
#: candidate of ``--model auto`` (150°: 5 % of a first harmonic's amplitude beyond a joint zero and a
#: line at the worst phase; see the module)
HARMONIC_MIN_SPAN = float(np.radians(150.0))


def cycle_span(model: RobotModel, joints: np.ndarray, ratios: tuple[float, ...] | None = None) -> np.ndarray:
    """``(g,)`` [rad] the span (max − min) of every joint's cycle angle ``r_j q_j`` over ``joints``
    ``(n, g)``; 0 for a prismatic joint."""
    q = model.check_joints(joints)
    r = np.ones(q.shape[1]) if ratios is None else np.abs(np.asarray(ratios, dtype=float))
    span = (q.max(axis=0) - q.min(axis=0)) * r if q.shape[0] else np.zeros(q.shape[1])
    return np.where(np.array(model.joint_types) == "revolute", span, 0.0)


def candidate_tiers(model: RobotModel, joints: np.ndarray, rows: TermRows | None = None,
                    ratios: tuple[float, ...] | None = None, lumped: bool = False) -> tuple[tuple[str, ...], ...]:
    """The families ``--model auto`` tries, tier by tier (see the module): compliance; its torque
    shape fitted (``mass_shape``) where ``lumped`` (the robot file gives no masses); backlash
    where the rows carry approach signs and drift where they carry a time; the first harmonic of
    each joint whose cycle angle spans at least :data:`HARMONIC_MIN_SPAN`."""
    avail = available_families(model, rows)
    span = cycle_span(model, joints, ratios)
    timed = rows is not None and rows.order is not None
    tiers = (
        tuple(f for f in avail if f == "compliance"),
        ("mass_shape",) if lumped and "compliance" in avail else (),
        tuple(f for f in avail if f == "backlash" or (f == "drift" and timed)),
        tuple(f for f in avail if f.startswith("cyclic.q") and span[int(f[8:]) - 1] >= HARMONIC_MIN_SPAN),
    )
    return tuple(t for t in tiers if t)
