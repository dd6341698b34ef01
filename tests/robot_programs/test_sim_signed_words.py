"""The simulated controller's robot program reads its registers the way a UR program does
(e-Series Script Directory §17.38: read_port_register returns the signed value -32768 .. 32767)
and turns them into the map's words itself, so a signed/unsigned slip fails here - as the first
UR program's unsigned reads would have failed on the robot."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.controller import ModbusController
from drivers.controller_map import REG, ControllerError
from simulators.controller_server import SimulatedController

# sr800 (the simulator's default robot): 1.5708 rad = 1 570 800 counts = 0x0017F7F0, a low word
# >= 0x8000; -0.5 rad: a high word 0xFFFF
TARGET = np.array([1.5708, -0.5, -50.0, 0.7])


def test_the_simulated_program_sees_signed_registers_and_decodes_every_target():
    with SimulatedController(time_scale=0.0) as sim:
        ctl = ModbusController("127.0.0.1", sim.port).connect()
        try:
            ctl.move_joints(TARGET, speed=0.5).wait(10.0)
            np.testing.assert_allclose(sim.joints, TARGET, atol=1e-6)
            low = REG["cmd_target"].address + 1  # joint 1's low word (big word order)
            assert sim._regs[low] == 0xF7F0  # read by the program as 0xF7F0 - 65536 = -2064
            # sequence numbers past 32767: the program reads them as negative values
            ctl._seq = sim._last_seq = 32766  # both sides at 32766, as after 32 766 commands
            for _ in range(3):
                ctl.stop()
            assert sim.register("ack_seq") == 32769 and sim.register("cmd_seq") == 32769
        finally:
            ctl.close()


def test_a_program_that_forgets_the_signed_reads_fails(monkeypatch):
    monkeypatch.setattr(SimulatedController, "_word", staticmethod(lambda v: v))  # the slip
    sim = SimulatedController(time_scale=0.0).start()
    ctl = ModbusController("127.0.0.1", sim.port, ack_timeout=0.5, command_timeout=1.0)
    try:
        with pytest.raises(ControllerError):
            ctl.connect()
            ctl.move_joints(TARGET, speed=0.5).wait(2.0)
    finally:
        ctl.close()
        with pytest.raises(RuntimeError, match="failed"):
            sim.stop()
