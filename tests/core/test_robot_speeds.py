"""Joint speeds in robot files (``max_speed``): read, checked, written back."""

from __future__ import annotations

import math

import numpy as np
import pytest

from station.core.kinematics.model import robot_from_dict, robot_to_toml
from station.errors import ConfigError
from station.io.robot.files import load_robot


def _doc(speeds):
    joints = [{"name": "A1", "joint": "revolute", "z": 800.0, "limits": [-130, 130]},
              {"name": "A2", "joint": "revolute", "x": 445.0, "limits": [-145, 145]},
              {"name": "A3", "joint": "prismatic", "x": 355.0, "limits": [-200, 0]}]
    for j, v in zip(joints, speeds):
        if v is not None:
            j["max_speed"] = v
    return {"robot": {"name": "r", "angle_unit": "deg", "length_unit": "mm"},
            "transform": [{"name": "R"}, *joints, {"name": "K", "z": -100.0}]}


def test_speeds_are_read_in_rad_and_mm_per_second():
    m = robot_from_dict(_doc([180.0, 90.0, 500.0]))
    assert m.max_speed is not None
    np.testing.assert_allclose(m.max_speed, [math.pi, math.pi / 2, 500.0])
    assert robot_from_dict(_doc([None, None, None])).max_speed is None


@pytest.mark.parametrize("speeds, pattern", [
    ([180.0, None, 500.0], r"max_speed is given for 2 of 3 joints"),
    ([180.0, -1.0, 500.0], r"'A2': max_speed must be a finite number > 0"),
    ([180.0, math.inf, 500.0], r"'A2': max_speed must be a finite number > 0"),
    ([180.0, "fast", 500.0], r"'A2': max_speed must be a finite number > 0"),
])
def test_bad_speeds_are_refused_naming_the_joint(speeds, pattern):
    with pytest.raises(ConfigError, match=pattern):
        robot_from_dict(_doc(speeds))


def test_a_speed_on_a_transform_without_joint_is_refused():
    d = _doc([None, None, None])
    d["transform"][-1]["max_speed"] = 10.0
    with pytest.raises(ConfigError, match=r"'K' has no joint, so no limits or max_speed"):
        robot_from_dict(d)


def test_speeds_survive_a_round_trip_and_an_identified_model_keeps_them():
    import tomllib

    m = load_robot("sr800")
    assert m.max_speed is not None
    back = robot_from_dict(tomllib.loads(robot_to_toml(m)))
    np.testing.assert_allclose(back.max_speed, m.max_speed, rtol=1e-12)
    np.testing.assert_allclose(m.with_params(m.nominal + 0.01).max_speed, m.max_speed)
