"""The torque shape fitted where the robot file gives no masses (issue 38, station/core/terms/mass_shape.py):
the lumped term is the sum of the points' torques, and ``--model auto`` keeps the fitted shape where
the arm's weight sits elsewhere than the lumped 1 kg per joint (and only there)."""

from __future__ import annotations

import numpy as np
import pytest

from simulators.joint_errors import JointErrors
from simulators.six_axis_cell import six_axis_truth
from simulators.truth_kinematics import true_forward
from station.core.identification.identify import identify
from station.core.kinematics.poses import spread_joints
from station.core.measurement.measurements import MeasurementSet, add_noise
from station.core.terms.error_model import GravityModel, TermSpec, apply_terms, gravity_torques, term_basis
from station.core.terms.mass_shape import lumped_points, point_torques
from station.core.terms.selection import select_model
from station.errors import ConfigError

SIGMA = np.array([0.015] * 3)
#: the simulated heavy arm's weight (simulators/joint_errors.py): 60 kg at joint 3's origin, 25 kg at
#: joint 5's, 5 kg at the tool; compliances of a stiff shoulder and elbow, ×3 to show over the noise
HEAVY = JointErrors(compliance=(0.0, 1.2e-6, 1.8e-6, 0.0, 0.0, 0.0), masses=((2, 60.0), (4, 25.0)), payload_kg=5.0)
#: the same compliances under the lumped shape itself: 1 kg at every later joint's origin and the tool
LUMPED = JointErrors(compliance=(0.0, 6e-5, 9e-5, 0.0, 0.0, 0.0),
                     masses=((1, 1.0), (2, 1.0), (3, 1.0), (4, 1.0), (5, 1.0)), payload_kg=1.0)


def test_the_lumped_term_is_the_sum_of_its_points_torques():
    truth = six_axis_truth(1)
    q = spread_joints(truth.model, 20, np.random.default_rng(3))
    tau_b = point_torques(truth.model, q, GravityModel().gravity, truth.params)
    assert tau_b.shape == (len(lumped_points(truth.model)), 20, 6)
    lumped = gravity_torques(truth.model, q, GravityModel(), truth.params)
    np.testing.assert_allclose(tau_b.sum(axis=0), lumped, atol=1e-9 * np.abs(lumped).max())
    # a vertical axis 1 carries no gravity torque (the drawn robot's axis tilts by hundredths of a degree)
    assert np.abs(tau_b[:, :, 0]).max() < 1e-3 * np.abs(tau_b).max()


def _measure(errs: JointErrors, seed: int, n: int):
    truth = six_axis_truth(seed)
    model, p = truth.model, truth.params
    kinds = [t.joint for t in model.transforms]
    rng = np.random.default_rng(seed)
    q = spread_joints(model, n, rng)
    pts = true_forward(kinds, p, q + errs.delta(model, p, q))[:, :3, 3]
    d = MeasurementSet("position", q, pts, SIGMA)
    return model, d.with_measured(add_noise(d, pts, rng)), (kinds, p, errs)


def _held_out_um(model, sel, truth, n: int = 200) -> float:
    kinds, p, errs = truth
    q = spread_joints(model, n, np.random.default_rng(99))
    real = true_forward(kinds, p, q + errs.delta(model, p, q))[:, :3, 3]
    basis = term_basis(model, q, TermSpec(sel.chosen), params=sel.fit.params)
    cols = np.array([basis.names.index(nm) for nm in sel.fit.basis.names], dtype=int)
    pred = apply_terms(model, q, sel.fit.params, basis.select(cols), sel.fit.values)[:, :3, 3]
    return float(np.sqrt(np.mean(np.sum((pred - real) ** 2, axis=1)))) * 1e3


def test_auto_fits_the_torque_shape_where_the_weight_sits_at_the_elbow_and_wrist():
    model, data, truth = _measure(HEAVY, 1, 120)
    geo = identify(model, data)
    auto = select_model(model, data, geometric=geo)
    lumped = select_model(model, data, geometric=geo, force=("compliance",))
    assert auto.chosen[:2] == ("compliance", "mass_shape")
    row = next(r for r in auto.table if r.families[-1:] == ("mass_shape",))
    assert row.kept and row.level == auto.alpha_physics
    assert any(n.startswith("mass_shape.q2.") for n in auto.fit.basis.names)
    # the lumped shape leaves what the fitted one takes, at poses it never saw
    assert _held_out_um(model, auto, truth) < 0.8 * _held_out_um(model, lumped, truth)


def test_auto_keeps_the_lumped_shape_where_the_arm_is_built_like_it():
    model, data, _ = _measure(LUMPED, 2, 120)
    auto = select_model(model, data, geometric=identify(model, data))
    assert "compliance" in auto.chosen and "mass_shape" not in auto.chosen


def test_a_robot_file_with_masses_has_no_shape_to_fit():
    truth = six_axis_truth(1)
    spec = TermSpec(("compliance", "mass_shape"), GravityModel(masses=(0.0, 0.0, 60.0, 0.0, 25.0, 0.0)))
    q = spread_joints(truth.model, 5, np.random.default_rng(0))
    with pytest.raises(ConfigError, match="gives the masses"):
        term_basis(truth.model, q, spec)


def test_a_fitted_shape_is_written_with_the_model_and_read_back(tmp_path, capsys):
    """identify -o keeps the fitted shape's terms; validate predicts with them as the fit did."""
    import json

    from station.io.datafile import write_csv
    from station.ui.cli.main import main

    model, data, _ = _measure(HEAVY, 3, 60)
    f = tmp_path / "cal.csv"
    write_csv(f, [f"q{i} [deg]" for i in range(1, 7)] + ["x [mm]", "y [mm]", "z [mm]"],
              np.column_stack([np.degrees(data.joints), data.measured]))
    out = tmp_path / "model.toml"
    assert main(["identify", str(f), "--robot", "irb2600", "--model", "compliance+mass_shape", "-o", str(out),
                 "--json"]) == 0
    em = json.loads(capsys.readouterr().out)["error_model"]
    assert any(t["name"].startswith("mass_shape.q2.") for t in em["terms"])
    assert '"mass_shape"' in out.read_text()
    assert main(["validate", str(out), str(f), "--json"]) == 0
    rms = json.loads(capsys.readouterr().out)["model_errors"]["rms_position_um"]
    lumped = select_model(model, data, geometric=identify(model, data), force=("compliance",))
    assert rms < 0.5 * lumped.fit.rms_position_mm() * 1e3  # the shape's fit, not the lumped one's
