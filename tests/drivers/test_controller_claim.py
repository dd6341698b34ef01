"""One station per controller in the driver and the simulated controller (map 3's claim block):
a second station refused naming the holder, a command with another token refused by the program,
the claim of a killed station freed by the program's watchdog (not by hand), and a driver without
a heartbeat thread that takes its lapsed claim back before it commands. Timing: every wait is
on a state of the controller, never a wall-clock bound."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from pymodbus.client import ModbusTcpClient

from drivers.controller import ModbusController
from drivers.controller_errors import ControllerClaimed
from drivers.controller_map import REG, Command, ErrorCode, encode, register_span
from simulators.controller_server import SimulatedController

ROOT = Path(__file__).resolve().parents[2]
HOLDER = """
import sys, time
from drivers.controller import ModbusController
c = ModbusController("127.0.0.1", int(sys.argv[1]), heartbeat_period=0.05).connect()
print("held", c.claim_token, flush=True)
time.sleep(600)
"""


def until(pred, what: str, limit: float = 60.0) -> None:
    """Wait for a state (the limit only stops a hung test; no test asserts a duration)."""
    deadline = time.monotonic() + limit
    while not pred():
        assert time.monotonic() < deadline, f"never: {what}"
        time.sleep(0.01)


@pytest.fixture
def sim():
    s = SimulatedController(time_scale=0.0, watchdog=0.5).start()
    yield s
    s.stop()


def test_the_claim_of_a_killed_station_expires_by_the_watchdog(sim):
    p = subprocess.Popen([sys.executable, "-c", HOLDER, str(sim.port)], cwd=ROOT, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, env=dict(os.environ, PYTHONPATH=str(ROOT)))
    try:
        assert p.stdout is not None
        word, token = p.stdout.readline().split()
        assert word == "held" and sim.register("claim_owner") == int(token)
        second = ModbusController("127.0.0.1", sim.port, heartbeat_period=None)
        with pytest.raises(ControllerClaimed) as ei:
            second.connect()
        assert ei.value.holder.pid == p.pid and ei.value.holder.host == "127.0.0.1"
        assert f"PID {p.pid}" in str(ei.value) and "watchdog (500 ms without its heartbeat)" in str(ei.value)
        p.send_signal(signal.SIGKILL)  # the station dies: no release, its heartbeat stops
        p.wait(10)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait(10)
    until(lambda: sim.register("claim_owner") == 0, "the watchdog frees the dead station's claim")
    assert [sim.register(n) for n in ("claim_request", "claim_host", "claim_pid", "claim_since")] == [0] * 4
    second.connect()  # now it is free: nobody cleared anything by hand
    assert second.claimed and sim.register("claim_owner") == second.claim_token
    assert second.holder().pid == os.getpid()
    second.move_joints([0.1, 0.2, -10.0, 0.3]).wait(5.0)
    second.close()
    assert sim.register("claim_owner") == 0  # given back at the orderly end
    assert sim.command_writes == [(1, 1)]  # the refused connect commanded nothing


def test_a_command_with_another_token_is_refused_by_the_program(sim):
    holder = ModbusController("127.0.0.1", sim.port, heartbeat_period=0.05).connect()
    try:
        q0 = sim.joints
        raw = ModbusTcpClient("127.0.0.1", port=sim.port, timeout=2.0, retries=0)
        assert raw.connect()
        try:  # a client that ignores the claim: a move written with another token
            seq = sim.register("cmd_seq") + 1
            block = ([int(Command.MOVE_JOINTS), seq, 0, 500] + encode("cmd_target", [0.5, 0.5, -50.0, 0.5, 0.0, 0.0])
                     + encode("cmd_token", holder.claim_token ^ 1))
            first, _count = register_span("cmd_code", "cmd_token")
            assert not raw.write_registers(first, block, device_id=1).isError()
            until(lambda: sim.register("error_seq") == seq, "the program answers the foreign command")
            assert sim.register("error_code") == ErrorCode.NOT_CLAIMED
            # and claim_owner is the program's: a PC cannot write it
            rr = raw.write_registers(REG["claim_owner"].address, [0, 0], device_id=1)
            assert rr.isError() and rr.exception_code == 2
        finally:
            raw.close()
        np.testing.assert_array_equal(sim.joints, q0)  # nothing moved
        holder.connect()  # the holder resynchronises its sequence number and goes on
        holder.move_joints([0.1, 0.2, -10.0, 0.3]).wait(5.0)
        assert [t for _c, _s, t in sim.command_log] == [holder.claim_token ^ 1, holder.claim_token]
    finally:
        holder.close()


def test_without_a_heartbeat_thread_a_lapsed_claim_is_taken_back_before_a_command(sim):
    c = ModbusController("127.0.0.1", sim.port, heartbeat_period=None).connect()
    try:
        until(lambda: sim.register("claim_owner") == 0, "the claim lapses: nothing beats")
        assert sim.register("claim_pid") == 0
        c.move_joints([0.1, 0.2, -10.0, 0.3]).wait(5.0)  # beats, finds the claim gone, asks again
        assert sim.register("claim_owner") == c.claim_token and sim.register("claim_pid") == os.getpid()
        assert sim.command_log == [(1, 1, c.claim_token)]
    finally:
        c.close()


def test_a_station_started_right_after_a_killed_one_waits_for_the_watchdog(sim):
    """The resume after a crash: the holder was a process of this machine that is gone, so the new
    station waits for the robot program's watchdog to free the claim (it clears nothing itself)."""
    p = subprocess.Popen([sys.executable, "-c", HOLDER, str(sim.port)], cwd=ROOT, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, env=dict(os.environ, PYTHONPATH=str(ROOT)))
    try:
        assert p.stdout is not None and p.stdout.readline().startswith("held")
    finally:
        p.send_signal(signal.SIGKILL)
        p.wait(10)
    c = ModbusController("127.0.0.1", sim.port, heartbeat_period=None)
    c.connect()  # no ControllerClaimed: it waited until the program freed the dead holder's claim
    try:
        assert sim.register("claim_owner") == c.claim_token and sim.register("claim_pid") == os.getpid()
    finally:
        c.close()


def test_a_station_after_one_that_died_on_its_first_heartbeat_is_granted(sim):
    """The program sees a heartbeat as live while ``hb_pc`` changes. A station killed right after
    its first heartbeat left hb_pc = 1; a new station counting from 0 would write 1 again, which
    the program cannot tell from silence, and its claim would never be granted (a CI run of the
    twenty-kills test met exactly this). The driver goes on from the value the controller holds."""
    raw = ModbusTcpClient("127.0.0.1", port=sim.port)
    assert raw.connect()
    try:
        assert not raw.write_register(REG["hb_pc"].address, 1).isError()  # the dead station's last heartbeat
    finally:
        raw.close()
    until(lambda: sim._watchdog_expired(), "the program sees no heartbeat for its watchdog period")
    c = ModbusController("127.0.0.1", sim.port, heartbeat_period=None)
    c.connect()
    try:
        assert sim.register("claim_owner") == c.claim_token and sim.register("hb_pc") == 2
    finally:
        c.close()
