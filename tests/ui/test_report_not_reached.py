"""The report of a run that did not reach a step shows no figures of that step (issue 36, §4).

An ABORTED run with enough identification measurements on disk was identified again by the report,
which printed parameters, residuals, predicted accuracy and a correction table under a progress line
that said identification and correction were "Not reached"."""

from __future__ import annotations

import pytest

from station.cell.pipeline.calibration import run_calibration
from station.cell.run.facts.events import MeasurementRecorded
from station.cell.run.runcontrol import RunAborted, RunControl
from station.ui.report.render.markdown_page import render_markdown
from station.ui.report.run import report_data_for_run
from tests.cell.test_pipeline import Cell


@pytest.fixture
def cell(tmp_path):
    c = Cell(tmp_path)
    yield c
    c.close()


def test_an_aborted_run_shows_no_identification_it_did_not_reach(cell):
    control = RunControl()

    def emit(e):
        if isinstance(e, MeasurementRecorded) and e.index == 11:
            control.abort()  # 12 identification measurements on disk: enough to identify from

    with pytest.raises(RunAborted):
        run_calibration(cell.cfg, cell.probe, cell.ctrl, cell.db, emit, control)
    run = cell.db.latest_run()
    valid = [r for r in cell.db.measurements(run.id) if r.ok and r.pose is not None]
    assert len(valid) >= 5  # the report could have recomputed an identification from them
    d = report_data_for_run(cell.db, run.id)
    assert len(d.param_names) == 0 and d.residuals.size == 0 and d.accuracy_xy_mm.size == 0
    assert d.table_info is None
    assert any("none are recomputed from the measurements it took" in n for n in d.notes)
    md = render_markdown(d)
    assert "Not reached: the identification" in md and "none are recomputed" in md
