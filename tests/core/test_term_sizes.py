"""A kept term says its physical size (issue 38): a compliance in µrad per N·m, a harmonic in arc
seconds, and the largest joint turn it gives over the data, each with its σ."""

from __future__ import annotations

import json

import numpy as np
import pytest

from station.core.accuracy.studies import StudyInputs, perturbed
from station.core.identification.identify import identify
from station.core.kinematics.poses import spread_joints
from station.core.measurement.measurements import MeasurementSet, add_noise
from station.core.terms.error_model import GravityModel, TermSpec, apply_terms, gravity_torques, term_basis
from station.core.terms.selection import select_model
from station.core.units import ARCSEC
from station.io.robot.files import load_robot

ARM = load_robot("irb2600")
GRAVITY = GravityModel(masses=(0.0, 25.0, 20.0, 8.0, 4.0, 1.0), payload_kg=12.0)


def test_compliance_in_microradians_per_newton_metre_and_its_largest_turn():
    rng = np.random.default_rng(7)
    q = spread_joints(ARM, 60, rng)
    spec = TermSpec(("compliance", "cyclic.q4"), GRAVITY)
    basis = term_basis(ARM, q, spec)
    x = np.array([2e-6, 3e-6] + [0.0] * (basis.size - 4) + [1e-4, -5e-5])
    true = perturbed(ARM, np.random.default_rng(7), StudyInputs())
    d = MeasurementSet("position", q, apply_terms(ARM, q, true, basis, x)[:, :3, 3], np.array([0.015] * 3))
    d = d.with_measured(add_noise(d, d.measured, rng))
    sel = select_model(ARM, d, spec=spec, geometric=identify(ARM, d), force=("compliance", "cyclic.q4"))
    terms = {t["name"]: t for t in json.loads(json.dumps(sel.fit.terms_dict()))}
    c2 = terms["compliance.q2"]
    assert c2["unit"] == "rad/(N·m)" and c2["readable"]["unit"] == "µrad/(N·m)"
    # the station divides by 1e-6: the same as × 1e6 to the last bit for most values, not all
    assert c2["readable"]["value"] == pytest.approx(c2["value"] * 1e6, rel=1e-15)
    assert c2["readable"]["sigma"] == pytest.approx(c2["sigma"] * 1e6, rel=1e-15)
    assert abs(c2["readable"]["value"] - 2.0) < 4 * c2["readable"]["sigma"]  # the true 2 µrad/(N·m)
    tau = np.abs(gravity_torques(ARM, q, GRAVITY, sel.geometric.params)[:, 1]).max()  # at the fitted geometry
    assert abs(c2["largest_joint_turn"]["value"] - tau * abs(c2["value"]) / ARCSEC) < 1e-9 * tau
    assert c2["largest_joint_turn"]["unit"] == "″" and c2["largest_joint_turn"]["sigma"] > 0
    h = terms["cyclic.q4.cos1"]
    assert h["readable"]["unit"] == "″" and abs(h["readable"]["value"] - h["value"] / ARCSEC) < 1e-9
    assert "largest_shift" not in h
