"""One number per fact (issue 36, §4): the table's interpolation bound the operator is asked to
upload is the run's stored bound, which the JSON, the report and the fleet's publication read.

It was not: the upload dialog showed the whole table's bound (every reachable cell, 5.6 µm) where
the run judged, stored and reported the bound over the working cells (4.7 µm)."""

from __future__ import annotations

from station.cell.pipeline.calibration import Options, run_calibration
from station.cell.publication.payload import build_publication
from station.cell.run.questions import UploadProposal
from station.errors import Outcome
from station.ui.report.run import report_for_run
from station.ui.report.tables import fmt
from station.ui.tui.screens import question_markup


def test_the_upload_dialog_the_json_the_report_and_the_fleet_read_one_bound(cell, tmp_path):
    asked: list[UploadProposal] = []

    def confirm(question):
        if isinstance(question, UploadProposal):
            asked.append(question)
        return True

    summary = run_calibration(cell.cfg, cell.probe, cell.ctrl, cell.db, cell.events.append,
                              options=Options(confirm=confirm))
    assert summary.outcome is Outcome.SUCCESS and len(asked) == 1
    stored = cell.db.load_result(summary.run_id, "summary")["correction"]["interpolation_bound_um"]
    assert asked[0].interpolation_bound_um == stored == summary.correction.interpolation_bound_um
    _, body, _ = question_markup(asked[0])
    assert f"interpolation bound  {stored:.1f} µm" in body
    pub = build_publication(cell.db, summary.run_id, cell.cfg, "uuid", "2026-01-01T00:00:00Z")
    assert pub["detail"]["summary"]["correction"]["interpolation_bound_um"] == stored
    report_for_run(tmp_path / "runs.sqlite", summary.run_id, tmp_path / "report")
    md = (tmp_path / "report" / "report.md").read_text(encoding="utf-8")
    assert f"interpolation bound | {fmt(stored)} µm" in md
