"""Driver against the simulated controller over real TCP on 127.0.0.1 (ephemeral port)."""

import time

import numpy as np
import pytest

from drivers.controller import ModbusController
from drivers.controller_errors import (
    ControllerConnectionError,
    ControllerLinkLost,
    DriveFault,
    EmergencyStop,
    HandshakeTimeout,
    ModbusExceptionError,
    MotionAborted,
    MotionRejected,
)
from drivers.controller_map import REG, Command, ControllerError, WordOrder
from drivers.correction_table import TableError, TableVerifyError
from simulators.controller_server import SimulatedController
from station.core.kinematics.forward import forward, scara_ik
from station.core.kinematics.transforms import matrix_to_pose, pose_to_matrix
from station.core.table.values import CorrectionTableData, TableAxis


def wait_for(cond, timeout, what):
    deadline = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.01)


@pytest.fixture
def sim():
    s = SimulatedController(time_scale=0.0).start()
    yield s
    s.stop()


@pytest.fixture
def ctl(sim):
    c = ModbusController("127.0.0.1", sim.port, heartbeat_period=0.05)
    c.connect()
    yield c
    c.close()


def test_joint_move_and_nominal_cartesian(sim, ctl):
    q = np.array([0.3, -0.6, -80.0, 0.4])
    ctl.move_joints(q, speed=0.8).wait(2.0)
    np.testing.assert_allclose(ctl.read_joints(), q, atol=1e-5)
    expected = matrix_to_pose(forward(sim.model, q[None], setup=False)[0])
    np.testing.assert_allclose(ctl.read_cartesian(), expected, atol=1e-3)
    st = ctl.status()
    assert st.in_position and not st.moving and st.ready and st.done_seq == st.ack_seq == 1


def test_cartesian_move_uses_nominal_ik_with_elbow(sim, ctl):
    pose = np.array([550.0, 150.0, 320.0, 0.0, 0.0, 0.3])
    for elbow in (1, -1):
        ctl.move_cartesian(pose, elbow=elbow).wait(2.0)
        q = ctl.read_joints()
        assert np.sign(q[1]) == elbow
        np.testing.assert_allclose(ctl.read_cartesian()[[0, 1, 2, 5]], pose[[0, 1, 2, 5]], atol=2e-3)


def test_soft_limit_and_unreachable_rejected(sim, ctl):
    st = ctl.move_joints([0.0, 2.6, -50.0, 0.0])
    with pytest.raises(MotionRejected, match="joint 2 violates its upper soft limit 2.53073") as ei:
        st.wait(1.0)
    assert ei.value.seq == st.seq
    with pytest.raises(MotionRejected, match="not reachable"):
        ctl.move_cartesian([1500.0, 0, 300, 0, 0, 0]).wait(1.0)
    np.testing.assert_allclose(ctl.read_joints(), sim.joints, atol=1e-6)  # nothing moved


def test_sequence_numbers_continue_across_sessions(sim, ctl):
    for k in range(3):
        st = ctl.move_joints([0.1 * k, 0.2, -10.0, 0.0])
        st.wait(1.0)
        assert st.seq == k + 1
    ctl.close()
    with ModbusController("127.0.0.1", sim.port, heartbeat_period=None) as c2:
        st = c2.move_joints([0.0, 0.0, -10.0, 0.0])
        st.wait(1.0)
        assert st.seq == 4 and c2.status().done_seq == 4


def test_pending_motion_blocks_new_motion_and_stop_aborts():
    with SimulatedController(time_scale=1.0) as sim, \
            ModbusController("127.0.0.1", sim.port, heartbeat_period=0.05) as c:
        st = c.move_joints([2.0, 0.0, -100.0, 0.0], speed=0.2)  # ~4 s
        wait_for(lambda: c.status().moving, 2.0, "moving bit")
        with pytest.raises(ControllerError, match="still in progress"):
            c.move_joints([0.0, 0.0, -100.0, 0.0])
        c.stop(timeout=2.0)
        with pytest.raises(MotionAborted):
            st.wait(1.0)
        assert 0.0 < c.read_joints()[0] < 2.0


def test_controller_watchdog_stops_move_without_pc_heartbeat():
    with SimulatedController(time_scale=1.0, watchdog=0.2) as sim:
        with ModbusController("127.0.0.1", sim.port, heartbeat_period=None) as c:
            st = c.move_joints([0.5, 0.0, -100.0, 0.0], speed=1.0)
            with pytest.raises(ControllerLinkLost, match="PC heartbeat stopped"):
                st.wait(3.0)
            assert c.status().error
            c.reset_error()
        with ModbusController("127.0.0.1", sim.port, heartbeat_period=0.04) as c:
            c.move_joints([0.5, 0.0, -100.0, 0.0], speed=1.0).wait(3.0)  # ~0.25 s, heartbeat alive
            np.testing.assert_allclose(c.read_joints()[0], 0.5, atol=1e-6)


def test_robot_heartbeat_loss_declares_link_lost(sim):
    with ModbusController("127.0.0.1", sim.port, heartbeat_period=0.03, link_timeout=0.2) as c:
        sim.freeze_heartbeat(True)
        wait_for(lambda: c.link_lost is not None, 3.0, "link lost")
        with pytest.raises(ControllerLinkLost, match="did not advance"):
            c.status()
        sim.freeze_heartbeat(False)
        c.connect()
        assert c.link_lost is None and c.status().ready


def test_modbus_exception_then_recovery(sim, ctl):
    sim.inject_modbus_exception(REG["act_joints"].address, function_code=3, code=2)
    with pytest.raises(ModbusExceptionError, match="illegal data address") as ei:
        ctl.read_joints()
    assert ei.value.code == 2 and ei.value.function_code == 3
    assert ctl.read_joints().shape == (4,)
    with pytest.raises(ModbusExceptionError) as ei:  # the robot heartbeat is read-only
        ctl._write(REG["hb_robot"].address, [1])
    assert ei.value.code == 2


def test_estop_needs_reset(sim, ctl):
    sim.estop_during_next_move()
    with pytest.raises(EmergencyStop):
        ctl.move_joints([0.4, 0.0, -50.0, 0.0]).wait(1.0)
    s = ctl.status()
    assert s.estop and s.error and not s.ready
    with pytest.raises(MotionRejected, match="reset"):
        ctl.move_joints([0.4, 0.0, -50.0, 0.0]).wait(1.0)
    ctl.reset_error()
    assert not ctl.status().estop
    ctl.move_joints([0.4, 0.0, -50.0, 0.0]).wait(1.0)
    np.testing.assert_allclose(ctl.read_joints()[0], 0.4, atol=1e-6)


def test_drive_fault(sim, ctl):
    sim.drive_fault_during_next_move(axis=3)
    with pytest.raises(DriveFault, match="axis 3"):
        ctl.move_joints([0.0, 0.3, -50.0, 0.0]).wait(1.0)
    ctl.reset_error()
    ctl.move_joints([0.0, 0.3, -50.0, 0.0]).wait(1.0)


def test_lost_ack_raises_and_is_not_resent(sim, ctl):
    before = ctl.read_joints()
    sim.lose_next_ack()
    ctl.ack_timeout = 0.2
    with pytest.raises(HandshakeTimeout, match="NOT re-sent.*operator must check"):
        ctl.move_joints([0.7, 0.0, -50.0, 0.0])
    np.testing.assert_allclose(ctl.read_joints(), before)
    st = ctl.move_joints([0.7, 0.0, -50.0, 0.0])  # next number is accepted
    st.wait(1.0)
    assert st.seq == 2
    # "sent exactly once" without a pause to watch: the driver writes its commands in order on
    # one connection, so a re-sent number 1 would stand before number 2 in the server's log
    writes = list(sim.command_writes)
    assert (1, 2) in writes and [w for w in writes if w[1] == 1] == [(1, 1)], writes


def test_tcp_disconnect_then_reconnect(sim):
    with ModbusController("127.0.0.1", sim.port, heartbeat_period=None, timeout=0.5) as c:
        c.status()
        sim.drop_connections()
        with pytest.raises(ControllerConnectionError):
            wait_for(lambda: c.status() is None, 2.0, "the dropped connection to surface")
        # The client reconnects on a later call; the server may still be closing the old socket
        # for a moment, so allow a bounded number of attempts.
        deadline = time.monotonic() + 3.0
        while True:
            try:
                assert c.status().ready
                break
            except ControllerConnectionError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.05)


def test_latency_is_tolerated(sim, ctl):
    sim.set_latency(0.05)
    t = time.monotonic()
    ctl.read_joints()
    assert time.monotonic() - t >= 0.05
    sim.set_latency(0.0)


def test_little_endian_word_order():
    with SimulatedController(word_order=WordOrder.LITTLE) as sim, \
            ModbusController("127.0.0.1", sim.port, word_order=WordOrder.LITTLE, heartbeat_period=None) as c:
        np.testing.assert_allclose(c.soft_limits()[2], [-200.0, 0.0])
        c.move_joints([0.2, 0.1, -30.0, 0.5]).wait(1.0)
        np.testing.assert_allclose(c.read_joints(), [0.2, 0.1, -30.0, 0.5], atol=1e-6)


def _table(seed=0, n_configs=2):
    axes = (TableAxis(450.0, 50.0, 5), TableAxis(-100.0, 50.0, 5), TableAxis(250.0, 100.0, 2),
            TableAxis(-np.pi, np.pi / 4, 8, periodic=True))
    rng = np.random.default_rng(seed)
    return CorrectionTableData(axes, rng.normal(0.0, 1e-3, (n_configs, 5, 5, 2, 8, 4)))


def test_table_lifecycle(sim, ctl):
    t1, t2 = _table(1), _table(2)
    with pytest.raises(TableVerifyError, match="no table uploaded"):
        ctl.activate_table()
    ctl.upload_table(t1)
    assert ctl.read_table().same_as(t1)
    with pytest.raises(TableVerifyError, match="stage_table"):
        ctl.activate_table()  # read back fine, but not staged yet
    ctl.stage_table()
    assert ctl.table_crcs()["staged"] == t1.crc32()
    ctl.activate_table()
    assert ctl.status().table_active and sim.active_table.same_as(t1)
    ctl.upload_table(t2)
    ctl.verify_table()
    ctl.stage_table()
    ctl.activate_table()
    assert ctl.table_crcs() == {"staged": 0, "active": t2.crc32(), "previous": t1.crc32()}
    ctl.rollback_table()
    assert sim.active_table.same_as(t1)
    ctl.deactivate_table()
    assert not ctl.status().table_active and ctl.table_crcs()["active"] == 0
    with pytest.raises(TableError, match="no staged table"):
        ctl._table_command(Command.TABLE_ACTIVATE, 1.0)  # bypass the driver-side gate


def test_activation_refused_when_readback_differs(sim, ctl):
    t = _table(3)
    ctl.upload_table(t)
    sim.corrupt_staging_value(17, 1e-3)  # value 17 changes in the controller's store
    with pytest.raises(TableError, match="CRC-32"):
        ctl.read_table()  # the whole-table CRC-32 of the read-back catches it
    with pytest.raises(TableVerifyError, match="read-back failed"):
        ctl.activate_table()
    with pytest.raises(TableVerifyError, match="read-back failed"):
        ctl.stage_table()  # nothing is staged from a table that did not read back
    assert not ctl.status().table_active and not ctl.status().table_staged


def test_corrected_cartesian_move_follows_interpolation_rule(sim, ctl):
    t = _table(4)
    ctl.upload_table(t)
    ctl.verify_table()
    ctl.stage_table()
    ctl.activate_table()
    for pose, elbow in (([537.0, 12.5, 301.0, 0.0, 0.0, 0.37], 1),
                        ([612.0, -71.0, 333.0, 0.0, 0.0, 2.9], -1)):
        pose = np.array(pose, dtype=np.float32).astype(float)  # what travels on the wire
        ctl.move_cartesian(pose, elbow=elbow).wait(1.0)
        q_nom = scara_ik(sim.model, pose_to_matrix(pose)[None], elbow=elbow, setup=False)[0]
        dq = t.interpolate(pose[[0, 1, 2, 5]], 0 if elbow == 1 else 1)
        assert np.max(np.abs(dq)) > 1e-4
        np.testing.assert_allclose(ctl.read_joints(), q_nom + dq, atol=2e-6)
    with pytest.raises(MotionRejected, match="outside the active correction table"):
        ctl.move_cartesian([700.0, 300.0, 300.0, 0, 0, 0]).wait(1.0)
    ctl.move_joints([0.1, 0.2, -30.0, 0.0]).wait(1.0)  # joint moves are not corrected
    np.testing.assert_allclose(ctl.read_joints(), [0.1, 0.2, -30.0, 0.0], atol=1e-6)
