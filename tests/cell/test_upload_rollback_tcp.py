"""The roll-back policy of the verified upload over TCP (issue 33, part 7): the simulated
controller fails an activation, refused or after it took effect, and then a roll back too; the
station's driver and ``verified_upload`` decide from the controller's CRC registers alone, and the
controller's slots say afterwards whether they decided right."""

from __future__ import annotations

import math

import numpy as np
import pytest

from drivers.controller import ModbusController
from drivers.controller_errors import CommandRejected
from drivers.controller_map import ErrorCode
from simulators.controller_server import SimulatedController
from station.cell.correction.upload import verified_upload
from station.cell.run.facts.events import Notice
from station.core.table.values import CorrectionTableData, TableAxis


def table(v: float) -> CorrectionTableData:
    axes = (TableAxis(0.0, 10.0, 3), TableAxis(-math.pi, math.pi / 2, 4, periodic=True))
    vals = np.full((2, 3, 4, 4), v, dtype=np.float32)
    vals[1] *= -1
    return CorrectionTableData(axes, vals)


@pytest.fixture
def cell():
    """A simulated controller already holding table A (the operator's), and a connected station."""
    sim = SimulatedController(time_scale=0.0).start()
    ctl = ModbusController("127.0.0.1", sim.port, heartbeat_period=0.05)
    ctl.connect()
    a = table(0.001)
    verified_upload(ctl, a, lambda e: None)
    assert ctl.table_crcs()["active"] == a.crc32()
    try:
        yield sim, ctl, a
    finally:
        ctl.close()
        sim.stop()


def _warnings(events) -> list[str]:
    return [e.message for e in events if isinstance(e, Notice) and e.level == "warning"]


def test_a_refused_activation_leaves_the_operators_table_active_and_rolls_nothing_back(cell):
    sim, ctl, a = cell
    b, events = table(0.002), []
    sim.fail_next_table_switch("TABLE_ACTIVATE", ErrorCode.DRIVE_FAULT, takes_effect=False)
    with pytest.raises(CommandRejected) as ei:
        verified_upload(ctl, b, events.append)
    assert "no roll back needed" in " ".join(ei.value.__notes__)
    crcs = ctl.table_crcs()
    assert crcs["active"] == a.crc32() and crcs["staged"] == b.crc32()  # B staged, never active
    assert not any("rolling back" in w for w in _warnings(events))


def test_an_activation_that_took_effect_and_failed_is_rolled_back_to_the_operators_table(cell):
    sim, ctl, a = cell
    b, events = table(0.002), []
    sim.fail_next_table_switch("TABLE_ACTIVATE", ErrorCode.DRIVE_FAULT, takes_effect=True)
    with pytest.raises(CommandRejected) as ei:
        verified_upload(ctl, b, events.append)
    assert "rolled back to the previous table" in " ".join(ei.value.__notes__)
    crcs = ctl.table_crcs()
    assert crcs["active"] == a.crc32()  # the operator's table again, read from the controller
    active = ctl.read_slot_table("active")  # the values themselves, read from the active slot
    assert active is not None and active.same_as(a)
    assert any("rolling back" in w for w in _warnings(events))


def test_a_roll_back_that_fails_too_says_so_and_leaves_the_unverified_table_named(cell):
    sim, ctl, a = cell
    b, events = table(0.002), []
    sim.fail_next_table_switch("TABLE_ACTIVATE", ErrorCode.DRIVE_FAULT, takes_effect=True)
    sim.fail_next_table_switch("TABLE_ROLLBACK", ErrorCode.DRIVE_FAULT, takes_effect=False)
    with pytest.raises(CommandRejected) as ei:
        verified_upload(ctl, b, events.append)
    note = " ".join(ei.value.__notes__)
    assert "roll back failed too" in note and "deactivate the table on the controller before moving" in note
    # the controller really holds B active: the note's warning is the truth, not a guess
    crcs = ctl.table_crcs()
    assert crcs["active"] == b.crc32() and crcs["previous"] == a.crc32()
    assert any("roll back failed too" in w for w in _warnings(events))
