"""The error terms beyond geometry in the cell's session (issue 30): ``[identification] model``,
checked before anything moves, and a simulated six-axis rehearsal whose arm bends under gravity
and errs once per turn (``[simulation] joint_errors = "six-axis"``), identified with ``auto``,
compensated with the full model and judged against an oracle that knows the joint errors too; a
SCARA whose gears err once per turn, its correction table built with the terms ``auto`` keeps."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from station.cell.config.cell_config import parse_text
from station.cell.config.template import TEMPLATE
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
    # the template's robot is a SCARA: its correction table carries the terms
    assert parse_text(TEMPLATE.replace('model = "geometric"', 'model = "auto"')).identification.terms == ("auto",)
    with pytest.raises(ConfigError, match="compliance, cyclic"):
        parse_text(TEMPLATE.replace('model = "geometric"', 'model = "complience"'))


def test_a_six_axis_model_names_real_joints(tmp_path):
    text = Path(_puma(tmp_path, "none", "compliance+cyclic.q3")).read_text(encoding="utf-8")
    src = str(tmp_path / "none-compliance+cyclic.q3" / "cell.toml")
    ident = parse_text(text, src).identification
    assert ident.terms == ("compliance", "cyclic.q3") and ident.gravity is None  # no [gravity]: lumped
    from station.cell.pipeline.preview import describe, preview

    pv = preview(parse_text(text.replace("compliance+cyclic.q3", "auto"), src))
    assert pv.error_model == "auto" and pv.to_json()["error_model"] == "auto"
    assert any(line.strip().startswith("error model: auto") for line in describe(pv))
    with pytest.raises(ConfigError, match="unknown error term 'cyclic.q7'"):
        parse_text(text.replace("cyclic.q3", "cyclic.q7"), src)
    with pytest.raises(ConfigError, match='objective = "pose"'):
        parse_text(text.replace("[identification]\n", '[identification]\nobjective = "distance"\n'), src)


def test_the_pose_design_accounts_for_the_terms_the_model_may_keep(tmp_path):
    """Issue 30: with ``[identification] model = "auto"`` the I-optimal identification design has the
    terms' columns beside the geometry's (compliance, first harmonics): its account counts their
    parameters, and the σ it predicts at the working poses is the full model's. A design blind to
    the terms claims less than its poses give the full model, and picks poses no better for it."""
    from station.cell.config.cell_config import load_config
    from station.cell.plan.articulated import _design_jacobians, articulated_candidates, design_terms
    from station.cell.plan.measurement_plan import build_plan
    from station.cell.plan.vias import clear_candidates

    cfgs = {}
    for model in ("geometric", "auto"):
        path = Path(_puma(tmp_path, "none", model))
        path.write_text(path.read_text(encoding="utf-8").replace("select = 120", "select = 40"), encoding="utf-8")
        cfgs[model] = load_config(str(path))
    auto = cfgs["auto"]
    spec = design_terms(auto)
    assert design_terms(cfgs["geometric"]) is None and spec is not None and "compliance" in spec.families
    # the working poses the design judges: the candidates a run can measure without a collision (the
    # PUMA's shoulder-back ones are left out: every way to them folds the wrist into the shoulder)
    cands, orient, _ = clear_candidates(auto, *articulated_candidates(auto)[:2])
    q_work = np.array([c.joints for c, k in zip(cands, orient) if k == 0])
    designs, full = {}, {}
    for model, cfg in cfgs.items():
        plan = build_plan(cfg)
        assert plan.design is not None and plan.design.n_poses == 40
        designs[model] = plan.design
        q = np.unique(np.array([st.q for st in plan.identification]), axis=0)
        J, G = _design_jacobians(auto, q, q_work)  # judged with the terms, whatever it was designed for
        C = np.linalg.pinv(np.einsum("crp,crq->pq", J, J)) / plan.design.repeats
        full[model] = float(np.sqrt(np.mean(np.einsum("msp,pq,msq->m", G, C, G)))) * 1e3
    geo, terms = designs["geometric"], designs["auto"]
    assert terms.n_parameters > geo.n_parameters  # the terms' columns: 44 against 30 for the Puma
    assert terms.sigma_work_um == pytest.approx(full["auto"], rel=1e-3)  # the account is the full model's
    assert geo.sigma_work_um < 0.9 * full["geometric"]  # blind, it claims less than its poses give: 6.3 against 7.3 µm
    assert full["auto"] <= full["geometric"] * 1.03, full  # its poses serve the full model no worse


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="issue 40: the PUMA 560 example keeps configuration +1 only (every way to the "
                   "other passes joint 3 through the fold, the wrist centre inside the shoulder: "
                   "tests/cell/test_puma_fold.py); on one configuration auto's cross-validated RMS with the terms it "
                   "keeps is 16.3 against 16.6 µm geometric, not under 0.8 of it")
def test_a_bending_arm_is_calibrated_with_the_terms_auto_keeps(tmp_path):
    """auto keeps terms on an arm with joint errors, ends within 0.7 … 1.2 of an oracle that knows
    them, and beats the geometric session of the same cell (whose after/oracle is now honest too)."""
    auto = _session(_puma(tmp_path, "six-axis", "auto"))
    geo = _session(_puma(tmp_path, "six-axis", "geometric"))
    for s in (auto, geo):
        assert s.outcome is Outcome.SUCCESS, s.failure
        assert s.after is not None and s.oracle is not None and s.before is not None
    # the same robot and set-up, but not the same plan (auto's is designed for the terms too), so not the
    # same set-up identified nor the same noise draws: 692 / 675 µm here, 644 / 678 µm on another
    # OpenBLAS kernel (docs/error-terms.md)
    assert auto.before.rms_um == pytest.approx(geo.before.rms_um, rel=0.15)
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


@pytest.mark.slow  # an end-to-end session: the slow tier (README), run by CI
def test_auto_keeps_nothing_on_a_rigid_arm(tmp_path):
    s = _session(_puma(tmp_path, "none", "auto"))
    # verified to the end; before correction is the uncorrected robot's in the frame it located the body in
    # (issue 40: no longer through the identified set-up, whose turn about axis 1 is a share of A1's zero),
    # 253 µm at seed 1, so the gain (~17) misses the station's default min_gain of 20 and nothing else
    if s.outcome is not Outcome.SUCCESS:
        assert s.outcome is Outcome.TARGET_MISSED and [m.id for m in s.missed] == ["min_gain"], s.failure
    assert s.gain is not None and s.gain >= 10.0, s.gain  # the six-axis cells' check (issue 9)
    em = s.error_model
    assert em is not None and em.chosen == () and em.terms == () and "geometric fit" in em.summary
    # nothing kept: the geometric fit, on poses designed for the terms' candidates too (seed 1: 1.20,
    # the geometric session of the same rigid arm 1.15; the verification's own noise is ~15 µm)
    assert s.after_vs_oracle is not None and 0.7 <= s.after_vs_oracle <= 1.3, s.after_vs_oracle
    assert s.run_id is not None and s.db is not None
    with RunDB(s.db) as rdb:
        assert rdb.load_result(s.run_id, "articulated")["method"] == "compensated targets"


def test_the_oracle_of_a_bending_arm_puts_the_true_robot_on_target():
    """The simulator's truth carries its joint errors; the oracle's targets compensated with them
    bring the true robot (geometry, half backlash and joint errors at the commanded joints) onto
    every verification target, where the geometric truth alone misses by the arm's bending."""
    from simulators.cell import SimulatedCell
    from simulators.joint_errors import six_axis_joint_errors
    from simulators.judge import CellJudge
    from simulators.six_axis_cell import six_axis_body, six_axis_config_text, six_axis_truth
    from station.cell.pipeline.calibration import articulated_targets, reference_params
    from station.cell.plan.measurement_plan import build_plan, head_targets_world
    from station.core.kinematics.forward import forward

    cell = SimulatedCell(truth=six_axis_truth(2), body=six_axis_body(2), seed=2, joint_errors=six_axis_joint_errors(2))

    class Servers:  # what the configuration's text takes of the started servers
        def __init__(self) -> None:
            self.cell = cell
            self.probe_port = "socket://127.0.0.1:1"
            self.controller_host, self.controller_port = "127.0.0.1", 1502

    cfg = parse_text(six_axis_config_text(Servers(), 2), "<six-axis>")
    truth = cell.truth
    assert truth.joint_errors is not None and CellJudge(truth).reference_delta() is not None
    assert CellJudge(six_axis_truth(2)).reference_delta() is None  # a rigid arm's oracle stays geometric
    steps = build_plan(cfg).run_steps(1, True)
    p_true = reference_params(cfg, truth)
    honest = articulated_targets(cfg, steps, p_true, p_true[:6], CellJudge(truth).reference_delta())
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


# --- a SCARA: the correction table carries the terms -----------------------------------------------

def _scara_cfg(model: str):
    """The built-in simulated SCARA cell's configuration (seed 1) with ``[identification] model``."""
    from simulators.cell import SimulatedCell
    from simulators.reference_cell import cell_config_text

    class Servers:  # what the configuration's text takes of the started servers
        def __init__(self) -> None:
            self.cell = SimulatedCell(seed=1)
            self.probe_port = "socket://127.0.0.1:1"
            self.controller_host, self.controller_port = "127.0.0.1", 1502

    text = cell_config_text(Servers(), 1).replace("[identification]\n", f'[identification]\nmodel = "{model}"\n', 1)
    return parse_text(text, "<scara>")


def test_a_scara_takes_terms_that_poses_identify_and_refuses_what_they_cannot():
    cfg = _scara_cfg("auto")
    assert cfg.model.is_scara and cfg.identification.terms == ("auto",)
    assert _scara_cfg("cyclic.q1+cyclic.q2").identification.terms == ("cyclic.q1", "cyclic.q2")
    # distances between measured points are fitted geometric only: the terms are not identified from them
    with pytest.raises(ConfigError, match="distance objective") as exc:
        parse_text(TEMPLATE.replace('model = "geometric"', 'model = "auto"').replace(
            'objective = "pose"', 'objective = "distance"'))
    assert exc.value.exit_code == 2
    # vertical axes carry no gravity torque and the quill the same load everywhere
    with pytest.raises(ConfigError, match="SCARA's compliance is not identifiable"):
        _scara_cfg("compliance+cyclic")
    with pytest.raises(ConfigError, match="unknown error term 'cyclic.q3'"):  # the quill is prismatic
        _scara_cfg("cyclic.q3")


def test_a_scara_table_with_the_terms_auto_keeps_beats_the_geometric_table_on_the_same_data():
    """A SCARA whose joints 1, 2, 4 err once per turn (simulators/joint_errors.py): its plan's
    identification poses measured on the truth (with noise of the robot's repeatability), ``auto``
    keeps the harmonics, and the table built with them puts the true robot on the verification
    targets closer than the geometric table of the same data (the controller's rule: nominal IK plus
    the interpolated table; the truth stands at the command plus its joint errors)."""
    import dataclasses

    from simulators.cell import CellTruth
    from simulators.joint_errors import scara_joint_errors
    from station.cell.correction.design import region_for
    from station.cell.pipeline.results import build_table_for
    from station.cell.pipeline.terms import terms_delta
    from station.cell.plan.measurement_plan import build_plan, head_targets_world
    from station.cell.plan.steps import StepKind
    from station.core.identification.identify import identify
    from station.core.kinematics.forward import scara_ik
    from station.core.kinematics.transforms import invert, pose_to_matrix
    from station.core.measurement.measurements import MeasurementSet
    from station.core.table.values import interpolate_table
    from station.core.terms.error_model import TermSpec
    from station.core.terms.selection import select_model

    cfg = _scara_cfg("auto")
    errs = scara_joint_errors(1)
    truth = dataclasses.replace(CellTruth.generate(seed=1), joint_errors=errs)
    truth = dataclasses.replace(truth, backlash=np.zeros_like(truth.backlash))  # the joint errors alone
    plan = build_plan(cfg)
    steps = plan.run_steps(1, False)
    q = np.array([st.q for st in steps if st.kind is StepKind.IDENTIFICATION])
    rng = np.random.default_rng(5)
    stands = q + truth.joint_delta(q) + rng.normal(0.0, 1.0, q.shape) * truth.repeatability
    data = MeasurementSet("pose", q, truth.head_pose(stands), cfg.identification.pose_sigma())
    geo = identify(cfg.model, data)
    sel = select_model(cfg.model, data, spec=TermSpec(), geometric=geo)  # as select_terms does for the run
    assert {"cyclic.q1", "cyclic.q2"} <= set(sel.chosen), sel.summary
    delta = terms_delta(cfg, sel)
    assert delta is not None

    region = region_for(cfg)
    grid = region.grid((7, 7, 2, 12))
    p_terms = np.asarray(sel.fit.params, dtype=float)
    with_terms = build_table_for(cfg, p_terms, grid, delta)
    geometric = build_table_for(cfg, geo.params, grid)
    assert with_terms.with_terms and with_terms.interpolation_bound_um < 3 * geometric.interpolation_bound_um

    heads = head_targets_world(cfg)
    ver = [st for st in steps if st.kind is StepKind.VERIFY_AFTER]
    assert ver

    def after_um(table, params) -> float:
        """RMS [µm] of the true robot's error at the verification targets, the table active."""
        err = []
        for st in ver:
            T_base = invert(pose_to_matrix(params[:6])) @ heads[st.point]
            pt = np.array([[*T_base[:3, 3], np.arctan2(T_base[1, 0], T_base[0, 0])]])
            q_cmd = scara_ik(cfg.model, T_base[None], st.elbow, check_limits=False)
            q_cmd = q_cmd + interpolate_table(table.data, pt, table.elbows.index(st.elbow))
            reached = truth.head_pose(q_cmd + truth.joint_delta(q_cmd))[0]
            err.append(np.linalg.norm(reached[:3, 3] - heads[st.point][:3, 3]) * 1e3)
        return float(np.sqrt(np.mean(np.square(err))))

    a_terms, a_geo = after_um(with_terms, p_terms), after_um(geometric, geo.params)
    assert a_terms < 0.3 * a_geo, (a_terms, a_geo)  # seed 1: 2.2 against 17.7 µm


@pytest.mark.slow
def test_a_scara_session_uploads_a_table_with_the_terms_and_meets_an_oracle_that_knows_them(tmp_path):
    """One session (~15 s): the geometric table of the same cell leaves 20.9 µm RMS after correction,
    after/oracle 2.0 (docs/error-terms.md); the comparison on the same data runs fast above."""
    # the operator's way: the built-in simulated SCARA whose gears err once per turn ([simulation]
    # joint_errors = "scara"), with [identification] model = "auto" taken from the same file
    config = tmp_path / "cell.toml"
    config.write_text('[simulation]\njoint_errors = "scara"\n\n[identification]\nmodel = "auto"\n', encoding="utf-8")
    db = tmp_path / "runs.sqlite"
    auto = run_calibration_session(CellRequest(config=str(config), simulated=True, seed=1, db=str(db), time_scale=0.0),
                                   lambda e: None, load=load_cell)
    assert auto.run_id is not None
    with RunDB(db) as runs:
        rec = runs.load_result(auto.run_id, "error_model", default=None)
        stored = runs.run(auto.run_id)
    # the run records the robot it rehearsed: its configuration says the joints erred, and the model asked
    assert 'joint_errors = "scara"' in stored.config_toml and 'model = "auto"' in stored.config_toml
    assert auto.outcome is Outcome.SUCCESS, auto.failure
    assert auto.after is not None and auto.oracle is not None and auto.before is not None
    em = auto.error_model
    assert em is not None and {"cyclic.q1", "cyclic.q2"} <= set(em.chosen)
    assert isinstance(rec, dict) and rec["model"] == "auto" and rec["chosen"] == list(em.chosen)
    assert any("the correction table's nodes carry the terms" in n for n in auto.notes)
    assert auto.after_vs_oracle is not None and 0.7 <= auto.after_vs_oracle <= 1.3, auto.after_vs_oracle
    assert auto.after.rms_um < 15.0, auto.after.rms_um  # seed 1: 9.8 µm (the geometric table: 20.9 µm)
    c = auto.correction
    assert c is not None and c.limit_um is not None and c.interpolation_bound_um <= c.limit_um
