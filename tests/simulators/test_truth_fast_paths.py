"""The simulated truth's two fast paths (issue 42: the suite's time) change no figure: the fixed
links built once give the same chain to the last bit as building them each time, and the capture
check's rotation angle is scipy's, near 0 and near π too."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from simulators import truth_kinematics as tk
from station.io.robot.files import load_robot

ROOT = Path(__file__).resolve().parents[2]


def _uncached_forward(kinds, params, q):
    """true_forward's chain with every fixed link built afresh (the code before the cache)."""
    p = np.asarray(params, dtype=float).reshape(len(kinds), 6)
    T = np.broadcast_to(np.eye(4), (q.shape[0], 4, 4)).copy()
    j = 0
    for t, kind in enumerate(kinds):
        S = np.eye(4)
        S[:3, :3] = Rotation.from_euler("xyz", p[t, 3:6]).as_matrix()
        S[:3, 3] = p[t, :3]
        T = T @ S
        if kind is not None:
            T = T @ tk._joint(kind, q[:, j])
            j += 1
    return T


@pytest.mark.parametrize("robot", ["sr800", str(ROOT / "examples" / "scara600" / "robot.toml")])
def test_the_cached_links_give_the_chain_to_the_last_bit(robot):
    model = load_robot(robot)
    kinds = [t.joint for t in model.transforms]
    rng = np.random.default_rng(5)
    for _ in range(20):
        params = model.nominal + rng.normal(0, 1e-3, model.n_params)
        q = rng.uniform(-1, 1, (3, model.n_joints))
        for _again in range(2):  # the second time from the cache
            assert np.array_equal(tk.true_forward(kinds, params, q), _uncached_forward(kinds, params, q))


def test_a_cached_link_cannot_be_changed_in_place():
    link = tk._static(np.array([1.0, 2.0, 3.0, 0.1, 0.2, 0.3]))
    with pytest.raises(ValueError):
        link[0, 3] = 0.0


def test_the_rotation_angle_is_scipys_from_0_to_pi():
    rng = np.random.default_rng(7)
    axes = rng.normal(size=(300, 3))
    axes /= np.linalg.norm(axes, axis=1)[:, None]
    angles = np.concatenate([rng.uniform(0, np.pi, 100), rng.uniform(0, 1e-6, 100), np.pi - rng.uniform(0, 1e-6, 100)])
    for axis, angle in zip(axes, angles, strict=True):
        R = Rotation.from_rotvec(axis * angle).as_matrix()
        assert tk.rotation_angle(R) == pytest.approx(Rotation.from_matrix(R).magnitude(), abs=1e-12)
    assert tk.rotation_angle(np.eye(3)) == 0.0
