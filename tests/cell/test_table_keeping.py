"""The table the operator chose, at every step (issue 17, part 4): a run that is declined,
aborted, fails or is not uploaded ends with exactly the table that was active when it started,
confirmed by its CRC-32; a kept correction leaves the operator's table in the roll-back slot."""

from __future__ import annotations

from contextlib import ExitStack

import numpy as np
import pytest

from simulators import start_simulated_cell
from simulators.judge import CellJudge
from simulators.reference_cell import cell_config_text
from station.cell.config.cell_config import parse_text
from station.cell.correction.table_keeping import RESULT_KEY
from station.cell.pipeline.calibration import Options, run_calibration
from station.cell.records.rundb import RunDB
from station.cell.run.facts.events import MeasurementRecorded, PhaseChanged
from station.cell.run.questions import UploadProposal
from station.cell.session.calibrate import open_cell
from station.core.table.values import CorrectionTableData, TableAxis
from station.errors import Outcome, RunAborted

#: a short run: one cycle of verification, no repeated identification poses
SHORT = {"repeats = 4": "repeats = 1\nselect = 40", "verification_cycles = 5": "verification_cycles = 1"}


class Cell:
    def __init__(self, tmp_path):
        self.stack = ExitStack()
        self.srv = start_simulated_cell(seed=2)
        self.stack.callback(self.srv.stop)
        text = cell_config_text(self.srv, 2)
        for old, new in SHORT.items():
            text = text.replace(old, new)
        self.cfg = parse_text(text)
        self.db = self.stack.enter_context(RunDB(tmp_path / "runs.sqlite"))
        devices = open_cell(self.cfg, self.stack)
        self.ctrl = devices.controller
        self.probe = devices.probe

    def activate(self, scale: float) -> int:
        """Upload, verify, stage and activate a small table (the operator's table A)."""
        g = self.cfg.model.n_joints
        t = CorrectionTableData((TableAxis(-1000.0, 500.0, 5),), np.full((2, 5, g), scale))
        self.ctrl.upload_table(t)
        self.ctrl.verify_table()
        self.ctrl.stage_table()
        self.ctrl.activate_table()
        return t.crc32()

    def run(self, **kw):
        return run_calibration(self.cfg, self.probe, self.ctrl, self.db, lambda e: None, **kw)

    def crcs(self):
        return self.ctrl.table_crcs()


@pytest.fixture
def cell(tmp_path):
    c = Cell(tmp_path)
    yield c
    c.stack.close()


def test_declining_the_new_table_brings_the_operators_table_back(cell):
    a = cell.activate(1e-6)
    summary = cell.run(options=Options(confirm=lambda q: isinstance(q, UploadProposal)))  # upload yes, keep no
    assert summary.outcome is Outcome.NOT_UPLOADED and summary.upload is not None
    assert cell.crcs()["active"] == a
    assert summary.tables.active_at_start == summary.tables.active_at_end == f"{a:08x}"
    assert summary.tables.restored
    # the run's record holds the operator's table itself, read back from the active slot
    rec = cell.db.load_result(summary.run_id, RESULT_KEY)
    assert rec["active_crc32"] == f"{a:08x}" and rec["values"]


def test_declining_the_upload_and_no_upload_keep_the_operators_table(cell):
    a = cell.activate(2e-6)
    summary = cell.run(options=Options(confirm=lambda q: False))
    assert summary.outcome is Outcome.NOT_UPLOADED and cell.crcs()["active"] == a
    summary = cell.run(options=Options(upload=False))  # 'before' runs with the table deactivated
    assert summary.outcome is Outcome.NOT_UPLOADED and cell.crcs()["active"] == a
    assert summary.tables.restored


def test_a_kept_table_leaves_the_operators_one_for_a_roll_back_and_the_oracles_nowhere(cell):
    a = cell.activate(1e-6)
    summary = cell.run(options=Options(judge=CellJudge(cell.srv.cell.truth)))
    assert summary.outcome is Outcome.SUCCESS
    crcs = cell.crcs()
    assert crcs["active"] == int(summary.correction.crc32, 16)
    assert crcs["previous"] == 0  # never the oracle's table: a roll back cannot revive it
    assert summary.tables.active_at_start == f"{a:08x}" and not summary.tables.restored

    no_oracle = cell.run()  # a real cell's run: the table it replaced waits in the roll-back slot
    assert no_oracle.outcome is Outcome.SUCCESS
    assert cell.crcs()["previous"] == int(summary.correction.crc32, 16)


def test_an_abort_after_activation_restores_the_operators_table(cell):
    a = cell.activate(3e-6)
    seen = {"after": False, "n": 0}

    def emit(event):
        if isinstance(event, PhaseChanged) and event.detail.startswith("after correction"):
            seen["after"] = True
        if seen["after"] and isinstance(event, MeasurementRecorded):
            seen["n"] += 1
            if seen["n"] == 2:  # the new table is active and measured
                raise RunAborted("operator abort during 'verify after'")

    with pytest.raises(RunAborted) as err:
        run_calibration(cell.cfg, cell.probe, cell.ctrl, cell.db, emit)
    assert cell.crcs()["active"] == a
    assert any("is active again" in n for n in getattr(err.value, "__notes__", ()))
