"""The verified upload (station.cell.correction.upload): sequence, events, roll back policy; against a
fake controller that mirrors the driver's gates, and against the simulated controller."""

from __future__ import annotations

import math

import numpy as np
import pytest

from drivers.correction_table import TableError, TableVerifyError
from station.cell.correction.upload import verified_upload
from station.cell.run.facts.events import Event, Notice, PhaseChanged
from station.core.table.build import build_correction_table
from station.core.table.grid import GridSpec
from station.core.table.values import CorrectionTableData, TableAxis
from station.io.robot.files import load_robot

# --------------------------------------------------------------------------

def small_table(v=0.001):
    axes = (TableAxis(0.0, 10.0, 3), TableAxis(-math.pi, math.pi / 2, 4, periodic=True))
    vals = np.full((2, 3, 4, 4), v, dtype=np.float32)
    vals[1] *= -1
    return CorrectionTableData(axes, vals)


class FakeController:
    """Keeps staged/active/previous like the controller program, and gates like the driver:
    ``verify_table`` compares the read-back, ``activate_table`` refuses an unverified table or
    a staged CRC that is not the uploaded one."""

    def __init__(self, corrupt=False, activate_error=None, activate_takes_effect=True,
                 crcs_readable=True, stage_crc_wrong=False, crc_read_failures=0):
        self.crc_read_failures = crc_read_failures
        self.calls, self.corrupt, self.activate_error = [], corrupt, activate_error
        self.activate_takes_effect = activate_takes_effect
        self.crcs_readable = crcs_readable
        self.stage_crc_wrong = stage_crc_wrong
        self.uploaded = self.staged = self.previous = None
        self.verified = False
        self.active = small_table(0.5)  # an older table is active

    def status(self):
        raise AssertionError("the upload sequence does not need the status word")

    def upload_table(self, t):
        self.calls.append("upload")
        self.uploaded, self.verified = t, False

    def verify_table(self):
        self.calls.append("verify")
        back = self.uploaded
        if self.corrupt:
            v = back.values.copy()
            v.ravel()[17] += 1e-8  # one count of the wire's 1e-8 grid
            back = CorrectionTableData(back.axes, v)
        diff = self.uploaded.first_difference(back)
        if diff is not None:
            raise TableVerifyError(f"read-back differs from upload: {diff}: upload the table again")
        self.verified = True
        return back

    def stage_table(self, timeout=None):
        self.calls.append("stage")
        self.staged = small_table(0.7) if self.stage_crc_wrong else self.uploaded

    def activate_table(self, timeout=None):
        self.calls.append("activate")
        if not self.verified or self.staged.crc32() != self.uploaded.crc32():
            raise TableVerifyError("activation refused: staged table CRC does not match the upload")
        if self.activate_takes_effect:
            self.previous, self.active, self.staged = self.active, self.staged, None
        if self.activate_error is not None:
            raise self.activate_error

    def deactivate_table(self, timeout=None):
        self.calls.append("deactivate")

    def rollback_table(self, timeout=None):
        self.calls.append("rollback")
        self.previous, self.active = self.active, self.previous

    def table_crcs(self):
        if not self.crcs_readable:
            raise TimeoutError("no answer")
        if self.crc_read_failures > 0:
            self.crc_read_failures -= 1
            raise TimeoutError("transient")
        return {k: 0 if getattr(self, k) is None else getattr(self, k).crc32()
                for k in ("staged", "active", "previous")}


def test_upload_verified_happy_path_and_its_events():
    ctl, events = FakeController(), []
    t = small_table()
    rep = verified_upload(ctl, t, events.append)
    assert ctl.calls == ["upload", "verify", "stage", "activate"]
    assert rep.crc32 == t.crc32() == rep.active_crc32 == rep.staged_crc32
    assert rep.previous_crc32 == small_table(0.5).crc32()
    assert rep.n_values == t.n_values
    assert rep.total_s >= rep.upload_s >= 0
    assert all(isinstance(e, Event) for e in events)
    assert isinstance(events[0], PhaseChanged) and events[0].phase == "upload"
    texts = [e.message for e in events if isinstance(e, Notice)]
    assert any("read back" in m and "identical" in m for m in texts)
    assert any("active" in m and f"{t.crc32():#010x}" in m for m in texts)


def test_upload_verified_refuses_a_changed_value():
    ctl, events = FakeController(corrupt=True), []
    with pytest.raises(TableVerifyError, match="first at flat index 17"):
        verified_upload(ctl, small_table(), events.append)
    assert "activate" not in ctl.calls and "stage" not in ctl.calls
    assert ctl.active.same_as(small_table(0.5))
    assert any(isinstance(e, Notice) and e.level == "warning" and "NOT activated" in e.message for e in events)


def test_upload_verified_refuses_a_wrong_staged_crc():
    ctl = FakeController(stage_crc_wrong=True)
    with pytest.raises(TableVerifyError, match="staged"):
        verified_upload(ctl, small_table(), lambda e: None)
    assert "rollback" not in ctl.calls  # the refusal changed nothing: nothing to roll back
    assert ctl.active.same_as(small_table(0.5))


def test_activation_failure_rolls_back():
    ctl = FakeController(activate_error=TableError("no done within timeout"))
    with pytest.raises(TableError, match="no done") as ei:
        verified_upload(ctl, small_table(), lambda e: None)
    assert ctl.calls == ["upload", "verify", "stage", "activate", "rollback"]
    assert ctl.active.same_as(small_table(0.5))  # the previous table is active again
    assert any("rolled back" in n for n in getattr(ei.value, "__notes__", []))


def test_unreadable_crcs_mean_no_activation():
    ctl = FakeController(crcs_readable=False)
    with pytest.raises(TableVerifyError, match="NOT activated"):
        verified_upload(ctl, small_table(), lambda e: None)
    assert "activate" not in ctl.calls and "rollback" not in ctl.calls
    assert ctl.active.same_as(small_table(0.5))


def test_transient_crc_read_errors_do_not_cause_a_roll_back():
    # the controller refused activation; two transient read errors of the CRCs must not make the
    # station believe the table changed and roll back to the one before (docs/correction.md)
    ctl = FakeController(activate_error=TableError("refused"), activate_takes_effect=False, crc_read_failures=2)
    with pytest.raises(TableError, match="refused") as ei:
        verified_upload(ctl, small_table(), lambda e: None)
    assert "rollback" not in ctl.calls
    assert any("still active" in n for n in ei.value.__notes__)
    ctl = FakeController(crc_read_failures=2)  # and a good upload goes through
    assert verified_upload(ctl, small_table(), lambda e: None).active_crc32 == small_table().crc32()


def test_refused_activation_leaves_the_previous_table_alone():
    # the controller refused: its active table did not change, so a roll back would wrongly
    # activate the table before it
    ctl = FakeController(activate_error=TableError("refused"), activate_takes_effect=False)
    with pytest.raises(TableError):
        verified_upload(ctl, small_table(), lambda e: None)
    assert "rollback" not in ctl.calls
    assert ctl.active.same_as(small_table(0.5))


def test_upload_verified_against_the_simulated_controller():
    robot = load_robot("sr800")
    identified = robot.nominal + np.where(robot.is_angle(), 1e-4, 0.02)
    pytest.importorskip("pymodbus")
    from drivers.controller import ModbusController
    from simulators.controller_server import SimulatedController

    t = build_correction_table(robot, identified, GridSpec(), n_check=100)
    sim = SimulatedController(time_scale=0.0).start()
    try:
        ctl = ModbusController("127.0.0.1", sim.port, heartbeat_period=0.05)
        ctl.connect()
        try:
            rep = verified_upload(ctl, t.data, lambda e: None)
            assert ctl.table_crcs()["active"] == t.data.crc32() == rep.crc32
            assert ctl.read_table().same_as(t.data)
        finally:
            ctl.close()
    finally:
        sim.stop()
