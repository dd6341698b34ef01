"""The verification path as the controller will move it (issue 40): with a table active, a SCARA's
Cartesian touch lands at its nominal joints plus the table's Δq, a path the pre-motion check never
saw. Once the table is designed and before it is active, the run checks the remaining verification
steps shifted by it (station/cell/plan/moved_path/shifted_check.py) and refuses a path that collides."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from simulators.judge import CellJudge
from station.cell.config.cell_config import parse_text
from station.cell.pipeline.calibration import Options
from station.cell.pipeline.outcomes import classify, hint_for
from station.cell.plan.measurement_plan import approach_pose, build_plan
from station.cell.plan.moved_path.shifted_check import ShiftedPathCollides, check_shifted, remeasures, shifted_path
from station.cell.plan.run_path import check_plan
from station.cell.plan.steps import StepKind
from station.cell.records.summary import RunSummary
from station.core.table.values import CorrectionTableData, TableAxis
from station.errors import Outcome

pytest.importorskip("fcl")

CELL = Path(__file__).resolve().parents[2] / "examples" / "scara600" / "cell.toml"

#: a 10 x 10 x 30 mm post beside the head's mount at the first verification touch after correction
#: (P1b elbow -1, plan step 171), 30 mm from the measuring point along the way a +0.3° table moves the
#: head there (3.45 mm): the nominal path clears it by 3.4 mm, over the 2 mm margin, the shifted by none
POST = """
[[obstacle]]
name = "post"
shape = "box"
frame = "body"
pose = [82.376, -222.614, 100.0, 0.0, 0.0, 0.0]
size_mm = [10.0, 10.0, 30.0]
"""


def _table(dq: np.ndarray) -> CorrectionTableData:
    """A table that adds ``dq`` (g,) everywhere in the SCARA's reach (one configuration)."""
    axes = (TableAxis(-1000.0, 500.0, 5),) * 3 + (TableAxis(-np.pi, np.pi / 4, 8, periodic=True),)
    return CorrectionTableData(axes, np.broadcast_to(dq, (1, 5, 5, 5, 8, dq.size)).copy())


@pytest.fixture(scope="module")
def post_cell():
    cfg = parse_text(CELL.read_text() + POST, str(CELL))
    plan = build_plan(cfg)
    steps = plan.run_steps(cfg.plan.verification_cycles, False)
    dq = np.array([np.radians(0.3) if k == "revolute" else 0.0 for k in cfg.model.joint_types])
    return cfg, plan, steps, dq


def test_a_table_that_pushes_a_verification_touch_into_an_obstacle_is_refused(post_cell):
    cfg, plan, steps, dq = post_cell
    R = cfg.model.nominal[:6]
    # the pre-motion check passes: the plan's path at its nominal joints clears the post over the margin
    pre = check_plan(cfg, plan)
    assert pre.clash is None and pre.closest is not None and "post" in pre.closest.b
    assert cfg.plan.collision_margin_mm < pre.closest.clearance_mm < cfg.plan.collision_margin_mm + 3.45
    # a table of zero correction: the verification path as planned, clear
    zero = check_shifted(cfg, steps, R, _table(0 * dq), {StepKind.VERIFY_AFTER})
    assert zero is not None and zero.clash is None
    assert zero.closest.clearance_mm == pytest.approx(pre.closest.clearance_mm, abs=0.05)
    # the touch is the nominal joints plus the table's Δq (the guard's rule), the pose above shifts with it
    first = next(st for st in steps if st.kind is StepKind.VERIFY_AFTER)
    nominal, shifted = shifted_path(cfg, [first], R, _table(0 * dq)), shifted_path(cfg, [first], R, _table(dq))
    # the seven-probe head re-measures once where its probes disagree ([plan] remeasure_attempts = 1): from
    # a wider approach (the runner's _touch), after the touch and its retract
    assert remeasures(cfg) == cfg.plan.remeasure_attempts == 1
    whats = ("approach", "above the point", "touch", "retract")
    assert [p[1] for p in shifted] == [f"step {first.index + 1} ({first.label}): {w}{again}"
                                       for again in ("", " (re-measure 1)") for w in whats]
    np.testing.assert_allclose(shifted[0][0], nominal[0][0])  # the approach is a joint move: no table
    for k in (1, 2, 3, 5, 6, 7):
        np.testing.assert_allclose(shifted[k][0] - nominal[k][0], dq, atol=1e-7)
    np.testing.assert_allclose(shifted[4][0], approach_pose(cfg, nominal[2][0], 1, first.cycle, 1))
    rev = dq != 0  # the revolute joints: the re-measure's approach offset is wider there
    assert np.abs(shifted[4][0] - nominal[2][0])[rev].max() > np.abs(shifted[0][0] - nominal[2][0])[rev].max()
    # +0.3°: refused before any of it moves, naming the step, the pair and the clearance, exit 2
    with pytest.raises(ShiftedPathCollides) as exc:
        check_shifted(cfg, steps, R, _table(dq), {StepKind.VERIFY_AFTER})
    msg = str(exc.value)
    assert f"step {first.index + 1} ({first.label})" in msg and "obstacle 'post'" in msg
    assert "under the margin of 2 mm" in msg or "overlapping" in msg
    assert classify(exc.value) is Outcome.CONFIG_ERROR and exc.value.exit_code == 2
    assert "collision_margin_mm" in hint_for(exc.value) and "post" not in hint_for(exc.value)
    # the same table on steps already measured (a resume past them) leaves nothing to check
    done = {st.index for st in steps if st.kind is StepKind.VERIFY_AFTER}
    assert check_shifted(cfg, steps, R, _table(dq), {StepKind.VERIFY_AFTER}, done) is None


def test_the_built_in_cell_records_its_shifted_clearance(tmp_path):
    from tests.cell.test_pipeline import SHORT, Cell

    cell = Cell(tmp_path, **SHORT)
    try:
        summary = cell.run(options=Options(judge=CellJudge(cell.srv.cell.truth)))
        n_after = len(cell.db.measurements(summary.run_id, kind=StepKind.VERIFY_AFTER.value))
        stored = cell.db.load_result(summary.run_id, "summary")
    finally:
        cell.close()
    assert summary.outcome is Outcome.SUCCESS
    checks = [c.check for c in summary.clearances]
    assert checks == ["pre-motion", "after (shifted)", "oracle (shifted)"]
    for c in summary.clearances[1:]:
        assert c.margin_mm == cell.cfg.plan.collision_margin_mm and c.poses >= 4
        assert c.least_mm is None or c.least_mm >= c.margin_mm
    assert n_after and summary.clearances[1].poses >= 4 * n_after  # approach, above, touch, retract each (and re-measures)
    js = summary.to_json()
    assert js["units"]["clearances"].startswith("mm") and js["clearances"][1]["check"] == checks[1]
    assert RunSummary.from_json(js).clearances == summary.clearances
    assert stored == js


def _refusing(kind: StepKind, monkeypatch):
    """The run's shifted check, refusing the steps of ``kind`` (the real check for the others)."""
    import station.cell.pipeline.shifted as shifted

    real = shifted.check_shifted

    def check(cfg, steps, R, table, kinds, done=(), what="", start=None):
        if kind in kinds:
            raise ShiftedPathCollides(f"with {what} active the verification path collides (test)", "a hint")
        return real(cfg, steps, R, table, kinds, done, what, start)

    monkeypatch.setattr(shifted, "check_shifted", check)


def test_a_refused_shifted_path_moves_none_of_it_and_leaves_no_table_active(tmp_path, monkeypatch):
    from tests.cell.test_pipeline import SHORT, Cell

    _refusing(StepKind.VERIFY_AFTER, monkeypatch)
    cell = Cell(tmp_path, **SHORT)
    try:
        with pytest.raises(ShiftedPathCollides):
            cell.run(options=Options(judge=CellJudge(cell.srv.cell.truth)))
        run = cell.db.latest_run()
        assert run is not None
        measured = {r.kind for r in cell.db.measurements(run.id)}
        # refused before any verification motion: not one step of the refused path, nothing uploaded
        assert not measured & {StepKind.VERIFY_AFTER.value, StepKind.VERIFY_BEFORE.value}
        assert not cell.ctrl.status().table_active
        assert cell.srv.controller_server.active_table is None
    finally:
        cell.close()


def test_a_refused_oracle_path_is_not_moved_and_the_stations_table_stays(tmp_path, monkeypatch):
    """The oracle is a simulated session's figure beside the result: where its shifted path is refused,
    its table is never uploaded, none of its steps moves, a warning says why, and the run ends on its
    own verification with its own table active (it ended CONFIG_ERROR before)."""
    from station.cell.run.facts.events import Notice
    from tests.cell.test_pipeline import SHORT, Cell

    _refusing(StepKind.REFERENCE, monkeypatch)
    cell = Cell(tmp_path, **SHORT)
    try:
        summary = cell.run(options=Options(judge=CellJudge(cell.srv.cell.truth)))
        assert summary.oracle is None and summary.after is not None and summary.upload is not None
        run = cell.db.latest_run()
        assert run is not None
        measured = {r.kind for r in cell.db.measurements(run.id)}
        assert StepKind.REFERENCE.value not in measured and StepKind.VERIFY_AFTER.value in measured
        assert any(isinstance(e, Notice) and e.level == "warning" and e.message.startswith(
            "oracle reference not measured") for e in cell.events)
        assert cell.ctrl.status().table_active
        assert f"{cell.ctrl.table_crcs()['active']:08x}" == summary.upload.crc32  # the station's own, read back
    finally:
        cell.close()


def test_around_a_column_the_shifted_path_takes_the_runners_vias():
    """scara600_column: direct moves between two verification steps pass through the column, so the
    check strings the vias the runner's Travel takes (travel_vias) and finds that path clear."""
    cfg = parse_text((CELL.parent.parent / "scara600_column" / "cell.toml").read_text(),
                     str(CELL.parent.parent / "scara600_column" / "cell.toml"))
    steps = build_plan(cfg).run_steps(cfg.plan.verification_cycles, False)
    dq = np.array([np.radians(0.3) if k == "revolute" else 0.0 for k in cfg.model.joint_types])
    after = [st for st in steps if st.kind is StepKind.VERIFY_AFTER]
    R = cfg.model.nominal[:6]
    direct = shifted_path(cfg, after, R, _table(dq), vias=False)
    assert len(direct) == 4 * len(after) * (remeasures(cfg) + 1)  # each touch and its re-measure
    report = check_shifted(cfg, steps, R, _table(dq), {StepKind.VERIFY_AFTER})
    assert report is not None and report.clash is None
    assert report.vias > 0 and report.poses == len(direct) + report.vias
    names = [p[1] for p in shifted_path(cfg, after, R, _table(dq))]
    assert any(n.endswith(("joint 1 first", "joint 2 first", "elbow to swing", "swung")) for n in names)


def test_the_next_move_line_shows_the_shifted_clearance_once_checked(post_cell):
    """The TUI's "next move" line (a NextMove event when the step starts): for the steps the shifted
    check saw, its figure, not the plan's, and the line says so."""
    from types import SimpleNamespace

    from station.cell.pipeline.shifted import checked_shifted
    from station.cell.run.facts.next_move import next_moves

    cfg, plan, steps, dq = post_cell
    R = cfg.model.nominal[:6]
    pre = check_plan(cfg, plan)
    runner = SimpleNamespace(next_moves=next_moves(pre, steps, steps))  # what run_calibration sets before motion
    first = next(st for st in steps if st.kind is StepKind.VERIFY_AFTER)
    planned = runner.next_moves[first.index]
    assert planned.check == "" and "post" in planned.b and planned.text().startswith("next move: clearance")
    notes = []
    summary = checked_shifted(cfg, steps, set(), R, _table(dq / 3), StepKind.VERIFY_AFTER, RunSummary(Outcome.SUCCESS),
                              notes.append, runner)  # +0.1°: clear, 1.2 mm closer to the post
    shown = runner.next_moves[first.index]
    assert shown.check == "after (shifted)" and "post" in shown.b
    assert shown.clearance_mm < planned.clearance_mm - 1.0
    assert shown.clearance_mm == pytest.approx(summary.clearances[-1].least_mm)  # the step nearest the post
    assert shown.text() == f"next move, with the correction: clearance {shown.clearance_mm:.1f} mm ({shown.a} ↔ {shown.b})"
    ident = next(st for st in steps if st.kind is StepKind.IDENTIFICATION)
    assert runner.next_moves[ident.index] == next_moves(pre, steps, steps)[ident.index]  # the others: the plan's
    assert {i for i, m in runner.next_moves.items() if m.check} == {
        st.index for st in steps if st.kind is StepKind.VERIFY_AFTER}
