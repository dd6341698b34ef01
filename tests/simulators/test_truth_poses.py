"""The simulator's own pose convention (simulators/truth_kinematics.py: scipy's rotations) against
the station's (station/core/kinematics/transforms.py): the simulated body's frames and the CMM report it
writes come from the simulator's, the station reads the report with its own, so the two must agree
with each other and with the documented R = Rz(yaw)·Ry(pitch)·Rx(roll) (docs/robot-file.md)."""

from __future__ import annotations

import numpy as np

from simulators.truth_kinematics import inverse, matrix_pose, pose_matrix, rotation_angle
from station.core.kinematics.transforms import invert, matrix_to_pose, pose_to_matrix, rotation_log


def _rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def _ry(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1.0, 0], [-s, 0, c]])


def _rx(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])


def test_both_conventions_are_the_documented_one_and_agree():
    rng = np.random.default_rng(3)
    for _ in range(200):
        p = np.concatenate([rng.normal(0, 500, 3), rng.uniform(-np.pi, np.pi, 3) * [1, 0.49, 1]])
        T = pose_matrix(p)
        assert np.allclose(T[:3, :3], _rz(p[5]) @ _ry(p[4]) @ _rx(p[3]), atol=1e-14)
        assert np.allclose(T, pose_to_matrix(p), atol=1e-12)
        assert np.allclose(matrix_pose(T), p, atol=1e-12) and np.allclose(matrix_to_pose(T), p, atol=1e-12)
        assert np.allclose(inverse(T), invert(T), atol=1e-12)
        R = pose_matrix(np.concatenate([[0, 0, 0], rng.normal(0, 0.3, 3)]))[:3, :3]
        assert np.isclose(rotation_angle(R), np.linalg.norm(rotation_log(R)), atol=1e-12)
