"""The TUI shows the next move's clearance (issue 40): the plan's collision check finds, per planned
step, the least clearance of its moves and the pair that sets it; the run carries it as a
:class:`NextMove` event when the step starts, and the TUI shows that line, computing nothing."""

from __future__ import annotations

import dataclasses
import threading
from pathlib import Path

import pytest
from test_tui_features import paused_after, wait_until

from station.cell.config.cell_config import load_config
from station.cell.plan.measurement_plan import build_plan
from station.cell.plan.run_path import check_plan
from station.cell.run.facts.events import PhaseChanged, RunStarted, StepStarted
from station.cell.run.facts.next_move import NextMove, next_moves
from station.errors import RunAborted
from station.ui.tui.app import StationApp

pytest.importorskip("fcl")

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


@pytest.fixture(scope="module")
def puma():
    """The PUMA 560 example (its head passes within twice the margin of the cubes on some moves, a
    SCARA's quill keeps every pair farther): its plan, the steps checked, the report."""
    cfg = load_config(EXAMPLES / "puma560" / "cell.toml")
    plan = build_plan(cfg)
    steps = plan.run_steps(cfg.plan.verification_cycles, False)
    return cfg, steps, check_plan(cfg, plan)


def test_each_step_carries_the_least_clearance_of_its_moves(puma):
    cfg, steps, report = puma
    moves = next_moves(report, steps, steps)
    assert set(moves) == {st.index for st in steps}  # every step the check saw has its line
    near = [m for m in moves.values() if m.clearance_mm is not None]
    assert near, "the head comes within twice the margin of the cubes on some moves"
    # the plan's least clearance is the least of its steps' (every pose belongs to a step)
    least = min(near, key=lambda m: m.clearance_mm)
    assert report.closest is not None
    assert least.clearance_mm == pytest.approx(report.closest.clearance_mm)
    assert {least.a, least.b} == {report.closest.a, report.closest.b}
    # each figure within the watch distance and over the margin (the plan is clear)
    assert all(cfg.plan.collision_margin_mm <= m.clearance_mm < m.watch_mm for m in near)
    assert all(m.watch_mm == 2 * cfg.plan.collision_margin_mm for m in moves.values())
    far = [m for m in moves.values() if m.clearance_mm is None]
    assert all(m.text() == f"next move: clearance over {m.watch_mm:g} mm" for m in far)
    assert least.text() == f"next move: clearance {least.clearance_mm:.1f} mm ({least.a} ↔ {least.b})"


def test_a_step_the_check_did_not_see_gets_no_line(puma):
    """A resumed run whose stored plan differs (other joints) or a step outside the checked plan
    (a simulated run's reference steps): no event, rather than another step's figure."""
    _cfg, steps, report = puma
    moved = [dataclasses.replace(st, joints=tuple(v + 0.01 for v in st.joints)) if st.index == 0 else st
             for st in steps]
    extra = dataclasses.replace(steps[-1], index=len(steps))
    moves = next_moves(report, steps, [*moved, extra])
    assert 0 not in moves and len(steps) not in moves and 1 in moves
    assert next_moves(None, steps, steps) == {}


class _Session:
    """Plays the events of a run's first steps, each with its NextMove where the run has one."""

    def __init__(self, steps, moves):
        self.steps, self.moves = steps, moves
        self.gate = threading.Semaphore(0)

    def __call__(self, emit, control, confirm=None, resume=None):
        emit(PhaseChanged("connect", "simulated cell"))
        emit(RunStarted(run_id=3, n_steps=len(self.steps)))
        emit(PhaseChanged("measure", "identification poses"))
        for st in self.steps:
            assert self.gate.acquire(timeout=10), "test never opened the gate"
            control.checkpoint(timeout=10, emit=emit, index=st.index)
            emit(StepStarted(st.index, len(self.steps), f"identification: {st.label}"))
            if st.index in self.moves:
                emit(self.moves[st.index])
        self.gate.acquire(timeout=10)
        raise RunAborted("test over")


async def test_the_tui_shows_the_clearance_the_step_carries(puma):
    _cfg, steps, report = puma
    moves = next_moves(report, steps, steps)
    near = next(k for k, m in moves.items() if m.clearance_mm is not None)
    far = next((k for k, m in moves.items() if m.clearance_mm is None), None)
    shown = [st for st in steps if st.index in (near, far)]
    unchecked = dataclasses.replace(steps[0], index=len(steps))  # no event for it
    session = _Session([*shown, unchecked], moves)
    app = StationApp(session, title="next move", clock=lambda: 0.0)
    async with app.run_test(size=(100, 30)) as pilot:
        line = app.query_one("#next-move")
        assert not line.display  # no run, no line
        await pilot.press("s")
        for st in shown:
            session.gate.release()
            await wait_until(pilot, lambda st=st: app.step_index == st.index and line.display, f"step {st.index}")
            m = moves[st.index]
            assert str(line.render()) == m.text()
            if m.clearance_mm is not None:
                assert f"{m.clearance_mm:.1f} mm" in str(line.render()) and m.a in str(line.render())
        session.gate.release()
        await wait_until(pilot, lambda: app.step_index == len(steps), "the unchecked step")
        await pilot.pause()
        assert not line.display  # the earlier step's figure is not left standing
        session.gate.release()
        await wait_until(pilot, lambda: not app.running, "the run's end")


def test_next_move_event_is_frozen_and_plain():
    m = NextMove(4, 7.26, "link A2", "obstacle 'column'", 4.0, 2.0)
    assert m.text() == "next move: clearance 7.3 mm (link A2 ↔ obstacle 'column')"
    with pytest.raises(AttributeError):
        m.index = 5  # type: ignore[misc]


def test_snapshot_running_with_the_next_moves_clearance(snap_compare):
    """80×24 while a run streams the next move's clearance: its own line under the step's."""
    pytest.importorskip("pytest_textual_snapshot")
    from test_tui_features import RUNS, FakeSession, frozen, report_data
    from test_tui_snapshots import SIZE, at_rest, released_at_exit

    class WithClearance(FakeSession):
        def __call__(self, emit, control, confirm=None, resume=None):
            def emit_with_clearance(ev):
                emit(ev)
                if isinstance(ev, StepStarted):  # as the runner streams it: after the step's start
                    emit(NextMove(ev.index, 12.3 + ev.index, "link A2", "obstacle 'column'", 4.0, 2.0))
            return super().__call__(emit_with_clearance, control, confirm, resume)

    session = WithClearance()

    async def before(pilot):
        await paused_after(pilot, session, 3)
        await at_rest(pilot)

    app = released_at_exit(StationApp(session, title="SR 800 — snapshot", clock=frozen, list_runs=lambda: RUNS,
                                      load_results=lambda run_id: report_data(), db_label="runs.sqlite"))
    assert snap_compare(app, terminal_size=SIZE, run_before=before)
