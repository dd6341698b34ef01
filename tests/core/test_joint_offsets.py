"""Joint-zero offsets only (station.core.kinematics.joint_offsets): exact where they suffice, and honestly
worse than the full model where they do not."""

from __future__ import annotations

import numpy as np
import pytest

from station.core.kinematics.forward import forward
from station.core.kinematics.joint_offsets import apply_joint_offsets, fit_joint_offsets, offset_accuracy, offset_joints
from station.core.kinematics.poses import spread_joints
from station.core.kinematics.transforms import pose_error
from station.io.robot.files import load_robot

ROBOTS = {"irb2600": load_robot("irb2600"), "sr800": load_robot("sr800")}


def _targets(model, params, n, seed):
    q = spread_joints(model, n, np.random.default_rng(seed))
    if model.n_joints == 6:
        q[:, 4] = np.sign(q[:, 4]) * np.maximum(np.abs(q[:, 4]), 0.2)
    return forward(model, q, params, setup=False)


def test_folding_offsets_into_the_parameters_is_exact():
    m = ROBOTS["irb2600"]
    d = np.array([0.01, -0.02, 0.005, 0.03, -0.01, 0.02])
    q = spread_joints(m, 20, np.random.default_rng(0))
    np.testing.assert_allclose(forward(m, q, apply_joint_offsets(m, m.nominal, d)), forward(m, q + d), atol=1e-9)


@pytest.mark.parametrize("name", ROBOTS)
def test_offsets_only_robot_is_recovered_exactly(name):
    m = ROBOTS[name]
    rng = np.random.default_rng(1)
    true = rng.normal(0.0, 0.01, m.n_joints)  # ~0.6° (and 10 µm for the SCARA's z)
    identified = apply_joint_offsets(m, m.nominal, true)
    fit = fit_joint_offsets(m, identified, spread_joints(m, 100, rng))
    np.testing.assert_allclose(fit.offsets, true, atol=1e-12)
    assert fit.fit.max_position_um < 1e-6 and not fit.unobservable
    # a controller applying them reaches the targets exactly
    T = _targets(m, identified, 15, 2)
    r = offset_joints(m, fit.offsets, T)
    ok = r.has_joints
    assert ok.sum() >= 12
    e = pose_error(forward(m, r.joints[ok], identified, setup=False), T[ok])
    assert np.abs(e[:, :3]).max() < 1e-8


@pytest.mark.parametrize("name", ROBOTS)
def test_full_error_robot_offsets_leave_more_than_the_full_model(name):
    m = ROBOTS[name]
    rng = np.random.default_rng(3)
    offsets_part = rng.normal(0.0, 0.005, m.n_joints)
    identified = apply_joint_offsets(m, m.nominal, offsets_part)
    identified[6:] += rng.standard_normal(m.n_params - 6) * np.where(m.is_angle()[6:], 2e-5, 0.05)
    fit = fit_joint_offsets(m, identified, spread_joints(m, 300, rng))
    acc = offset_accuracy(m, identified, fit.offsets, _targets(m, identified, 40, 4))
    assert acc.n_targets >= 30
    u, j, f = acc.uncorrected, acc.joint_offsets, acc.full_model
    assert f.max_position_um < 1e-3  # the full model is exact on its own prediction
    assert j.rms_position_um > 10 * max(f.rms_position_um, 1e-3)  # offsets cannot express the rest
    assert j.rms_position_um < 0.5 * u.rms_position_um  # but they take out the offset part
    assert fit.fit.rms_position_um > 1.0
    d = acc.to_dict()
    assert set(d) >= {"uncorrected", "joint_offsets", "full_model"}


def test_against_a_true_robot_the_comparison_uses_the_reference():
    m = ROBOTS["irb2600"]
    rng = np.random.default_rng(5)
    true = m.nominal + rng.standard_normal(m.n_params) * np.where(m.is_angle(), 1e-4, 0.2)
    identified = true + rng.standard_normal(m.n_params) * np.where(m.is_angle(), 1e-6, 0.002)
    fit = fit_joint_offsets(m, identified, spread_joints(m, 300, rng))
    acc = offset_accuracy(m, identified, fit.offsets, _targets(m, true, 30, 6), reference_params=true)
    # against the true robot the full model is no longer exact, but still far better
    assert 0.0 < acc.full_model.rms_position_um < acc.joint_offsets.rms_position_um


def test_position_only_fit_holds_the_unobservable_axis_6():
    m = ROBOTS["irb2600"]  # its probe head K lies on axis 6
    identified = apply_joint_offsets(m, m.nominal, [0.0, 0.0, 0.0, 0.0, 0.0, 0.02])
    fit = fit_joint_offsets(m, identified, spread_joints(m, 50, np.random.default_rng(7)), rotation_weight_mm=0.0)
    assert fit.unobservable == ("A6",)
    assert fit.offsets[5] == 0.0
