"""The simulated reference cell: its configuration text, and its controller in either word order."""

import tomllib

import numpy as np
import pytest

from drivers.controller import ModbusController
from drivers.controller_errors import WordOrderError
from drivers.controller_map import WordOrder
from simulators import start_simulated_cell
from simulators.cell import DEFAULT_SETUP
from simulators.reference_cell import cell_config_text


@pytest.fixture(scope="module")
def little_cell():
    with start_simulated_cell(seed=5, word_order=WordOrder.LITTLE) as servers:
        yield servers


def test_config_text_describes_the_running_cell(little_cell):
    servers = little_cell
    cfg = tomllib.loads(cell_config_text(servers, 5))
    dev = cfg["devices"]
    assert dev["controller"] == f"{servers.controller_host}:{servers.controller_port}"
    assert dev["probe_head"] == servers.probe_port
    assert "word_order" not in dev  # big is the configuration's default
    assert cfg["simulation"]["seed"] == 5
    body = servers.cell.body
    assert cfg["body"]["cube_edge_mm"] == body.cube_edge_mm
    assert len(cfg["body"]["points"]) == len(body.labels)
    assert cfg["body"]["points"][0]["id"] == f"C{body.labels[0][0] + 1}.{'abcd'[body.labels[0][1]]}"
    np.testing.assert_allclose(cfg["body"]["points"][0]["pose"][:3], body.nominal[0][:3, 3])
    np.testing.assert_allclose(cfg["robot"]["setup"][:3], DEFAULT_SETUP[:3])


def test_config_text_names_a_little_word_order(little_cell):
    cfg = tomllib.loads(cell_config_text(little_cell, 5, word_order="little"))
    assert cfg["devices"]["word_order"] == "little"
    assert cfg["devices"]["motion_timeout_s"] == 30.0
    with pytest.raises(ValueError, match="word_order"):
        cell_config_text(little_cell, 5, word_order="LITTLE")


def test_little_word_order_cell_serves_true_joints(little_cell):
    servers = little_cell
    sim = servers.controller_server
    with ModbusController(servers.controller_host, servers.controller_port, word_order=WordOrder.LITTLE,
                          heartbeat_period=None) as c:
        np.testing.assert_allclose(c.read_joints(), sim.joints, rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(c.soft_limits(), sim.soft_limits, rtol=1e-6)
        # every joint away from 0, whose two words read the same in either order
        target = np.array([0.3, -0.4, -80.0, 1.2])
        c.move_joints(target).wait(2.0)
        truth = sim.joints
        np.testing.assert_allclose(truth, target, atol=1e-3)
        np.testing.assert_allclose(c.read_joints(), truth, rtol=1e-6, atol=1e-6)
    # A client configured for the other word order would swap the halves of every 32-bit value
    # (the soft limits read as implausible numbers): it is refused on connect, naming the order.
    c = ModbusController(servers.controller_host, servers.controller_port, word_order=WordOrder.BIG,
                         heartbeat_period=None)
    with pytest.raises(WordOrderError) as info:
        c.connect()
    c.close()
    assert info.value.detected is WordOrder.LITTLE
    np.testing.assert_allclose(sim.joints, truth)  # nothing moved
