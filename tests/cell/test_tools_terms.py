"""Tools after the head with error terms beyond geometry (issue 30, docs/error-terms.md "Tools"):
a tool's correction carries the terms the run kept — the joints' errors are the robot's, whatever
tool it carries — its simulated figures put the true robot at ``q + δ_true(q)``, and ``station
export --tool`` rebuilds the table from the run's stored error model."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from simulators.judge import CellJudge
from station.cell.config.cell_config import parse_text
from station.cell.config.template import TEMPLATE
from station.cell.correction.design import region_for
from station.cell.correction.robot_tools import evaluate_tool, result_key
from station.cell.correction.tool_export import tool_export
from station.cell.pipeline.calibration import reference_params
from station.cell.pipeline.results import build_table_for
from station.cell.pipeline.terms import error_model_record
from station.cell.records.rundb import RunDB
from station.core.kinematics.forward import forward
from station.core.kinematics.tool_frame import tool_params
from station.core.kinematics.transforms import pose_to_matrix
from station.errors import ConfigError
from tests.cell.scara_terms import scara_terms
from tests.cell.test_tools import GRIPPER, _six_axis, _steps, _with_tools


def test_a_scara_tools_table_with_the_terms_puts_the_true_robot_closer_than_the_geometric_one():
    """The gripper's table built with the terms ``auto`` keeps, on the geometry fitted with them,
    against the geometric table of the same data: the true robot (its gears err once per turn,
    scatter left out so that the figures compare the models) stands closer to the tool's targets,
    near the oracle's, which knows the true joint errors."""
    s = scara_terms()
    cfg, tool = s.cfg, s.cfg.tools[0]
    still = dataclasses.replace(s.truth, repeatability=np.zeros_like(s.truth.repeatability))
    p_true, p_terms = reference_params(cfg, s.truth), np.asarray(s.sel.fit.params, dtype=float)
    head = build_table_for(cfg, p_terms, region_for(cfg).grid((7, 7, 2, 12)), s.delta)  # the head's, with the terms
    terms = evaluate_tool(cfg, tool, p_terms, s.steps, head, p_ref=p_true, judge=CellJudge(still), delta=s.delta)
    geo = evaluate_tool(cfg, tool, s.geo.params, s.steps, None, p_ref=p_true, judge=CellJudge(still))
    assert terms.correction.table is not None and terms.correction.table.with_terms and terms.correction.with_terms
    assert geo.correction.table is not None and not geo.correction.with_terms
    assert terms.result()["error_terms"] is True and geo.result()["error_terms"] is False
    t, g = terms.summary(), geo.summary()
    assert t.n_after == t.n_targets == g.n_after and t.n_targets >= 8
    assert t.after_rms_um is not None and g.after_rms_um is not None and t.oracle_rms_um is not None
    assert t.after_rms_um < 0.3 * g.after_rms_um, (t.after_rms_um, g.after_rms_um)  # seed 1: 2.9 against 17.3 µm
    # the oracle's table carries the true joint errors: it leaves the interpolation, not the gears
    assert t.oracle_rms_um < 0.3 * g.after_rms_um and t.after_rms_um < 2.0 * t.oracle_rms_um
    # the head's table (rebuilt on the tool's grid with its terms) as the identified model predicts
    # it for this tool, and as the true robot with its joint errors shows it
    assert t.head_rms_um is not None and t.head_predicted_rms_um == pytest.approx(t.head_rms_um, rel=0.05)


class _BendingJudge:
    """A simulated cell's judge as the tools read it (station.cell.records.judge.RunJudge): joints
    that stand at ``q + δ(q)``, no scatter."""

    seed = 0

    def __init__(self, g: int) -> None:
        self.repeatability = np.zeros(g)

    @staticmethod
    def joint_delta(q: np.ndarray) -> np.ndarray:
        return 2e-4 * np.sin(q) + 1e-4 * np.cos(2.0 * q)  # rad: about 40″ and 20″

    def reference_delta(self):
        return self.joint_delta


def test_other_robots_tool_targets_are_compensated_with_the_terms():
    """A six-axis arm identified exactly, its joints erring by δ(q): the tool's targets compensated
    with δ put the true tool on them, the geometric ones miss by what δ moves it."""
    base = parse_text(_with_tools(TEMPLATE, GRIPPER.replace("-200.0", "150.0")))
    model = _six_axis()
    cfg = dataclasses.replace(base, model=model, head_in_flange=None)
    rng = np.random.default_rng(7)
    p = np.array(model.nominal)
    p[6:] += rng.normal(0.0, 1.0, model.n_params - 6) * np.tile([0.05, 0.05, 0.05, 5e-4, 5e-4, 5e-4], 7)
    joints = np.radians([[10, 20, -30, 40, 50, 60], [-20, 40, -10, -30, 40, 10], [30, 10, -50, 10, -60, -40]])
    steps = _steps(cfg, joints, [1, 1, 1])
    judge = _BendingJudge(model.n_joints)
    with_terms = evaluate_tool(cfg, cfg.tools[0], p, steps, None, p_ref=p, judge=judge, delta=judge.joint_delta)
    geometric = evaluate_tool(cfg, cfg.tools[0], p, steps, None, p_ref=p, judge=judge)
    for ev in (with_terms, geometric):
        assert ev.own_um is not None and ev.oracle_um is not None and ev.head_um is not None
        assert float(np.max(ev.oracle_um)) < 1e-3  # the oracle knows the joint errors
    assert float(np.max(with_terms.own_um)) < 1e-3 and float(np.max(with_terms.head_um)) < 1e-3
    assert float(np.min(geometric.own_um)) > 20.0  # µm: what δ moves the tool
    # the predicted head figure is the identified model's with its terms: here the truth itself
    np.testing.assert_allclose(with_terms.head_predicted_um, 0.0, atol=1e-3)
    corr = with_terms.correction
    assert corr.with_terms and corr.commanded_joints is not None and corr.commands is not None
    # the commands are the nominal tool's poses at the commanded joints; the true tool, standing at
    # q + δ(q) there, is on its target
    np.testing.assert_allclose(forward(corr.kin.nominal, corr.commanded_joints, setup=False), corr.commands, atol=1e-9)
    q = corr.commanded_joints
    true_tool = tool_params(model, p, pose_to_matrix(model.nominal[-6:]), cfg.tools[0].tcp_matrix)
    reached = forward(model, q + judge.joint_delta(q), true_tool, setup=False)
    np.testing.assert_allclose(reached[:, :3, 3], corr.targets.base[:, :3, 3], atol=1e-6)


def _run_with(db: RunDB, error_model: dict | None, tool_result: dict, ident: np.ndarray) -> int:
    s = scara_terms()
    run_id = db.create_run(s.cfg.source_text, [st.to_record() for st in s.steps], seed=1)
    db.save_result(run_id, "identification", {"params": [float(v) for v in ident]})
    if error_model is not None:
        db.save_result(run_id, "error_model", error_model)
    db.save_result(run_id, result_key("gripper"), tool_result)
    return run_id


def test_export_rebuilds_a_tools_table_with_the_runs_stored_error_model(tmp_path):
    """``station export --tool`` of a run that kept terms: the table rebuilt from the stored error
    model (its geometry and δ) has the CRC-32 the run stored; the same run without its error model
    would rebuild the geometric table, which the CRC check refuses."""
    s = scara_terms()
    cfg, tool = s.cfg, s.cfg.tools[0]
    p_terms = np.asarray(s.sel.fit.params, dtype=float)
    stored = evaluate_tool(cfg, tool, p_terms, s.steps, None, delta=s.delta).result()  # as run_tools stores it
    assert stored["error_terms"] is True
    record = error_model_record(cfg, s.sel)
    with RunDB(tmp_path / "runs.sqlite") as db:
        run_id = _run_with(db, record, stored, s.geo.params)
        out = tool_export(db, run_id, "gripper", force=True)  # its bound is beyond 15 µm: --force
        assert out["table"]["crc32"] == stored["summary"]["crc32"] and out["error_terms"] == list(s.sel.chosen)
        assert "warning" in out
        lost = _run_with(db, None, stored, s.geo.params)  # its error model lost: a geometric rebuild
        with pytest.raises(ConfigError, match="CRC-32"):
            tool_export(db, lost, "gripper", force=True)
