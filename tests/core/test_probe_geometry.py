"""3-2-1 probe-head geometry: forward readings, pose solve, markers, sensitivity."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from station.core.kinematics.transforms import matrix_to_pose, pose_to_matrix, rotation_log
from station.core.probe.geometry import (
    PoseSolveError,
    contact_pose_covariance,
    default_probe_head,
    readings_from_pose,
    readings_from_poses,
    solve_pose,
)

ARCSEC = np.pi / (180 * 3600)
GEOM = default_probe_head()
M_NOM = GEOM.nominal_contact_pose()


def perturbed(delta):
    """Nominal pose moved by ``delta`` = (x, y, z, roll, pitch, yaw) in MPKS."""
    return M_NOM @ pose_to_matrix(np.asarray(delta, dtype=float))


def random_small_poses(n, seed=0):
    rng = np.random.default_rng(seed)
    d = np.hstack([rng.uniform(-2.0, 2.0, (n, 3)), rng.uniform(-0.02, 0.02, (n, 3))])
    return M_NOM @ pose_to_matrix(d)


def test_layout_and_nominal_pose():
    assert GEOM.mount_points.shape == (6, 3) and GEOM.directions.shape == (6, 3)
    assert GEOM.faces.tolist() == [0, 0, 0, 1, 1, 2]
    np.testing.assert_allclose(np.linalg.norm(GEOM.directions, axis=1), 1.0)
    np.testing.assert_allclose(M_NOM[:3, :3], np.eye(3))  # axes parallel to MKKS
    np.testing.assert_allclose(M_NOM[:3, 3], [0.0, 0.0, -60.0])  # corner below the head
    np.testing.assert_allclose(readings_from_pose(GEOM, M_NOM), 0.0, atol=1e-12)
    assert not GEOM.mount_points.flags.writeable


def test_reading_sign_convention():
    # cube 1 mm farther below: top plungers extend (+1); 1 mm closer: pushed back (-1)
    np.testing.assert_allclose(readings_from_pose(GEOM, perturbed([0, 0, -1, 0, 0, 0]))[:3], 1.0)
    np.testing.assert_allclose(readings_from_pose(GEOM, perturbed([0, 0, 1, 0, 0, 0]))[:3], -1.0)
    # cube moved +x in MKKS: the x face recedes from the +x pointing probes
    np.testing.assert_allclose(readings_from_pose(GEOM, perturbed([0.5, 0, 0, 0, 0, 0]))[3:5], 0.5)


def test_round_trip_random_small_poses():
    Ms = random_small_poses(200)
    R = readings_from_poses(GEOM, Ms)
    assert np.isfinite(R).all()
    for M, r in zip(Ms, R):
        np.testing.assert_array_equal(readings_from_pose(GEOM, M), r)  # vectorised == single
        sol = solve_pose(GEOM, r)
        assert sol.converged and sol.iterations <= 10
        assert np.max(np.abs(sol.M[:3, 3] - M[:3, 3])) < 1e-9
        assert np.linalg.norm(rotation_log(sol.M[:3, :3] @ M[:3, :3].T)) < 1e-9
        assert np.max(np.abs(sol.residuals_mm)) < 1e-9
        assert 1 < sol.condition < 100
        np.testing.assert_allclose(readings_from_pose(GEOM, sol.M), r, atol=1e-9)


def test_solution_is_read_only():
    sol = solve_pose(GEOM, np.zeros(6))
    np.testing.assert_allclose(sol.M, M_NOM, atol=1e-12)
    with pytest.raises(ValueError):
        sol.M[0, 0] = 2.0


def test_misses_and_out_of_stroke_give_markers():
    # cube moved +6 mm in x: probe 0 (contact x = 5) falls off the top face's edge, probe 2
    # (x = 20) still lands, the x-face probes run out of stroke (+6 > +5)
    r = readings_from_pose(GEOM, perturbed([6.0, 0, 0, 0, 0, 0]))
    assert np.isnan(r[0]) and np.isfinite(r[2])
    assert np.isposinf(r[3:5]).all()
    # cube 6 mm closer: top plungers pushed beyond -stroke/2
    assert np.isneginf(readings_from_pose(GEOM, perturbed([0, 0, 6.0, 0, 0, 0]))[:3]).all()
    # side probes at z = -15 miss when the cube drops 20 mm (their contact is above the top)
    r = readings_from_pose(GEOM, perturbed([0, 0, -20.0, 0, 0, 0]))
    assert np.isnan(r[3:]).all()
    # a cube turned 90 degrees about y: top face parallel to the top probes -> miss
    r = readings_from_pose(GEOM, perturbed([0, 0, 0, 0, np.pi / 2, 0]))
    assert np.isnan(r[:3]).all()


def test_vectorised_shape():
    Ms = random_small_poses(12).reshape(3, 4, 4, 4)
    assert readings_from_poses(GEOM, Ms).shape == (3, 4, 6)


def test_noise_sensitivity_matches_covariance_and_is_arcseconds():
    sigma = 0.001  # 1 µm
    M = perturbed([0.5, -0.3, 0.2, 0.004, -0.003, 0.002])
    r0 = readings_from_pose(GEOM, M)
    cov = contact_pose_covariance(GEOM, M, sigma)
    assert cov.shape == (6, 6)
    np.testing.assert_allclose(cov, cov.T)
    rng = np.random.default_rng(7)
    p_true = matrix_to_pose(M)
    samples = np.array([
        matrix_to_pose(solve_pose(GEOM, r0 + rng.normal(0, sigma, 6), noise_mm=sigma).M) - p_true
        for _ in range(1500)
    ])
    empirical = samples.std(axis=0)
    predicted = np.sqrt(np.diag(cov))
    np.testing.assert_allclose(empirical, predicted, rtol=0.1)
    # documented figures: 1 µm reading noise -> about 1-2 µm and 8-13 arc seconds
    assert np.all(predicted[:3] < 0.002)
    assert np.all((predicted[3:] / ARCSEC > 5) & (predicted[3:] / ARCSEC < 15))


def test_covariance_scales_with_noise():
    c1 = contact_pose_covariance(GEOM, M_NOM, 0.001)
    c2 = contact_pose_covariance(GEOM, M_NOM, 0.002)
    np.testing.assert_allclose(c2, 4 * c1, rtol=1e-6)


@pytest.mark.parametrize(
    "readings",
    [[np.nan, 0, 0, 0, 0, 0], [0, 0, np.inf, 0, 0, 0], [0, 0, 0, 0, 0, -np.inf], [0.0] * 5],
)
def test_solver_refuses_non_finite_or_wrong_shape(readings):
    with pytest.raises(PoseSolveError):
        solve_pose(GEOM, np.array(readings))


def test_solver_refuses_when_not_converged():
    r = readings_from_pose(GEOM, perturbed([1.0, 1.0, 1.0, 0.02, 0.02, 0.02]))
    with pytest.raises(PoseSolveError, match="did not converge"):
        solve_pose(GEOM, r, max_iterations=1)


def test_solver_refuses_contacts_off_the_faces():
    # Readings that a larger cube (edge 80) produces, with a long stroke: the exact solution
    # puts probe 1 at x = 42 mm, outside the 40 mm cube the geometry describes.
    big = dataclasses.replace(GEOM, cube_edge_mm=80.0, stroke_mm=40.0)
    r = readings_from_pose(big, perturbed([-7.0, 0, 0, 0, 0, 0]))
    assert np.isfinite(r).all()
    long_stroke = dataclasses.replace(GEOM, stroke_mm=40.0)
    with pytest.raises(PoseSolveError, match=r"probes \[1\] off"):
        solve_pose(long_stroke, r)


def test_overdetermined_head_checks_plane_residuals():
    # a fourth probe on the top face makes the residual meaningful
    extra = GEOM.mount_points[0] + np.array([10.0, 20.0, 0.0])
    head7 = dataclasses.replace(
        GEOM,
        mount_points=np.vstack([GEOM.mount_points, extra]),
        directions=np.vstack([GEOM.directions, GEOM.directions[0]]),
        faces=np.append(GEOM.faces, 0),
    )
    M = perturbed([0.2, 0.1, -0.3, 0.003, 0.001, -0.002])
    r = readings_from_pose(head7, M)
    sol = solve_pose(head7, r, noise_mm=0.0005)
    assert np.max(np.abs(sol.M - M)) < 1e-9
    r_bad = r.copy()
    r_bad[6] += 0.02  # 20 µm: a dirty probe
    with pytest.raises(PoseSolveError, match="plane residuals"):
        solve_pose(head7, r_bad, noise_mm=0.0005)
    # within the noise bound it is accepted, and the residuals are reported
    r_ok = r.copy()
    r_ok[6] += 0.0005
    assert np.max(np.abs(solve_pose(head7, r_ok, noise_mm=0.0005).residuals_mm)) > 1e-5


def test_geometry_validation():
    # a real head's probes need not read 0 at the nominal touch, but inside their stroke with
    # a margin (20 % of the stroke at each end: |reading| <= 3 mm for a 10 mm stroke)
    assert np.allclose(dataclasses.replace(GEOM, mount_points=GEOM.mount_points + [0.0, 0.0, 0.1])
                       .nominal_readings()[:3], 0.1)
    with pytest.raises(ValueError, match="probe 1 \\(channel 1\\) reads 3.500 mm"):
        dataclasses.replace(GEOM, mount_points=GEOM.mount_points + [0.0, 0.0, 3.5])
    with pytest.raises(ValueError):
        dataclasses.replace(GEOM, faces=np.array([0, 0, 0, 1, 1, 3]))
    with pytest.raises(ValueError):
        dataclasses.replace(GEOM, mount_points=GEOM.mount_points[:5],
                            directions=GEOM.directions[:5], faces=GEOM.faces[:5])
