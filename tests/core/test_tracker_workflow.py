"""Laser-tracker workflow: units and frame checked by registration before fitting, convergence
from any instrument frame, and degenerate data refused before fitting."""

from __future__ import annotations

import numpy as np
import pytest

from station.core.identification.identify import identify
from station.core.identification.registration import register
from station.core.kinematics.forward import forward
from station.core.kinematics.poses import spread_joints
from station.core.kinematics.transforms import pose_to_matrix
from station.core.measurement.measurements import MeasurementSet, synthetic_set
from station.core.units import DEG
from station.errors import ConfigError, IdentificationError
from station.io.robot.files import load_robot

SR800 = load_robot("sr800")


def _truth(seed=3):
    rng = np.random.default_rng(seed)
    return SR800.nominal + rng.standard_normal(36) * np.where(SR800.is_angle(), 5e-4, 0.2)


def _tracker_data(frame_pose, n=40, seed=5, true=None):
    """Noisy tracker positions of the true robot, the tracker standing at ``frame_pose``
    (pose of the robot base in the tracker frame)."""
    true = _truth() if true is None else true
    rng = np.random.default_rng(seed)
    q = spread_joints(SR800, n, rng)
    base = synthetic_set(SR800, "position", q, true, rng=rng)  # the same physical noise in every frame
    T = pose_to_matrix(frame_pose) @ np.linalg.inv(pose_to_matrix(true[:6]))
    p = np.array(true)
    p[:6] = frame_pose
    return p, base.with_measured(base.measured @ T[:3, :3].T + T[:3, 3])


@pytest.mark.parametrize("factor,unit", [(1e-3, "m"), (1 / 25.4, "inch"), (1e3, "µm")])
def test_wrong_length_unit_refused_with_unit_named(factor, unit):
    _, data = _tracker_data(np.zeros(6))
    wrong = MeasurementSet("position", data.joints, data.measured * factor, data.sigma)
    with pytest.raises(ConfigError, match=rf"look like {unit}, not mm"):
        identify(SR800, wrong)


FRAMES = {
    "aligned": np.zeros(6),
    "turned 120°, tilted 10°, 3 m away": np.array([2100.0, -1500.0, 1600.0, 10 * DEG, 0.0, 120 * DEG]),
    "flipped 180°, 10 m away": np.array([10_000.0, 4_000.0, -2_500.0, 180 * DEG, 0.0, 30 * DEG]),
}


def test_any_tracker_frame_converges_to_the_same_held_out_error():
    held_out = {}
    q_test = spread_joints(SR800, 60, np.random.default_rng(99))
    for name, frame in FRAMES.items():
        p_true, data = _tracker_data(frame)
        res = identify(SR800, data)
        assert res.converged, name
        assert res.registration is not None
        np.testing.assert_allclose(res.registration.transform, pose_to_matrix(frame), atol=5.0)
        # held-out positions in the same tracker frame, noise-free truth
        err = forward(SR800, q_test, res.params)[:, :3, 3] - forward(SR800, q_test, p_true)[:, :3, 3]
        held_out[name] = float(np.sqrt(np.mean(np.sum(err**2, axis=1))))
    values = np.array(list(held_out.values()))
    assert values.max() < 0.05, held_out  # mm: of the order of the 15 µm noise
    np.testing.assert_allclose(values, values[0], rtol=1e-6, err_msg=str(held_out))


def test_without_registration_a_flipped_frame_is_refused_or_fitted_right():
    """From the file's R = 0, a flipped tracker's fit either is refused (it diverged) or, with
    the whole set-up in the fitted set (issue 36), reaches the registered fit's held-out error:
    never a converged wrong robot."""
    p_true, data = _tracker_data(FRAMES["flipped 180°, 10 m away"])
    q_test = spread_joints(SR800, 60, np.random.default_rng(99))
    try:
        res = identify(SR800, data, register_frame=False)
    except IdentificationError:
        return
    err = forward(SR800, q_test, res.params)[:, :3, 3] - forward(SR800, q_test, p_true)[:, :3, 3]
    assert float(np.sqrt(np.mean(np.sum(err**2, axis=1)))) < 0.05


def test_wrong_joint_order_refused_with_worst_rows():
    _, data = _tracker_data(FRAMES["turned 120°, tilted 10°, 3 m away"])
    swapped = data.joints[:, [1, 0, 2, 3]]
    bad = MeasurementSet("position", swapped, data.measured, data.sigma)
    with pytest.raises(IdentificationError, match=r"joint order.*|worst row"):
        identify(SR800, bad)
    reg_err = None
    try:
        register(SR800, swapped, data.measured, 0.015)
    except (IdentificationError, ConfigError) as exc:
        reg_err = str(exc)
    assert reg_err is not None and "row " in reg_err


def test_joint_units_deg_as_rad_refused():
    _, data = _tracker_data(np.zeros(6))
    q = np.array(data.joints)
    q[:, [0, 1, 3]] = np.degrees(q[:, [0, 1, 3]]) * DEG * DEG  # degrees read as if they were rad·DEG
    bad = MeasurementSet("position", q, data.measured, data.sigma)
    with pytest.raises(IdentificationError, match="joint units"):
        identify(SR800, bad)


def _rows(data):
    return data.joints, data.measured


@pytest.mark.parametrize("case", ["identical", "zeros", "duplicated", "huge"])
def test_degenerate_data_refused_before_fitting(case):
    _, data = _tracker_data(np.zeros(6), n=50)
    q, m = np.array(data.joints), np.array(data.measured)
    if case == "identical":
        q[:], m[:] = q[0], m[0]
        pattern = "only 1 distinct joint configuration"
    elif case == "zeros":
        q[:], m[:] = 0.0, 0.0
        pattern = "only 1 distinct joint configuration"
    elif case == "duplicated":
        q, m = np.concatenate([q, q[:10]]), np.concatenate([m, m[:10]])
        pattern = "repeat another row exactly"
    else:
        m[3, 0] = 1e308
        pattern = "not a robot cell"
    with pytest.raises(ConfigError, match=pattern):
        identify(SR800, MeasurementSet("position", q, m, data.sigma[:3]))


def test_report_says_what_was_fitted():
    _, data = _tracker_data(FRAMES["turned 120°, tilted 10°, 3 m away"])
    res = identify(SR800, data)
    left_out = {d.name for d in res.identifiability.dependencies}
    assert set(res.chosen).isdisjoint(left_out)
    assert len(res.chosen) + len(left_out) == SR800.n_params
    assert any(d.merges_with for d in res.identifiability.dependencies)
    assert res.registration.scale == pytest.approx(1.0, abs=0.01)
    assert "R started from the registration" in " ".join(res.notes)


def test_distances_between_equal_nominal_points_are_dropped_not_a_crash():
    """q4 and q4 + 360° give the same point: such a distance has no direction (SVD did not converge)."""
    from station.core.measurement.distance_pairs import distances, make_pairs

    _, data = _tracker_data(np.zeros(6), n=30)
    q = np.vstack([data.joints, data.joints[:4] + np.array([0.0, 0.0, 0.0, 2 * np.pi])])
    pts = np.vstack([data.measured, data.measured[:4] + 0.01])
    pairs = make_pairs(len(q), "all")
    d = MeasurementSet("distance", q, distances(pts, pairs), np.sqrt(2) * 0.015, pairs, point_sigma=0.015)
    res = identify(SR800, d)
    assert sorted(res.dropped_pairs) == [(i, 30 + i) for i in range(4)]
    assert res.residuals.shape[0] == len(pairs) - 4
    assert "4 of 561 distances dropped" in " ".join(res.notes)


def test_marker_offset_refused_naming_tool_unknown_then_fitted():
    true = _truth()
    true[-6:-3] += [70.0, -45.0, 0.0]  # a reflector on an adapter the robot file does not know
    _, data = _tracker_data(FRAMES["turned 120°, tilted 10°, 3 m away"], true=true)
    with pytest.raises(ConfigError, match=r"--tool unknown") as exc:
        identify(SR800, data)
    assert "not a unit error" in str(exc.value)
    res = identify(SR800, data, tool_unknown=True)
    assert res.converged and res.rms_normalized < 2.0
    assert res.registration is not None and res.registration.tool_undetermined == 1  # a SCARA: height open
    np.testing.assert_allclose(res.registration.tool_offset_mm[:2] - SR800.nominal[-6:-4], [70.0, -45.0], atol=1.0)
