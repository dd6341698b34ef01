"""The identified robot in its true base frame (issue 36): a set-up error of a few mm stays with
the set-up, so the corrected robot beats the nominal one where the user commands it and reaches
the best a body calibration can (the truth with its unobservable part handed to the set-up)."""

from __future__ import annotations

import numpy as np
import pytest

from simulators.base_frame import base_frame_check, reference_params, targets_in_box
from station.core.identification.identify import identify
from station.core.kinematics.forward import forward
from station.core.kinematics.poses import spread_joints
from station.core.measurement.measurements import synthetic_set
from station.io.robot.files import load_robot

SCARA = "examples/scara600/robot.toml"
SIX_AXIS = "examples/puma560/puma560.mdh.csv"
SIGMA = np.array([0.006] * 3 + [np.radians(6 / 3600)] * 3)  # 6 µm, 6″: the example cell's


def cell(path: str, seed: int, setup_error):
    """A true robot (every parameter off by 0.2 mm / 0.02°), a set-up ``setup_error`` (mm, rad)
    off the configured one, and its noisy pose measurements at 60 poses."""
    m = load_robot(path)
    rng = np.random.default_rng(seed)
    p_true = m.nominal + rng.standard_normal(m.n_params) * np.where(m.is_angle(), np.radians(0.02), 0.2)
    p_true[:6] = m.nominal[:6] + np.asarray(setup_error, dtype=float)
    q = spread_joints(m, 60, rng)
    return m, p_true, q, synthetic_set(m, "pose", q, p_true, sigma=SIGMA, rng=rng), rng


def region_targets(m, q, rng, n=300):
    """Targets over the region the measurements cover (the head frame in the base frame)."""
    P = forward(m, q, m.nominal, setup=False)[:, :3, 3]
    return targets_in_box(m, P.min(axis=0), P.max(axis=0), n, rng)


@pytest.mark.parametrize("path", [SCARA, SIX_AXIS])
@pytest.mark.parametrize("seed", [1, 2])
def test_corrected_robot_in_its_true_base_frame(path, seed):
    setup_error = [3.0, -2.0, 2.5, np.radians(0.05), np.radians(-0.05), np.radians(0.3)]
    m, p_true, q, data, rng = cell(path, seed, setup_error)
    res = identify(m, data)
    check = base_frame_check(m, p_true, res.params, res.chosen, "pose", region_targets(m, q, rng), fit_joints=q)
    assert check.corrected_um < check.nominal_um
    assert check.ratio <= 1.2, check
    # the set-up took its error (and the truth's unobservable part): the identified R is the
    # reference's to a few σ, millimetres away from the configured guess
    p_ref = reference_params(m, p_true, res.chosen, "pose", q)
    assert np.all(np.abs(res.params[:3] - p_ref[:3]) < 0.05)
    assert np.all(np.abs(res.params[:3] - m.nominal[:3]) > 1.0)


@pytest.mark.parametrize("path", [SCARA, SIX_AXIS])
def test_setup_error_in_z_and_yaw_stays_with_the_setup(path):
    """A set-up 2 mm higher and 0.5° turned about z: the identified robot's parameters stay within
    σ (3 σ) of the truth's in the same convention, and its base frame with them; the robot file's
    base parameters (A1, through which set-up and robot meet) keep their values."""
    m, p_true, q, data, rng = cell(path, 3, [0.0, 0.0, 2.0, 0.0, 0.0, np.radians(0.5)])
    res = identify(m, data)
    p_ref = reference_params(m, p_true, res.chosen, "pose", q)
    robot = [k for k, n in enumerate(res.chosen) if not n.startswith("R.")]
    d = (res.estimates - p_ref[res.chosen_index])[robot]
    assert np.all(np.abs(d) <= 3 * res.uncertainty.sigma[robot]), dict(zip(np.array(res.chosen)[robot], d))
    a1 = [m.param_index(f"A1.{s}") for s in ("x", "y", "z", "roll", "pitch", "yaw")]
    np.testing.assert_array_equal(res.params[a1], m.nominal[a1])
    # the base frame itself: the identified and the reference robot agree to a few σ of position
    t = region_targets(m, q, rng, 200)
    gap = forward(m, t, res.params, setup=False)[:, :3, 3] - forward(m, t, p_ref, setup=False)[:, :3, 3]
    assert np.sqrt(np.mean(np.sum(gap**2, axis=1))) < 0.03  # mm; the set-up's 2 mm would show whole
    # and the convention is the set-up's: in the true base frame the identified robot is no worse
    # than the robot file's (a robot that took the set-up's 2 mm is ~2 mm off)
    check = base_frame_check(m, p_true, res.params, res.chosen, "pose", t, fit_joints=q)
    assert check.corrected_um < check.nominal_um and check.ratio <= 1.2, check
