"""The error terms beyond geometry in the cell's session (issue 30): ``[identification] model``,
checked before anything moves, and a simulated six-axis rehearsal whose arm bends under gravity
and errs once per turn (``[simulation] joint_errors = "six-axis"``), identified with ``auto``,
compensated with the full model and judged against an oracle that knows the joint errors too."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from station.cell.config.cell_config import TEMPLATE, parse_text
from station.cell.records.rundb import RunDB
from station.cell.records.summary import RunSummary
from station.cell.session.calibrate import CellRequest, run_calibration_session
from station.errors import ConfigError, Outcome
from station.ui.simulated_cell import load_cell

PUMA = Path(__file__).resolve().parents[2] / "examples" / "puma560"


def _puma(tmp_path: Path, joint_errors: str, model: str) -> str:
    """The example PUMA 560 cell with the given joint errors and error model."""
    d = tmp_path / f"{joint_errors}-{model}"
    shutil.copytree(PUMA, d)
    text = (d / "cell.toml").read_text(encoding="utf-8")
    text = text.replace("[identification]\n", f'[identification]\nmodel = "{model}"\n', 1)
    text = text.replace("[simulation]\n", f'[simulation]\njoint_errors = "{joint_errors}"\n', 1)
    (d / "cell.toml").write_text(text, encoding="utf-8")
    return str(d / "cell.toml")


def _session(config: str) -> RunSummary:
    db = str(Path(config).with_name("runs.sqlite"))
    return run_calibration_session(CellRequest(config=config, simulated=True, seed=1, db=db, time_scale=0.0),
                                   lambda e: None, load=load_cell)


def test_the_template_says_geometric_and_the_model_is_checked_before_motion():
    assert parse_text(TEMPLATE).identification.terms == ("geometric",)
    # the template's robot is a SCARA: its correction table holds the geometric model only
    with pytest.raises(ConfigError, match="SCARA's correction table") as exc:
        parse_text(TEMPLATE.replace('model = "geometric"', 'model = "auto"'))
    assert exc.value.exit_code == 2
    with pytest.raises(ConfigError, match="compliance, cyclic"):
        parse_text(TEMPLATE.replace('model = "geometric"', 'model = "complience"'))


def test_a_six_axis_model_names_real_joints(tmp_path):
    text = Path(_puma(tmp_path, "none", "compliance+cyclic.q3")).read_text(encoding="utf-8")
    src = str(tmp_path / "none-compliance+cyclic.q3" / "cell.toml")
    ident = parse_text(text, src).identification
    assert ident.terms == ("compliance", "cyclic.q3") and ident.gravity is None  # no [gravity]: lumped
    from station.cell.results.preview import describe, preview

    pv = preview(parse_text(text.replace("compliance+cyclic.q3", "auto"), src))
    assert pv.error_model == "auto" and pv.to_json()["error_model"] == "auto"
    assert any(line.strip().startswith("error model: auto") for line in describe(pv))
    with pytest.raises(ConfigError, match="unknown error term 'cyclic.q7'"):
        parse_text(text.replace("cyclic.q3", "cyclic.q7"), src)
    with pytest.raises(ConfigError, match='objective = "pose"'):
        parse_text(text.replace("[identification]\n", '[identification]\nobjective = "distance"\n'), src)


@pytest.mark.slow
def test_a_bending_arm_is_calibrated_with_the_terms_auto_keeps(tmp_path):
    """auto keeps terms on an arm with joint errors, ends within 0.7 … 1.2 of an oracle that knows
    them, and beats the geometric session of the same cell (whose after/oracle is now honest too)."""
    auto = _session(_puma(tmp_path, "six-axis", "auto"))
    geo = _session(_puma(tmp_path, "six-axis", "geometric"))
    for s in (auto, geo):
        assert s.outcome is Outcome.SUCCESS, s.failure
        assert s.after is not None and s.oracle is not None and s.before is not None
    assert auto.before.rms_um == pytest.approx(geo.before.rms_um)  # the same robot, the same set-up
    em = auto.error_model
    assert em is not None and "compliance" in em.chosen and em.terms
    assert em.cv_chosen_um < 0.8 * em.cv_geometric_um
    assert {t.unit for t in em.terms} >= {"rad"} and all(t.sigma > 0 for t in em.terms)
    assert auto.after_vs_oracle is not None and 0.7 <= auto.after_vs_oracle <= 1.2, auto.after_vs_oracle
    assert auto.after.rms_um < 0.8 * geo.after.rms_um, (auto.after.rms_um, geo.after.rms_um)
    # the geometric session against the same honest oracle: the terms it lacks show
    assert geo.error_model is None and geo.after_vs_oracle is not None and geo.after_vs_oracle > 1.3
    assert auto.oracle.rms_um == pytest.approx(geo.oracle.rms_um, rel=0.2)
    # stored with the run: the selection's table, the terms with units, and the --json object
    assert auto.run_id is not None and auto.db is not None
    with RunDB(auto.db) as rdb:
        rec = rdb.load_result(auto.run_id, "error_model")
        extra = rdb.load_result(auto.run_id, "articulated")
    assert rec["model"] == "auto" and rec["chosen"] == list(em.chosen) and rec["units"]["cv_rms_um"] == "µm"
    assert [t["name"] for t in rec["terms"]] == [t.name for t in em.terms]
    assert np.asarray(rec["params"]).shape == (48,)  # the geometry fitted with the terms: 8 transforms
    assert extra["method"] == "compensated targets with error terms"
    js = auto.to_json()
    assert js["error_model"]["terms"][0]["unit"] and "error terms" in js["units"]
    assert RunSummary.from_json(js).error_model == em
    assert any(n.startswith("error model ([identification] model = 'auto')") for n in auto.notes)


def test_auto_keeps_nothing_on_a_rigid_arm(tmp_path):
    s = _session(_puma(tmp_path, "none", "auto"))
    assert s.outcome is Outcome.SUCCESS, s.failure
    em = s.error_model
    assert em is not None and em.chosen == () and em.terms == () and "geometric fit" in em.summary
    assert s.after_vs_oracle is not None and 0.7 <= s.after_vs_oracle <= 1.2, s.after_vs_oracle
    assert s.run_id is not None and s.db is not None
    with RunDB(s.db) as rdb:
        assert rdb.load_result(s.run_id, "articulated")["method"] == "compensated targets"


def test_the_oracle_of_a_bending_arm_puts_the_true_robot_on_target():
    """The simulator's truth carries its joint errors; the oracle's targets compensated with them
    bring the true robot (geometry, half backlash and joint errors at the commanded joints) onto
    every verification target, where the geometric truth alone misses by the arm's bending."""
    from simulators.cell import SimulatedCell
    from simulators.joint_errors import six_axis_joint_errors
    from simulators.six_axis_cell import six_axis_body, six_axis_config_text, six_axis_truth
    from station.cell.plan.measurement_plan import build_plan, head_targets_world
    from station.cell.results.pipeline import articulated_targets, oracle_params
    from station.cell.results.pipeline_terms import truth_delta
    from station.core.kinematics import forward

    cell = SimulatedCell(truth=six_axis_truth(2), body=six_axis_body(2), seed=2, joint_errors=six_axis_joint_errors(2))

    class Servers:  # what the configuration's text takes of the started servers
        def __init__(self) -> None:
            self.cell = cell
            self.probe_port = "socket://127.0.0.1:1"
            self.controller_host, self.controller_port = "127.0.0.1", 1502

    cfg = parse_text(six_axis_config_text(Servers(), 2), "<six-axis>")
    truth = cell.truth
    assert truth.joint_errors is not None and truth_delta(truth) is not None
    assert truth_delta(six_axis_truth(2)) is None  # a rigid arm's oracle stays geometric
    steps = build_plan(cfg).run_steps(1, True)
    p_true = oracle_params(cfg, truth)
    honest = articulated_targets(cfg, steps, p_true, p_true[:6], truth_delta(truth))
    rigid = articulated_targets(cfg, steps, p_true, p_true[:6])
    heads = head_targets_world(cfg)
    missed = []
    for key, (q, _) in honest.items():
        stands = q[None] + truth.joint_delta(q[None])
        np.testing.assert_allclose(forward(cfg.model, stands, p_true)[0, :3, 3], heads[key[0]][:3, 3], atol=1e-6)
        q_rigid = rigid[key][0][None]
        missed.append(np.linalg.norm(forward(cfg.model, q_rigid + truth.joint_delta(q_rigid), p_true)[0, :3, 3]
                                     - heads[key[0]][:3, 3]))
    assert np.sqrt(np.mean(np.square(missed))) > 0.05  # mm: the geometric oracle misses a bending arm
