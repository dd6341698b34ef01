"""Gravity compliance judged by the joint's deflection, not by one column's sign (issue 38,
station/core/terms/selection.py): beside the fitted torque shape (``mass_shape``) the compliance
column is one lumped point's mass and the sum of the others', so its value may read below zero
while the joint bends with gravity; and where the lumped compliance alone comes out bending a joint
against gravity, the shape is tried with it, since the lumped shape, not gravity, is what is wrong.

Pose data of the simulated IRB 2600 class arm with its own joint errors (simulators/joint_errors.py:
compliance of joints 2-6 under 60 kg at the elbow, 25 kg at the wrist and a 5 kg head, a first
harmonic of every joint), 15 µm / 15″ measurement noise and 10 µm of repeatability at each joint's
lever, 100 random poses."""

from __future__ import annotations

import numpy as np
import pytest

from simulators.joint_errors import six_axis_joint_errors
from simulators.six_axis_cell import LEVERS_MM, six_axis_truth
from simulators.truth_kinematics import true_forward
from station.core.identification.identify import identify
from station.core.kinematics.poses import spread_joints
from station.core.measurement.measurements import MeasurementSet, add_noise
from station.core.terms.error_model import TermSpec, apply_terms, term_basis
from station.core.terms.selection import IMPLAUSIBLE_SIGMAS, select_model

SIGMA = np.array([0.015] * 3 + [15 * np.pi / 180 / 3600] * 3)


def _arm(seed: int, n: int = 100, scale: float = 1.0):
    """The measured pose data of seed ``seed``, and the truth (model, params, joint errors × ``scale``)."""
    truth = six_axis_truth(seed)
    model, p = truth.model, truth.params
    errs = six_axis_joint_errors(seed, scale)
    rng = np.random.default_rng(seed)
    kinds = [t.joint for t in model.transforms]
    q = spread_joints(model, n, rng)
    T = true_forward(kinds, p, q + errs.delta(model, p, q) + rng.standard_normal(q.shape) * 0.01 / LEVERS_MM)
    d = MeasurementSet("pose", q, T, SIGMA)
    return d.with_measured(add_noise(d, T, rng)), (model, p, errs)


def _held_out_um(sel, truth, n: int = 300) -> float:
    """RMS [µm] of the selection's prediction against the truth's own (no noise) at other poses."""
    model, p, errs = truth
    q = spread_joints(model, n, np.random.default_rng(99))
    real = true_forward([t.joint for t in model.transforms], p, q + errs.delta(model, p, q))[:, :3, 3]
    basis = term_basis(model, q, TermSpec(sel.chosen), params=sel.fit.params)
    cols = np.array([basis.names.index(nm) for nm in sel.fit.basis.names], dtype=int)
    pred = apply_terms(model, q, sel.fit.params, basis.select(cols), sel.fit.values)[:, :3, 3]
    return float(np.sqrt(np.mean(np.sum((pred - real) ** 2, axis=1)))) * 1e3


def test_a_shape_whose_compliance_column_reads_below_zero_bends_with_gravity_and_is_kept():
    data, truth = _arm(6)
    model, p, errs = truth
    geo = identify(model, data)
    pair = select_model(model, data, geometric=geo, force=("compliance", "mass_shape")).fit
    # a compliance column below zero by more than the limit (a sign check alone refused this fit) ...
    assert any(n.startswith("compliance.") and v + IMPLAUSIBLE_SIGMAS * s < 0
               for n, v, s in zip(pair.basis.names, pair.values, pair.sigma))
    # ... while every loaded joint's fitted deflection follows the simulator's own gravity torque
    tau = errs.torques(model, p, data.joints)
    for j in {int(n.split(".")[1][1:]) - 1 for n in pair.basis.names if n.startswith("compliance.")}:
        cols = [i for i, n in enumerate(pair.basis.names) if n.split(".")[:2] in (["compliance", f"q{j + 1}"],
                                                                                 ["mass_shape", f"q{j + 1}"])]
        bend = pair.basis.B[:, j, cols] @ pair.values[cols]
        assert np.corrcoef(bend, tau[:, j])[0, 1] > 0.9, j
    auto = select_model(model, data, geometric=geo)
    assert auto.chosen[:2] == ("compliance", "mass_shape")
    assert next(r for r in auto.table if r.families == ("compliance", "mass_shape")).plausible


def test_where_the_lumped_compliance_bends_a_joint_against_gravity_the_shape_is_tried_with_it():
    data, truth = _arm(8)
    model = truth[0]
    geo = identify(model, data)
    auto = select_model(model, data, geometric=geo)
    lumped = auto.table[1]
    assert lumped.families == ("compliance",) and lumped.p_value is not None and lumped.p_value < lumped.level
    assert not lumped.plausible and not lumped.kept
    pair = next(r for r in auto.table if r.families == ("compliance", "mass_shape"))
    assert pair.plausible and pair.kept and pair.level == auto.alpha_physics and pair.base == ()
    assert auto.chosen[:2] == ("compliance", "mass_shape")
    geometric = select_model(model, data, geometric=geo, force=())
    harmonics = select_model(model, data, geometric=geo,
                             force=tuple(f for f in auto.chosen if f.startswith("cyclic")))
    # what the selection kept before (the harmonics without gravity) against what it keeps now
    ours, before = _held_out_um(auto, truth), _held_out_um(harmonics, truth)
    assert ours < 0.5 * before < _held_out_um(geometric, truth), (ours, before)


@pytest.mark.parametrize("seed", [6, 8])
def test_an_arm_bent_against_gravity_keeps_neither_the_lumped_compliance_nor_the_shape(seed):
    """The same arm with every joint error's sign turned (scale −1: the joints give against gravity, a
    physically impossible robot): both physics candidates earn their test and are refused."""
    data, truth = _arm(seed, scale=-1.0)
    model = truth[0]
    auto = select_model(model, data, geometric=identify(model, data))
    rows = {r.families: r for r in auto.table if r.families in (("compliance",), ("compliance", "mass_shape"))}
    assert set(rows) == {("compliance",), ("compliance", "mass_shape")}
    for r in rows.values():
        assert r.p_value is not None and r.p_value < r.level and not r.plausible and not r.kept
    assert "compliance" not in auto.chosen and "mass_shape" not in auto.chosen


@pytest.mark.parametrize("seed", [6, 8])
def test_the_same_arm_rigid_keeps_nothing(seed):
    """Scale 0: the same poses and noise without joint errors; no compliance, shape or harmonic."""
    truth = six_axis_truth(seed)
    model, p = truth.model, truth.params
    rng = np.random.default_rng(seed)
    q = spread_joints(model, 100, rng)
    T = true_forward([t.joint for t in model.transforms], p, q + rng.standard_normal(q.shape) * 0.01 / LEVERS_MM)
    d = MeasurementSet("pose", q, T, SIGMA)
    d = d.with_measured(add_noise(d, T, rng))
    assert select_model(model, d, geometric=identify(model, d)).chosen == ()
