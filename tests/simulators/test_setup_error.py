"""``[simulation] setup_error`` (issue 36): the true set-up's error planted exactly, the seed's robot
unchanged, and a bad table refused with the key and its bounds."""

from __future__ import annotations

import tomllib

import numpy as np
import pytest

from simulators import start_simulated_cell
from simulators.from_config import SimulationPhysics, setup_error_vector, simulated_cell_for
from simulators.reference_cell import cell_config_text
from station.cell.config.cell_config import parse_text
from station.core.units import DEG
from station.errors import ConfigError
from tests.simulators.test_from_config import user_config

PLANTED = "setup_error = { x_mm = -0.4, z_mm = 1.5, pitch_deg = 0.01, yaw_deg = 0.3 }"


def test_the_planted_error_is_the_truths_and_the_robot_stays_the_seeds():
    drawn = simulated_cell_for(parse_text(user_config()), 3).truth
    planted = simulated_cell_for(parse_text(user_config(PLANTED)), 3).truth
    assert planted.errors[:6] == pytest.approx([-0.4, 0.0, 1.5, 0.0, 0.01 * DEG, 0.3 * DEG], abs=1e-12)
    # the seed's robot, head and joints are the same draws; only R differs
    assert np.array_equal(planted.params[6:], drawn.params[6:])
    assert np.array_equal(planted.backlash, drawn.backlash)
    assert not np.allclose(drawn.errors[:6], planted.errors[:6])


def test_a_planted_error_is_exact_whatever_the_sigma():
    """σ scales a draw; a planted error ignores it (σ 0 and σ 50 mm plant the same set-up)."""
    a = simulated_cell_for(parse_text(user_config(f"setup_sigma_mm = 0.0\n{PLANTED}")), 5).truth
    b = simulated_cell_for(parse_text(user_config(f"setup_sigma_mm = 50.0\n{PLANTED}")), 5).truth
    assert np.array_equal(a.params, b.params)


@pytest.mark.parametrize("bad, where", [
    ("setup_error = { z_mm = 101.0 }", r"simulation\.setup_error\.z_mm"),
    ("setup_error = { yaw_deg = -10.5 }", r"simulation\.setup_error\.yaw_deg"),
    ("setup_error = { z = 1.0 }", r"simulation\.setup_error: unknown key 'z'; allowed: x_mm"),
    ('setup_error = { z_mm = "1" }', r"simulation\.setup_error\.z_mm"),
    ("setup_error = [0.0, 0.0, 1.5, 0.0, 0.0, 0.3]", r"simulation\.setup_error"),
])
def test_a_bad_setup_error_is_refused_with_its_key(bad, where):
    with pytest.raises(ConfigError, match=where):
        parse_text(user_config(bad))


def test_the_builtin_cell_records_a_planted_error_as_the_table_it_reads():
    table = {"z_mm": -1.2, "yaw_deg": 0.25}
    with start_simulated_cell(seed=2, setup_error=table) as servers:
        assert servers.cell.truth.errors[:6] == pytest.approx(setup_error_vector(table), abs=1e-12)
        sim = tomllib.loads(cell_config_text(servers, 2))["simulation"]
    assert sim["setup_error"] == table
    assert SimulationPhysics.from_settings(sim).setup_error == table
