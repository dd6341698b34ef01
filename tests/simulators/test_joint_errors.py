"""The simulated arm's joint errors beyond geometry (issue 30): compliance under gravity and gear
harmonics, their own physics, and the ``[simulation] joint_errors`` key."""

from __future__ import annotations

import numpy as np
import pytest

from simulators.cell import SimulatedCell
from simulators.from_config import _joint_errors
from simulators.joint_errors import NO_JOINT_ERRORS, six_axis_joint_errors
from simulators.six_axis_cell import six_axis_body, six_axis_truth
from station.cell.config.cell_config import simulation_settings
from station.core.kinematics.poses import spread_joints
from station.core.terms.error_model import GravityModel, gravity_torques
from station.errors import ConfigError
from station.io.robot.files import load_robot


def test_the_simulators_torques_agree_with_the_stations_own_computation():
    """Two independent computations of the same gravity torques: the simulator's (differences of the
    potential of its own kinematics) and the station's (levers and axes of its chain)."""
    truth = six_axis_truth(1)
    errs = six_axis_joint_errors(1)
    q = spread_joints(truth.model, 8, np.random.default_rng(4))
    # the simulator's point masses at the joint origins of joints 3 and 5: in the station's terms,
    # links 2 and 4 with their centres at the next transform's origin; the payload at the tool
    p = truth.params.reshape(-1, 6)
    com = [(0.0, 0.0, 0.0)] * 6
    com[1], com[3] = tuple(p[3, :3]), tuple(p[5, :3])
    masses = [0.0] * 6
    masses[1], masses[3] = 60.0, 25.0
    gm = GravityModel(masses=tuple(masses), com=tuple(com), payload_kg=5.0)
    np.testing.assert_allclose(errs.torques(truth.model, truth.params, q),
                               gravity_torques(truth.model, q, gm, truth.params), atol=1e-4)


def test_a_cell_with_joint_errors_stands_where_the_joints_bend():
    truth = six_axis_truth(2)
    errs = six_axis_joint_errors(2)
    cell = SimulatedCell(truth=truth, body=six_axis_body(2), seed=2, joint_errors=errs)
    rigid = SimulatedCell(truth=truth, body=six_axis_body(2), seed=2)
    q = np.deg2rad([10.0, 35.0, -20.0, 5.0, 40.0, 0.0])
    bent = cell._physical(q, noise=False) - rigid._physical(q, noise=False)
    np.testing.assert_allclose(bent, errs.delta(truth.model, truth.params, q[None])[0], atol=1e-15)
    assert np.degrees(abs(bent[1])) * 3600 > 10.0  # the shoulder gives tens of arc seconds
    assert SimulatedCell(truth=truth, body=six_axis_body(2), seed=2, joint_errors=NO_JOINT_ERRORS).joint_errors is None


def test_simulation_key_is_off_by_default_and_each_kind_for_its_arm():
    assert simulation_settings("[simulation]\nseed = 1\n")["joint_errors"] == "none"
    s = simulation_settings('[simulation]\njoint_errors = "six-axis"\njoint_errors_scale = 0.5\n')
    arm = six_axis_truth(1).model
    errs = _joint_errors(s, arm, 1)
    assert errs is not None and errs.compliance == six_axis_joint_errors(1, 0.5).compliance
    assert _joint_errors({"joint_errors": "none"}, arm, 1) is None
    with pytest.raises(ConfigError, match="six-axis arm"):
        _joint_errors(s, load_robot("sr800"), 1)
    assert simulation_settings('[simulation]\njoint_errors = "scara"\n')["joint_errors"] == "scara"
    assert _joint_errors({"joint_errors": "scara"}, load_robot("sr800"), 1) is not None
    with pytest.raises(ConfigError, match="is for a SCARA"):
        _joint_errors({"joint_errors": "scara"}, arm, 1)
    with pytest.raises(ConfigError):
        simulation_settings('[simulation]\njoint_errors = "delta"\n')
