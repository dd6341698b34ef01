"""Physics first, then evidence (issue 38): the order in which ``--model auto`` tries the terms, the
150° rule for a joint's harmonic, drift only with a time, and compliance held to its own level."""

from __future__ import annotations

import numpy as np

from station.core.accuracy.studies import StudyInputs, perturbed
from station.core.identification.identify import identify
from station.core.kinematics.poses import spread_joints
from station.core.measurement.measurements import MeasurementSet, add_noise
from station.core.terms.error_model import TermRows, TermSpec, apply_terms, term_basis
from station.core.terms.physics_order import HARMONIC_MIN_SPAN, candidate_tiers, cycle_span
from station.core.terms.selection import ALPHA_PHYSICS, select_model
from station.io.robot.files import load_robot

ARM = load_robot("irb2600")


def _narrow(q: np.ndarray, joint: int, span_deg: float) -> np.ndarray:
    """``q`` with joint ``joint`` (0-based) squeezed into ``span_deg`` about its middle."""
    out = q.copy()
    lo, hi = out[:, joint].min(), out[:, joint].max()
    mid = 0.5 * (lo + hi)
    out[:, joint] = mid + (out[:, joint] - lo) / (hi - lo) * np.radians(span_deg) - np.radians(span_deg) / 2
    return out


def test_the_span_counts_the_cycle_angle_and_a_gear_ratio_multiplies_it():
    q = _narrow(spread_joints(ARM, 30, np.random.default_rng(1)), 1, 80.0)
    span = cycle_span(ARM, q)
    assert abs(np.degrees(span[1]) - 80.0) < 1e-9
    ratios = (1.0, 3.0, 1.0, 1.0, 1.0, 1.0)  # the motor turns 3× per joint turn: 240° of its angle
    assert abs(np.degrees(cycle_span(ARM, q, ratios)[1]) - 240.0) < 1e-9


def test_tiers_compliance_first_then_timed_drift_then_the_harmonics_of_covered_joints():
    q = _narrow(spread_joints(ARM, 30, np.random.default_rng(1)), 1, 80.0)
    span = cycle_span(ARM, q)
    tiers = candidate_tiers(ARM, q)
    assert tiers[0] == ("compliance",)
    harmonics = tiers[-1]
    assert "cyclic.q2" not in harmonics  # 80° of joint 2: under 150°
    assert all((f"cyclic.q{j + 1}" in harmonics) == (span[j] >= HARMONIC_MIN_SPAN) for j in range(6))
    assert not any("drift" in t for t in tiers)  # row order is not a time
    timed = candidate_tiers(ARM, q, TermRows(order=np.arange(30) * 12.0))
    assert timed[1] == ("drift",)
    signs = np.where(np.arange(180).reshape(30, 6) % 4 < 2, 1.0, -1.0)
    assert "backlash" in candidate_tiers(ARM, q, TermRows(approach=signs))[1]


def _bent(q, seed, x):
    rng = np.random.default_rng(seed)
    true = perturbed(ARM, np.random.default_rng(seed), StudyInputs())
    spec = TermSpec(("compliance", "cyclic.q2"))
    pts = apply_terms(ARM, q, true, term_basis(ARM, q, spec), x)[:, :3, 3]
    d = MeasurementSet("position", q, pts, np.array([0.015] * 3))
    return d.with_measured(add_noise(d, d.measured, rng))


def test_a_harmonic_of_a_joint_swept_under_150_degrees_is_never_tried():
    """Joint 2 over 80° with a real first harmonic of 60″: auto does not try it (what the data see
    of it is mostly the joint's zero and a slope); compliance is tried first at its own level."""
    q = _narrow(spread_joints(ARM, 60, np.random.default_rng(3)), 1, 80.0)
    d = _bent(q, 3, np.array([3e-6, 4e-6, 3e-4, 0.0]))
    sel = select_model(ARM, d, geometric=identify(ARM, d))
    tried = {f for r in sel.table for f in r.families}
    assert "cyclic.q2" not in tried and "cyclic2.q2" not in tried
    first = sel.table[1]
    assert first.families == ("compliance",) and first.level == ALPHA_PHYSICS and first.kept
    assert sel.chosen[0] == "compliance"


def test_a_negative_compliance_is_not_kept_however_well_it_fits():
    """Data bent *against* gravity (a compliance of −3 µrad per lumped N·m at joints 2 and 3, a
    physically impossible robot): the compliance passes its test but is not kept, and the table says
    why."""
    q = spread_joints(ARM, 60, np.random.default_rng(4))
    d = _bent(q, 4, np.array([-3e-6, -3e-6, 0.0, 0.0]))
    sel = select_model(ARM, d, geometric=identify(ARM, d))
    row = sel.table[1]
    assert row.families == ("compliance",) and row.p_value is not None and row.p_value < row.level
    assert not row.plausible and not row.kept and "compliance" not in sel.chosen
    assert row.to_dict()["plausible"] is False
