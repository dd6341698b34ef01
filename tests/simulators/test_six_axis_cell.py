"""The simulated six-axis cell: true errors, its configuration, and the controller's Cartesian
moves by general inverse kinematics (issue 9)."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.controller import ModbusController
from simulators.six_axis_cell import (
    SIX_AXIS_HOME,
    six_axis_cell,
    six_axis_config_text,
    six_axis_truth,
    start_six_axis_cell,
)
from station.cell.config.cell_config import parse_text
from station.core.kinematics.forward import forward
from station.core.kinematics.ik import configuration
from station.core.kinematics.transforms import matrix_to_pose


def test_true_errors_in_every_parameter_of_the_briefs_magnitude():
    t = six_axis_truth(1)
    m = t.model
    err = t.errors.reshape(-1, 6)[1:]  # A1 … A6 and K (R is the set-up)
    assert np.all(err != 0.0)  # every parameter is wrong
    lengths, angles = err[:, :3], np.degrees(err[:, 3:])
    assert 0.1 < float(np.sqrt(np.mean(lengths**2))) < 0.4  # several 0.1 mm
    assert 0.01 < float(np.sqrt(np.mean(angles**2))) < 0.04  # several 0.01°
    # backlash and repeatability per joint, larger in angle at the wrist (shorter levers)
    assert t.backlash.shape == (6,) and np.all(t.backlash > 0) and t.backlash[5] > 3 * t.backlash[0]
    assert np.all(t.repeatability > 0) and t.repeatability[5] > t.repeatability[0]
    # seeded: the same seed is the same robot, another seed another
    np.testing.assert_array_equal(six_axis_truth(1).params, t.params)
    assert not np.allclose(six_axis_truth(2).params, t.params)
    assert m.name == "irb2600"


def test_config_text_describes_the_cell():
    class S:
        def __init__(self) -> None:
            self.cell = six_axis_cell(2)
            self.probe_port = "socket://127.0.0.1:1"
            self.controller_host = "127.0.0.1"
            self.controller_port = 1502

    servers = S()
    cfg = parse_text(six_axis_config_text(servers, 2), "<six-axis>")
    assert cfg.model.name == "irb2600" and len(cfg.point_ids) == 24
    np.testing.assert_allclose(cfg.body_points, servers.cell.body.nominal, atol=1e-9)
    lim = cfg.model.joint_limits
    assert np.all(cfg.soft_limits[:, 0] > lim[:, 0]) and np.all(cfg.soft_limits[:, 1] < lim[:, 1])
    assert cfg.simulation.seed == 2


@pytest.fixture(scope="module")
def servers():
    s = start_six_axis_cell(seed=1)
    yield s
    s.stop()


def test_cartesian_moves_keep_the_configuration_the_robot_stands_in(servers):
    """The controller solves its nominal IK from the joints it stands at: a target reached in the
    wrist-flipped configuration stays flipped, a target in front of it stays in front."""
    m = servers.cell.truth.model
    with ModbusController(servers.controller_host, servers.controller_port, heartbeat_period=None) as c:
        np.testing.assert_allclose(c.read_joints(), SIX_AXIS_HOME, atol=1e-5)
        q_a = np.deg2rad([10.0, 20.0, 10.0, 30.0, 60.0, -40.0])
        q_flip = q_a + np.deg2rad([0.0, 0.0, 0.0, -180.0, 0.0, 180.0])
        q_flip[4] = -q_a[4]  # the same pose with the wrist flipped
        T = forward(m, np.stack([q_a, q_flip]), setup=False)
        np.testing.assert_allclose(T[0], T[1], atol=1e-9)
        target = np.deg2rad([12.0, 22.0, 8.0, 31.0, 58.0, -38.0])  # a small step away
        pose = matrix_to_pose(forward(m, target[None], setup=False)[0])
        for start in (q_a, q_flip):
            c.move_joints(start).wait(5.0)
            c.move_cartesian(pose, elbow=1).wait(5.0)
            q = c.read_joints()
            # the registers hold float32 joints, the encoder counts 1 µrad: a few µm over the arm
            np.testing.assert_allclose(forward(m, q[None], setup=False)[0, :3, 3],
                                       forward(m, target[None], setup=False)[0, :3, 3], atol=5e-3)
            assert tuple(configuration(m, q[None])[0]) == tuple(configuration(m, start[None])[0])
            assert np.max(np.abs(q - start)) < np.deg2rad(10.0)  # the nearby solution, not another branch
