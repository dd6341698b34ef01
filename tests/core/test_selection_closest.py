"""Never worse, and say why (issue 38): where auto keeps nothing, it names the candidate that came
closest, its CV change and its p beside the level it needed."""

from __future__ import annotations

import json

import numpy as np

from station.core.accuracy.studies import StudyInputs, perturbed
from station.core.identification.identify import identify
from station.core.kinematics.poses import spread_joints
from station.core.measurement.measurements import MeasurementSet, add_noise
from station.core.terms.error_model import TermSpec, apply_terms, term_basis
from station.core.terms.selection import select_model
from station.io.robot.files import load_robot

ARM = load_robot("irb2600")


def _geometric_only(seed: int = 5) -> MeasurementSet:
    rng = np.random.default_rng(seed)
    q = spread_joints(ARM, 60, rng)
    true = perturbed(ARM, np.random.default_rng(seed), StudyInputs())
    basis = term_basis(ARM, q, TermSpec(("compliance",)))
    pts = apply_terms(ARM, q, true, basis, np.zeros(basis.size))[:, :3, 3]
    d = MeasurementSet("position", q, pts, np.array([0.015] * 3))
    return d.with_measured(add_noise(d, d.measured, rng))


def test_nothing_kept_names_the_closest_candidate_and_by_how_much():
    data = _geometric_only()
    sel = select_model(ARM, data, geometric=identify(ARM, data))
    assert sel.chosen == ()
    near = sel.closest
    scored = [r for r in sel.table if r.families]
    assert near is not None and near.p_value == min(r.p_value for r in scored)
    # its level: compliance, tried first on physics, alpha_physics; the others alpha over their tiers
    # and their step's candidates
    level = near.level
    assert level is not None and level == sel.level_of(near) and near.p_value >= level  # why it was not kept
    assert next(r for r in scored if r.families == ("compliance",)).level == sel.alpha_physics
    assert all(r.level is not None and r.level < sel.alpha for r in scored if r.families != ("compliance",))
    assert f"closest: {near.label}" in sel.summary and f"{near.change_pct:+.1f} %" in sel.summary
    doc = json.loads(json.dumps(sel.to_dict()))
    assert doc["closest"]["model"] == near.label and doc["closest"]["level_needed"] == level
    assert abs(doc["closest"]["cv_rms_um"] - near.cv_rms_mm * 1e3) < 1e-9


def test_a_forced_model_names_no_closest_candidate():
    data = _geometric_only()
    sel = select_model(ARM, data, geometric=identify(ARM, data), force=("compliance",))
    assert sel.closest is None and sel.to_dict()["closest"] is None
