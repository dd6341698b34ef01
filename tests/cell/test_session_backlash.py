"""Backlash in a cell session (issue 30: "backlash or lost motion, where the data says it; the
cell's plan can approach a point from both sides when the model asks for it"): the rows
``select_terms`` fits carry the measurement time and the side every joint arrived from, derived
from the plan's commanded moves; with ``[plan] both_directions = true`` ``auto`` keeps the
simulated SCARA's backlash at its true width, without it backlash is no candidate, and a model
that names backlash without both directions is refused before motion.

The identification steps are measured in-process (the runner's procedure on the simulated cell's
physics, as ``tests/cell/test_recheck.py`` does), not in a full session."""

from __future__ import annotations

from datetime import datetime, timedelta, timezone
from types import SimpleNamespace

import numpy as np
import pytest

from simulators.cell import SimulatedCell
from station.cell.config.cell_config import parse_text
from station.cell.pipeline.results import identify_run, run_measurements, run_term_rows
from station.cell.pipeline.terms import select_terms
from station.cell.plan.measurement_plan import build_plan
from station.cell.plan.steps import StepKind
from station.cell.run.runner import ReadProbes, approach_and_read
from station.core.kinematics.forward import forward
from station.core.terms.error_model import TermRows, TermSpec, term_basis
from station.core.terms.selection import select_model
from station.errors import ConfigError
from tests.cell.test_recheck import InProcess, _sim_cfg

T0 = datetime(2026, 3, 2, 8, 0, 0, tzinfo=timezone.utc)
STEP_S = 7.25  # seconds between records (the stamps the rows' drift runs over)


def _cfg(model: str, both: bool):
    text = _sim_cfg(1).source_text
    text = text.replace("[identification]\n", f'[identification]\nmodel = "{model}"\n', 1)
    return parse_text(text.replace("[plan]\n", f"[plan]\nboth_directions = {'true' if both else 'false'}\n", 1))


class _Measured(InProcess):
    """The runner's procedure on the cell; each record as the run database holds it (kind, commanded
    joints, a UTC stamp) plus the side every joint really arrived from (the simulator's own
    record of its last move, at the probe reading)."""

    def _do(self, msg):
        if isinstance(msg, ReadProbes):
            self.sides = -self.cell.approach_direction
        return super()._do(msg)

    def records(self, steps):
        out = []
        for st in steps:
            r = self.execute(approach_and_read(self.cfg, st.q, st.direction, cycle=st.cycle))
            out.append(SimpleNamespace(
                step_index=st.index, kind=st.kind.value, point_id=st.point_id, label=st.label, ok=r.ok, pose=r.pose,
                joints_read=r.joints_read, joints_commanded=np.asarray(st.q, dtype=float), true_sides=self.sides,
                t_utc=(T0 + timedelta(seconds=STEP_S * st.index)).strftime("%Y-%m-%dT%H:%M:%S.%fZ")))
        return out


@pytest.fixture(scope="module")
def both_sides():
    """The built-in SCARA (seed 1; its truth has backlash) measured on every identification and
    reversal step of a plan with both directions."""
    cfg = _cfg("auto", True)
    cell = SimulatedCell(seed=1)
    recs = _Measured(cfg, cell).records(build_plan(cfg).identification)
    return cfg, cell.truth, recs


def test_the_rows_say_from_which_side_each_joint_arrived_and_when(both_sides):
    cfg, _, recs = both_sides
    assert {r.kind for r in recs} == {StepKind.IDENTIFICATION.value, StepKind.REVERSAL.value}
    recs = [*recs[:5], SimpleNamespace(**{**vars(recs[5]), "ok": False, "pose": None}), *recs[6:]]  # one invalid
    rows = run_term_rows(cfg, recs)
    kept = [r for r in recs if r.ok and r.pose is not None]
    assert rows.approach is not None and rows.approach.shape == (len(kept), 4)
    assert len(kept) == run_measurements(cfg, recs).n_items  # row for row with the data fitted
    # the sides derived from the plan's commanded moves are the ones the simulator's joints arrived from
    np.testing.assert_array_equal(rows.approach, np.array([r.true_sides for r in kept]))
    forward_rows = np.array([r.kind == StepKind.IDENTIFICATION.value for r in kept])
    # revolute joints: from below in direction +1, from above in the reversal; the quill always from above
    np.testing.assert_array_equal(rows.approach[forward_rows], np.tile([-1.0, -1.0, 1.0, -1.0], (forward_rows.sum(), 1)))
    np.testing.assert_array_equal(rows.approach[~forward_rows], np.ones(((~forward_rows).sum(), 4)))
    # drift runs over the seconds since the first record, not the row number (the invalid one leaves a gap)
    assert rows.order is not None
    np.testing.assert_allclose(rows.order, [STEP_S * (r.step_index - kept[0].step_index) for r in kept])


def test_auto_keeps_the_backlash_both_directions_show_at_its_true_width(both_sides):
    cfg, truth, recs = both_sides
    ident = [r for r in recs if r.kind == StepKind.IDENTIFICATION.value]
    reversal = [r for r in recs if r.kind == StepKind.REVERSAL.value]
    res = identify_run(cfg, ident)
    sel = select_terms(cfg, ident, res, reversal)
    assert sel is not None and "backlash" in sel.chosen, sel.summary
    values = dict(zip(sel.fit.basis.names, sel.fit.values))
    # the quill arrives from above in both directions: its lost motion merges with its zero (no term)
    assert "backlash.q3" not in values
    for j in (1, 2, 4):  # truth: 100 µm at a 450 mm lever, 2.22e-4 rad
        assert values[f"backlash.q{j}"] == pytest.approx(truth.backlash[j - 1], rel=0.05), (j, values)
    # the geometry it hands on carries the half lost motion of the station's own approach (direction
    # +1) in its joint zeros, as the oracle's does: read with backlash at zero, as the table and a
    # recheck read it, it puts the identification poses where they were measured
    data = run_measurements(cfg, ident)
    meas = data.measured[:, :3, 3]

    def rms_um(params) -> float:
        return float(np.sqrt(np.mean(np.sum((forward(cfg.model, data.joints, params)[:, :3, 3] - meas) ** 2, 1))) * 1e3)

    unfolded = select_model(cfg.model, run_measurements(cfg, ident + reversal),
                            rows=run_term_rows(cfg, ident + reversal), spec=TermSpec(),
                            geometric=identify_run(cfg, ident + reversal), force=sel.chosen).fit.params
    one_side = float(res.rms_position_mm() * 1e3)  # the geometric fit of the +1 side alone (seed 1: 9.7 µm)
    folded = rms_um(sel.fit.params)
    assert folded < 1.1 * one_side and rms_um(unfolded) > 4 * one_side, (folded, rms_um(unfolded), one_side)  # 87 µm


def test_without_both_directions_backlash_is_no_candidate(both_sides):
    cfg_both, _, recs = both_sides
    cfg = _cfg("auto", False)
    ident = [r for r in recs if r.kind == StepKind.IDENTIFICATION.value]  # the same poses, one side
    sel = select_terms(cfg, ident, identify_run(cfg, ident))
    assert sel is not None
    assert not any("backlash" in row.families for row in sel.table), [row.label for row in sel.table]
    assert "backlash" not in sel.chosen
    # a term set without backlash fits the identification records alone, reversal records or not
    cyc = _cfg("cyclic.q1", True)
    reversal = [r for r in recs if r.kind == StepKind.REVERSAL.value]
    one = select_terms(cyc, ident, identify_run(cyc, ident), reversal)
    assert one is not None and one.fit.residuals.shape[0] == len(ident)
    assert cfg_both.plan.both_directions and not cfg.plan.both_directions


def test_a_model_naming_backlash_needs_both_directions_before_motion():
    with pytest.raises(ConfigError, match=r"both_directions = true") as exc:
        _cfg("cyclic+backlash", False)
    assert exc.value.exit_code == 2 and "identification.model" in str(exc.value)
    assert _cfg("cyclic+backlash", True).identification.terms == ("cyclic", "backlash")
    assert _cfg("backlash", True).identification.terms == ("backlash",)
    assert _cfg("auto", False).identification.terms == ("auto",)  # auto only tries it where the data show it


def test_backlash_is_fitted_only_for_joints_that_arrived_from_both_sides():
    """The core: a joint whose approach sign never changes gets no backlash column (it merges with
    the joint's zero); backlash forced where no joint changes side is refused, not fitted as
    nothing."""
    from station.core.terms.selection import expand_families

    cfg = _cfg("auto", True)
    q = np.array([[0.1 * k, 0.5, -50.0, 0.2 * k] for k in range(6)])
    s = np.tile([-1.0, -1.0, 1.0, -1.0], (6, 1))
    s[::2, 1] = 1.0  # only joint 2 changes side
    b = term_basis(cfg.model, q, TermSpec(("backlash",)), TermRows(approach=s))
    assert b.names == ("backlash.q2",)
    assert expand_families(cfg.model, ("backlash",), TermRows(approach=s)) == ("backlash",)
    with pytest.raises(ConfigError, match="no joint arrived from both sides"):
        expand_families(cfg.model, ("backlash",), TermRows(approach=np.tile([-1.0, -1.0, 1.0, -1.0], (6, 1))))
