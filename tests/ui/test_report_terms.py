"""The report of a SCARA run that kept error terms (issue 30): its correction table — the grid of
the accuracy map and the CRC-32 the report shows — is rebuilt as the run built it, from the stored
error model (the geometry fitted with the terms and their joint error δ), not from the geometric
identification."""

from __future__ import annotations

import numpy as np

from station.cell.correction.design import grid_to_json, region_for
from station.cell.pipeline.results import build_table_for
from station.cell.pipeline.terms import error_model_record
from station.cell.records.rundb import RunDB
from station.ui.report.run import _rebuilt_table
from tests.cell.scara_terms import scara_terms


def test_the_report_rebuilds_the_table_a_run_with_terms_uploaded(tmp_path):
    s = scara_terms()
    cfg = s.cfg
    grid = region_for(cfg).grid((7, 7, 2, 12))
    p_terms = np.asarray(s.sel.fit.params, dtype=float)
    uploaded = build_table_for(cfg, p_terms, grid, s.delta).data.crc32()  # what the pipeline built and uploaded
    geometric = build_table_for(cfg, s.geo.params, grid).data.crc32()
    assert uploaded != geometric
    with RunDB(tmp_path / "runs.sqlite") as db:
        def run(error_terms: bool, error_model: bool) -> int:
            rid = db.create_run(cfg.source_text, [st.to_record() for st in s.steps], seed=1)
            db.save_result(rid, "correction_grid", {**grid_to_json(grid), "error_terms": error_terms})
            if error_model:
                db.save_result(rid, "error_model", error_model_record(cfg, s.sel))
            return rid

        notes: list[str] = []
        assert _rebuilt_table(cfg, db, run(True, True), s.geo, notes).data.crc32() == uploaded and not notes
        # a table without terms (a geometric session, or a station before them) is the geometric fit's
        assert _rebuilt_table(cfg, db, run(False, True), s.geo, notes).data.crc32() == geometric and not notes
        # its error model lost: rebuilt geometric, and the report says why its CRC-32 differs
        assert _rebuilt_table(cfg, db, run(True, False), s.geo, notes).data.crc32() == geometric
        assert notes and "no error model" in notes[0]


def test_the_report_of_a_run_with_terms_shows_the_uploaded_tables_crc(tmp_path):
    """The whole report of such a run (its identification poses stored as measured): the table it
    shows — CRC-32 and the grid of the accuracy map — is the one built with the terms."""
    from station.cell.plan.steps import StepKind
    from station.core.kinematics.transforms import invert
    from station.ui.report.run import report_data_for_run

    s = scara_terms()
    cfg = s.cfg
    grid = region_for(cfg).grid((7, 7, 2, 12))
    uploaded = build_table_for(cfg, np.asarray(s.sel.fit.params, dtype=float), grid, s.delta).data.crc32()
    with RunDB(tmp_path / "runs.sqlite") as db:
        rid = db.create_run(cfg.source_text, [st.to_record() for st in s.steps], seed=1)
        ident = [(i, st) for i, st in enumerate(s.steps) if st.kind is StepKind.IDENTIFICATION]
        for (i, st), T in zip(ident, s.measured):
            db.record_measurement(rid, i, kind=st.kind.value, joints_commanded=st.q, joints_read=st.q,
                                  pose=invert(T) @ cfg.body_points[st.point], point_id=st.point_id)
        db.save_result(rid, "correction_grid", {**grid_to_json(grid), "error_terms": True})
        db.save_result(rid, "error_model", error_model_record(cfg, s.sel))
        d = report_data_for_run(db, rid)
    assert d.table_info is not None and d.table_info["crc32"] == f"{uploaded:08x}", d.notes
    assert "correction table's grid" in d.accuracy_where and len(d.accuracy_xy_mm) > 0
