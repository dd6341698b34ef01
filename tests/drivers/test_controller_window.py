"""Map 2 against the simulated controller on loopback TCP: the whole station-side use of the
controller lies in one window of 128 registers at base 128 (the general-purpose registers of a
Universal Robots controller), with function codes 3, 4, 6 and 16 only; what falls outside gives
a typed error naming what to set."""

from __future__ import annotations

import numpy as np
import pytest
from pymodbus.client import ModbusTcpClient

from drivers.controller import ModbusController
from drivers.controller_errors import MapVersionError, RegisterWindowError
from drivers.controller_map import CorrectionState
from drivers.correction_table import TablePageError, TableVerifyError
from simulators import start_simulated_cell
from simulators.controller_server import SimulatedController
from station.core.table.values import CorrectionTableData, TableAxis


def _table(g: int = 4, n: int = 12) -> CorrectionTableData:
    axes = (TableAxis(300.0, 40.0, n), TableAxis(-300.0, 50.0, n), TableAxis(-np.pi, np.pi / 2, 4, periodic=True))
    return CorrectionTableData(axes, np.random.default_rng(3).normal(0, 2e-4, (2, n, n, 4, g)))


@pytest.fixture
def sim128():
    with SimulatedController(register_base=128, register_count=128, correction_state=1) as sim:
        yield sim


def test_a_whole_session_lies_in_registers_128_to_255(sim128):
    with ModbusController("127.0.0.1", sim128.port, register_base=128, heartbeat_period=0.05) as c:
        assert c.controller_correction_state() is CorrectionState.VENDOR
        c.move_joints([0.2, -0.3, -50.0, 0.1], speed=0.5).wait(5.0)
        np.testing.assert_allclose(c.read_joints(), [0.2, -0.3, -50.0, 0.1], atol=1e-6)
        c.move_cartesian([550.0, 120.0, 320.0, 0.0, 0.0, 0.3], elbow=1).wait(5.0)
        t = _table()
        c.upload_table(t)
        c.verify_table()
        c.stage_table()
        c.activate_table()
        assert c.table_crcs()["active"] == t.crc32() and sim128.active_table.same_as(t)
        c.read_cartesian()
    log = sim128.requests_log
    assert len(log) > 100
    assert all(128 <= a and a + n - 1 <= 255 for _fc, a, n in log), sorted({a for _f, a, _n in log})
    assert {fc for fc, _a, _n in log} <= {3, 4, 6, 16}


def test_a_table_of_32000_values_uploads_through_the_window(sim128):
    axes = (TableAxis(0.0, 10.0, 40), TableAxis(0.0, 10.0, 40), TableAxis(0.0, 10.0, 5))
    t = CorrectionTableData(axes, np.random.default_rng(0).normal(0, 1e-3, (1, 40, 40, 5, 4)))
    assert t.n_values == 32000
    with ModbusController("127.0.0.1", sim128.port, register_base=128, heartbeat_period=None) as c:
        c.upload_table(t)
        assert c.verify_table().same_as(t)
        c.stage_table()
        assert c.table_crcs()["staged"] == t.crc32()


def test_wrong_base_is_exception_2_naming_the_setting(sim128):
    c = ModbusController("127.0.0.1", sim128.port, register_base=0, heartbeat_period=None)
    with pytest.raises(RegisterWindowError, match=r"controller_register_base.*first register") as ei:
        c.connect()
    c.close()
    assert ei.value.code == 2 and ei.value.address == 0 and "0..127" in str(ei.value)
    assert sim128.command_writes == []


def test_a_window_smaller_than_the_map_is_refused_before_any_motion():
    with SimulatedController(register_base=128, register_count=100) as sim:
        c = ModbusController("127.0.0.1", sim.port, register_base=128, heartbeat_period=None)
        with pytest.raises(RegisterWindowError, match="smaller than the map"):
            c.connect()
        c.close()
        assert sim.command_writes == []


def test_only_function_codes_3_4_6_16_are_served(sim128):
    client = ModbusTcpClient("127.0.0.1", port=sim128.port, timeout=2.0, retries=0)
    assert client.connect()
    try:
        assert not client.read_holding_registers(130, count=1, device_id=1).isError()
        assert client.read_holding_registers(130, count=1, device_id=1).registers == [3]  # map_version
        assert client.read_input_registers(130, count=1, device_id=1).registers == [3]
        assert not client.write_register(128, 7, device_id=1).isError()  # FC 6 on hb_pc
        rr = client.read_coils(128, count=1, device_id=1)
        assert rr.isError() and rr.exception_code == 1
        for address in (127, 256):  # either side of the window
            rr = client.read_holding_registers(address, count=1, device_id=1)
            assert rr.isError() and rr.exception_code == 2
        rr = client.write_register(130, 9, device_id=1)  # map_version is the controller's
        assert rr.isError() and rr.exception_code == 2
    finally:
        client.close()


def test_wrong_map_version_is_a_typed_error(sim128):
    sim = SimulatedController(register_base=128, map_version=2).start()
    try:
        c = ModbusController("127.0.0.1", sim.port, register_base=128, heartbeat_period=None)
        with pytest.raises(MapVersionError, match=r"version 2 \(register 130\).*expects version 3"):
            c.connect()
        c.close()
    finally:
        sim.stop()


def test_page_crc_mismatch_is_typed_and_nothing_is_staged(sim128):
    with ModbusController("127.0.0.1", sim128.port, register_base=128, heartbeat_period=None) as c:
        sim128.corrupt_next_page()
        with pytest.raises(TablePageError, match="PAGE_CRC_MISMATCH"):
            c.upload_table(_table())
        with pytest.raises(TableVerifyError, match="last upload failed"):
            c.stage_table()
        assert c.table_crcs() == {"staged": 0, "active": 0, "previous": 0}
        assert not c.status().table_staged


def test_start_simulated_cell_hosts_the_window_it_is_given():
    with start_simulated_cell(seed=0, register_base=128, register_count=128) as servers:
        assert servers.controller_server.register_base == 128
        with ModbusController(servers.controller_host, servers.controller_port, register_base=128,
                              heartbeat_period=None) as c:
            assert c.n_joints == 4
        assert all(128 <= a <= 255 for _f, a, _n in servers.controller_server.requests_log)
