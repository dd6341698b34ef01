"""Built-in robots pass the checks a user's robot file passes (finite, ordered, physically
plausible limits and parameters; the TOML schema), and a SCARA's revolute soft limits hold to the
degree (issue 42: revolute limits left unconverted from degrees, 57× too wide, survived the SCARA
end-to-end and soft-limit tests because built-in robots skipped the plausibility check)."""

from __future__ import annotations

import math
import tomllib
from importlib import resources
from pathlib import Path

import numpy as np
import pytest

from drivers.controller import ModbusController
from drivers.controller_errors import MotionRejected
from simulators.controller_server import SimulatedController
from station.cell.limits.motion_guard import MotionGuard
from station.errors import ConfigError, UnreachableError
from station.io.robot import files as robot_files
from station.io.robot.files import builtin_robots, load_robot
from station.io.robot.schema import validate_robot_toml

#: sr800's revolute limits as its file writes them (deg), docs/robot-file.md: angle_unit = "deg"
SR800_DEG = {1: 130.0, 2: 145.0, 4: 360.0}


def test_every_built_in_robot_passes_the_schema_of_a_users_file():
    assert set(builtin_robots()) >= {"sr800", "irb2600"}
    for name in builtin_robots():
        text = resources.files("station.io.robots").joinpath(f"{name}.toml").read_text()
        validate_robot_toml(tomllib.loads(text), f"built-in robot {name}")


def _builtin(monkeypatch, tmp_path: Path, name: str, text: str) -> None:
    """A built-in robot ``name`` with the file ``text`` (the package's robots beside it)."""
    for other in builtin_robots():
        (tmp_path / f"{other}.toml").write_text(
            resources.files("station.io.robots").joinpath(f"{other}.toml").read_text())
    (tmp_path / f"{name}.toml").write_text(text)
    monkeypatch.setattr(robot_files.resources, "files", lambda package: tmp_path)


def test_a_built_in_robot_with_limits_in_degrees_read_as_radians_is_refused(monkeypatch, tmp_path):
    text = resources.files("station.io.robots").joinpath("sr800.toml").read_text()
    slipped = text.replace('angle_unit = "deg"', 'angle_unit = "rad"')  # its limits are degrees
    _builtin(monkeypatch, tmp_path, "slipped", slipped.replace('name = "sr800"', 'name = "slipped"'))
    assert "slipped" in builtin_robots()
    with pytest.raises(ConfigError, match=r"built-in robot slipped: .*beyond physical plausibility"):
        load_robot("slipped")


def test_a_built_in_robot_with_an_implausible_length_is_refused(monkeypatch, tmp_path):
    text = resources.files("station.io.robots").joinpath("sr800.toml").read_text()
    slipped = text.replace("x = 445.0", "x = 445000.0").replace('name = "sr800"', 'name = "far"')  # m read as mm
    _builtin(monkeypatch, tmp_path, "far", slipped)
    with pytest.raises(ConfigError, match=r"built-in robot far: parameter A2.x = 445000 mm is beyond"):
        load_robot("far")


def test_sr800s_revolute_limits_are_its_files_degrees_in_radians():
    lim = load_robot("sr800").joint_limits
    for j, deg in SR800_DEG.items():
        np.testing.assert_allclose(lim[j - 1], [-math.radians(deg), math.radians(deg)], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(lim[2], [-200.0, 0.0])  # the prismatic joint in mm, unscaled


@pytest.mark.parametrize("joint", [1, 2, 4])
def test_the_motion_guard_of_the_robots_limits_refuses_half_a_degree_beyond(joint):
    # a cell without [limits] guards the robot's own limits (cell_config._soft_limits)
    model = load_robot("sr800")
    guard = MotionGuard(model.joint_limits, joint_types=model.joint_types)
    q = np.array([0.1, -0.2, -50.0, 0.3])
    limit = SR800_DEG[joint]
    for sign in (1, -1):
        q[joint - 1] = sign * math.radians(limit - 0.5)
        guard.check_joints(q, "half a degree inside")
        q[joint - 1] = sign * math.radians(limit + 0.5)
        side = "upper" if sign > 0 else "lower"
        want = rf"joint {joint} = {sign * (limit + 0.5):.2f}° is 0.50° beyond its {side} soft limit {sign * limit:.2f}°"
        with pytest.raises(UnreachableError, match=want):
            guard.check_joints(q, "half a degree beyond")


def test_the_simulated_scara_refuses_half_a_degree_beyond_its_robots_limit():
    # the simulated controller's soft limits are the robot's (no [limits] given)
    sim = SimulatedController(time_scale=0.0).start()
    try:
        with ModbusController("127.0.0.1", sim.port, heartbeat_period=None) as ctl:
            inside = np.array([math.radians(129.5), math.radians(-144.5), -50.0, math.radians(359.5)])
            ctl.move_joints(inside).wait(2.0)
            np.testing.assert_allclose(ctl.read_joints(), inside, atol=1e-5)
            for j, deg in SR800_DEG.items():
                beyond = inside.copy()
                beyond[j - 1] = math.copysign(math.radians(deg + 0.5), inside[j - 1])
                with pytest.raises(MotionRejected, match=f"joint {j} violates its"):
                    ctl.move_joints(beyond).wait(2.0)
            np.testing.assert_allclose(ctl.read_joints(), inside, atol=1e-5)  # nothing moved
    finally:
        sim.stop()
