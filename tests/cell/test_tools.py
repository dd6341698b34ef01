"""Tools after the head ([[tool]], station/cell/correction/robot_tools.py): the schema, the per-tool correction,
and one simulated calibration that checks a 200 mm gripper against the simulator's true robot."""

from __future__ import annotations

import dataclasses
import json
import re
from contextlib import ExitStack

import numpy as np
import pytest

from simulators import start_simulated_cell
from simulators.judge import CellJudge
from simulators.reference_cell import cell_config_text
from station.cell.config.cell_config import parse_text
from station.cell.config.template import TEMPLATE
from station.cell.correction.robot_tools import (
    check_tools,
    evaluate_tool,
    find_tool,
    result_key,
)
from station.cell.correction.tool_export import table_from_json, tool_export
from station.cell.pipeline.calibration import Options, reference_params, run_calibration, stored_plan
from station.cell.plan.steps import PlannedStep, StepKind
from station.cell.records.rundb import RunDB
from station.cell.records.summary import RunSummary
from station.cell.run.facts.events import Notice
from station.cell.session.calibrate import open_cell
from station.core.kinematics.forward import forward
from station.core.kinematics.model import robot_from_dict
from station.core.kinematics.tool_frame import tool_params
from station.core.kinematics.transforms import matrix_to_pose, pose_to_matrix, rot_z
from station.core.table.values import CorrectionTableData
from station.errors import ConfigError, Outcome
from station.ui.cli.main import main as station_main
from station.ui.report.render.html_page import render_html
from station.ui.report.render.markdown_page import render_markdown
from station.ui.report.run import report_data_for_run

GRIPPER = """
[[tool]]
name = "gripper"
tcp = [50.0, 0.0, -200.0, 0.0, 0.0, 0.0]
z_mm = [150.0, 350.0, 200.0]
"""


def _with_tools(text: str, tools: str) -> str:
    return text + "\n" + tools


#: the template with its grid keys given (the old fixed grid x 250 … 650, y ±350, z 250 … 450 mm)
EXPLICIT = TEMPLATE
for _key in ("x_mm", "y_mm", "z_mm", "yaw_step_deg"):
    EXPLICIT = EXPLICIT.replace(f"# {_key} = ", f"{_key} = ", 1)


# ------------------------------------------------------------------------------ the schema

def test_tools_are_parsed_in_mm_and_rad():
    cfg = parse_text(_with_tools(TEMPLATE, GRIPPER + '\n[[tool]]\nname = "pen.2"\ntcp = [0, 0, -180, 0.0, 0.0, 90.0]\n'))
    assert [t.name for t in cfg.tools] == ["gripper", "pen.2"]
    np.testing.assert_allclose(cfg.tools[1].tcp, [0.0, 0.0, -180.0, 0.0, 0.0, np.pi / 2])
    np.testing.assert_allclose(cfg.tools[1].tcp_matrix[:3, 0], [0.0, 1.0, 0.0], atol=1e-15)
    # the gripper's own grid heights, the rest from [correction]
    assert cfg.tools[0].correction.z_mm == (150.0, 350.0, 200.0)
    assert cfg.tools[0].correction.x_mm == cfg.correction.x_mm
    assert cfg.tools[1].correction == cfg.correction
    assert parse_text(TEMPLATE).tools == ()


def test_the_templates_example_parses():
    # the [[tool]] example alone: the grid's commented keys come before it, and the [[obstacle]] example
    # (issue 40), with its own '# name =', after it; the tool's block ends at its blank line
    start = TEMPLATE.index("# [[tool]]")
    tools = TEMPLATE[start:TEMPLATE.index("\n\n", start)]
    assert "[[obstacle]]" not in tools
    example = [ln for ln in tools.splitlines() if ln.startswith(("# [[tool]]", "# name =", "# tcp =", "# z_mm ="))]
    assert len(example) == 4
    cfg = parse_text(TEMPLATE + "\n" + "\n".join(ln[2:] for ln in example) + "\n")
    assert cfg.tools[0].name == "gripper" and cfg.tools[0].tcp[2] == -200.0


@pytest.mark.parametrize("tools,pattern", [
    (GRIPPER + GRIPPER, r"tool name 'gripper' appears twice"),
    ('[[tool]]\nname = "g"\ntcp = [2500.0, 0, 0, 0, 0, 0]\n', r"tool\[0\]\.tcp.*2000"),
    ('[[tool]]\nname = "g"\ntcp = [0, 0, 0, 0, 0]\n', r"tool\[0\]\.tcp"),
    ('[[tool]]\nname = "g r"\ntcp = [0, 0, 0, 0, 0, 0]\n', r"tool\[0\]\.name = 'g r': use letters, digits"),
    ('[[tool]]\nname = "-g"\ntcp = [0, 0, 0, 0, 0, 0]\n', r"tool\[0\]\.name = '-g': .*starting with a letter"),
    ('[[tool]]\ntcp = [0, 0, 0, 0, 0, 0]\n', r"tool\[0\]\.name is missing"),
    ('[[tool]]\nname = "g"\ntcp = [0, 0, 0, 0, 0, 0]\nlength = 3.0\n', r"unknown key 'length'"),
    ('[[tool]]\nname = "g"\ntcp = [0, 0, 0, 0, 0, 0]\nz_mm = [150.0, 450.0, 100.0]\n', r"tool 'g'.*32000"),
    ('[[tool]]\nname = "g"\ntcp = [0, 0, 0, 0, 0, 0]\nz_mm = [150.0, 450.0, 70.0]\n', r"tool 'g'.*correction\.z_mm"),
])
def test_bad_tools_are_refused_naming_the_key(tools, pattern):
    with pytest.raises(ConfigError, match=pattern):  # an explicit grid: the tool's capacity is known when read
        parse_text(_with_tools(EXPLICIT, tools))


def test_a_scara_tool_must_run_along_the_last_axis():
    cfg = parse_text(_with_tools(TEMPLATE, '[[tool]]\nname = "angled"\ntcp = [0, 0, -150, 30.0, 0, 0]\n'))
    with pytest.raises(ConfigError, match=r"tool 'angled'.*tilted 30\.0 deg"):
        check_tools(cfg)
    check_tools(parse_text(_with_tools(TEMPLATE, '[[tool]]\nname = "ok"\ntcp = [0, 0, -150, 0.5, 0, 45]\n')))
    with pytest.raises(ConfigError, match=r"no tool 'drill'.*'angled'"):
        find_tool(cfg, "drill")


# ------------------------------------------------------------------------------ without a run

def _steps(cfg, joints, elbows):
    return [PlannedStep(i, StepKind.VERIFY_BEFORE, i, f"P{i}", int(e), 1, 0, tuple(float(v) for v in q))
            for i, (q, e) in enumerate(zip(joints, elbows))]


def _resplit_last(model, p, dz, dyaw):
    """The same robot with another split of the last joint's constant and K (see
    tests/core/test_tool_frame.py): the minimal set cannot tell them apart."""
    q = np.array(p, dtype=float)
    a = 6 * model.joint_transforms[-1]
    D = np.eye(4)
    D[:3, :3] = rot_z(dyaw)
    D[2, 3] = dz
    q[a:a + 6] = matrix_to_pose(pose_to_matrix(p[a:a + 6]) @ D)
    q[-6:] = matrix_to_pose(np.linalg.inv(D) @ pose_to_matrix(p[-6:]))
    return q


def test_a_truth_that_splits_a4_and_k_otherwise_needs_no_other_correction():
    """The identification's K absorbs A4's unidentifiable parts; a true robot that splits them
    otherwise is the same robot, and the tool's correction is the oracle's to the bit of float32."""
    cfg = parse_text(_with_tools(EXPLICIT, GRIPPER))  # a grid over these joints, not one designed for the plan
    rng = np.random.default_rng(4)
    p_id = np.array(cfg.model.nominal)
    p_id[6:] += rng.normal(0.0, 1.0, cfg.model.n_params - 6) * np.tile([0.04, 0.04, 0.04, 7e-4, 7e-4, 7e-4], 5)
    p_true = _resplit_last(cfg.model, p_id, dz=0.6, dyaw=0.004)
    joints = np.array([[-0.6, 1.6, -60.0, 0.2], [0.6, -1.6, -40.0, 1.0], [-0.9, 2.0, -80.0, -2.0]])
    steps = _steps(cfg, joints, [1, -1, 1])
    ev = evaluate_tool(cfg, cfg.tools[0], p_id, steps, None, p_ref=p_true)
    assert ev.own_um is not None and ev.oracle_um is not None
    assert np.all(np.isfinite(ev.own_um))
    np.testing.assert_allclose(ev.own_um, ev.oracle_um, atol=0.05)  # µm
    assert ev.correction.table is not None  # what is left is the table's interpolation
    assert float(np.max(ev.own_um)) <= ev.correction.table.interpolation_bound_um
    assert ev.head_um is None and not ev.notes[1:]  # no head table given: no head figure


def _six_axis():
    """A generic six-axis arm (no roll/pitch of ±90° in the chain) with a probe head as K."""
    tr = [{"name": "R"},
          {"name": "A1", "joint": "revolute", "z": 400.0, "limits": [-170, 170]},
          {"name": "A2", "joint": "revolute", "x": 150.0, "roll": -80.0, "limits": [-100, 150]},
          {"name": "A3", "joint": "revolute", "x": 600.0, "yaw": 10.0, "limits": [-170, 80]},
          {"name": "A4", "joint": "revolute", "x": 100.0, "y": -100.0, "roll": -80.0, "limits": [-300, 300]},
          {"name": "A5", "joint": "revolute", "z": 600.0, "roll": 80.0, "limits": [-120, 120]},
          {"name": "A6", "joint": "revolute", "y": 10.0, "roll": -80.0, "limits": [-300, 300]},
          {"name": "K", "z": 90.0, "x": 3.0}]
    return robot_from_dict({"robot": {"name": "six"}, "transform": tr})


def test_other_robots_get_compensated_targets_for_the_tool():
    base = parse_text(_with_tools(TEMPLATE, GRIPPER.replace("-200.0", "150.0")))
    model = _six_axis()
    cfg = dataclasses.replace(base, model=model, head_in_flange=None)  # the fallback: H = the nominal K
    rng = np.random.default_rng(7)
    p_true = np.array(model.nominal)
    p_true[6:] += rng.normal(0.0, 1.0, model.n_params - 6) * np.tile([0.05, 0.05, 0.05, 5e-4, 5e-4, 5e-4], 7)
    joints = np.radians([[10, 20, -30, 40, 50, 60], [-20, 40, -10, -30, 40, 10], [30, 10, -50, 10, -60, -40]])
    steps = _steps(cfg, joints, [1, 1, 1])
    tool = cfg.tools[0]
    ev = evaluate_tool(cfg, tool, p_true, steps, None, p_ref=p_true)  # identified = true
    corr = ev.correction
    assert corr.kind == "targets" and corr.table is None and corr.commands is not None
    assert ev.own_um is not None and ev.head_um is not None and ev.oracle_um is not None
    # the compensated targets put the true tool exactly on its targets
    assert float(np.max(ev.own_um)) < 1e-3 and float(np.max(ev.oracle_um)) < 1e-3
    # six joints correct the head's full pose, so the head's joint correction carries the rigid tool
    # along (unlike a SCARA's table, which cannot correct tilts: see the simulated run below)
    assert float(np.max(ev.head_um)) < 1e-3
    # without any correction the tool would miss by the model errors
    q_nominal = corr.targets.joints
    true_tool = tool_params(model, p_true, pose_to_matrix(model.nominal[-6:]), tool.tcp_matrix)
    miss = forward(model, q_nominal, true_tool, setup=False)[:, :3, 3] - corr.targets.base[:, :3, 3]
    assert float(np.min(np.linalg.norm(miss, axis=1))) > 0.05
    # the controller (nominal model with the nominal tool) reaches the commands with the corrected joints
    np.testing.assert_allclose(forward(corr.kin.nominal, corr.commanded_joints, setup=False), corr.commands, atol=1e-9)
    # and the true tool there is on the target
    reached = forward(model, corr.commanded_joints, true_tool, setup=False)
    np.testing.assert_allclose(reached[:, :3, 3], corr.targets.base[:, :3, 3], atol=1e-6)
    assert ev.summary().crc32 is None and ev.summary().kind == "targets"


# ------------------------------------------------------------------------------ one simulated run

@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """One simulated calibration of the built-in cell with a 200 mm gripper (50 mm off-axis) configured."""
    tmp = tmp_path_factory.mktemp("tools")
    with ExitStack() as stack:
        srv = start_simulated_cell(seed=1)
        stack.callback(srv.stop)
        cfg = parse_text(_with_tools(cell_config_text(srv, 1), GRIPPER))
        db = stack.enter_context(RunDB(tmp / "runs.sqlite"))
        devices = open_cell(cfg, stack)
        events: list = []
        summary = run_calibration(cfg, devices.probe, devices.controller, db, events.append,
                                  options=Options(judge=CellJudge(srv.cell.truth)))
        yield {"cfg": cfg, "db": db, "summary": summary, "events": events, "srv": srv, "tmp": tmp}


@pytest.mark.slow  # an end-to-end session: the slow tier (README), run by CI
def test_the_gripper_reaches_its_oracle_and_the_heads_correction_does_not(run):
    s = run["summary"]
    assert s.outcome is Outcome.SUCCESS
    (g,) = s.tools
    assert g.name == "gripper" and g.kind == "table" and g.n_targets >= 8 and g.n_after == g.n_targets
    # its own correction: within 1.2× the oracle's (the correction built from the true robot and true tool)
    assert g.after_vs_oracle is not None and 0.7 <= g.after_vs_oracle <= 1.2, g.after_vs_oracle
    assert g.after_rms_um < 20.0
    # the head's correction used as it is leaves a clearly larger error for this tool
    assert g.head_rms_um > 5.0 * g.after_rms_um and g.n_head == g.n_targets
    # and the station predicts that from the identified model alone (a real cell's figure)
    assert g.head_predicted_rms_um == pytest.approx(g.head_rms_um, rel=0.2)
    # The height sum the body cannot tell apart stays with the set-up (issue 36: R joins the minimal set
    # by exchange; before, K.z absorbed it and the flange moved > 50 µm along z): K's height is the robot
    # file's, and the identified flange differs from the nominal one by K's identified x, y and tilt only
    chosen = run["db"].load_result(s.run_id, "identification")["chosen"]
    assert "R.z" in chosen and "K.z" not in chosen
    stored = run["db"].load_result(s.run_id, result_key("gripper"))
    shift_mm = np.subtract(stored["flange_identified_pose_mm_rad"][:3], stored["flange_nominal_pose_mm_rad"][:3])
    assert abs(shift_mm[2]) < 0.01 and g.flange_shift_um == pytest.approx(1e3 * np.linalg.norm(shift_mm))
    assert g.flange_shift_um > 10.0 and g.flange_rotation_arcsec > 30.0  # still not the nominal flange


def test_the_tool_is_stored_reported_and_exported_the_head_table_stays_uploaded(run, capsys):
    cfg, db, s, srv = run["cfg"], run["db"], run["summary"], run["srv"]
    stored = db.load_result(s.run_id, result_key("gripper"))
    assert stored["summary"]["crc32"] == s.tools[0].crc32
    for key in ("after_um", "oracle_um", "head_um", "head_predicted_um", "flange_shift_um", "tcp_mm_deg",
                "flange_identified_pose_mm_rad", "tool_params_identified"):
        assert key in stored
    assert len(stored["after_um"]) == s.tools[0].n_targets
    assert len(stored["after_um"][0]) == cfg.plan.verification_cycles
    # the summary's JSON carries the three figures and reads back
    js = s.to_json()
    t = js["tools"][0]
    assert {"after_rms_um", "oracle_rms_um", "head_rms_um", "after_vs_oracle"} <= set(t)
    assert RunSummary.from_json(json.loads(json.dumps(js))) == s
    assert any(isinstance(e, Notice) and "tool 'gripper'" in e.message and "oracle" in e.message for e in run["events"])
    # the controller keeps the head's table: the tool's is exported, not uploaded
    active = srv.controller_server.active_table.crc32()
    assert active == int(s.correction.crc32, 16) and active != int(s.tools[0].crc32, 16)
    # the report shows the three figures per tool
    d = report_data_for_run(db, s.run_id)
    md = render_markdown(d)
    assert "## Tools after the head" in md
    row = next(ln for ln in md.splitlines() if ln.startswith("| gripper |") and "µm" not in ln and ln.count("|") == 10)
    assert f"{s.tools[0].after_rms_um:.1f}" in row and f"{s.tools[0].head_rms_um:.1f}" in row
    assert f"{s.tools[0].oracle_rms_um:.1f}" in row
    html = render_html(d)
    assert 'id="tools-check-table"' in html and 'href="#tools"' in html
    # station export --tool writes the table the run stored (same CRC-32), read back bit for bit
    out = run["tmp"] / "gripper.json"
    # its table's bound is beyond [correction].max_interpolation_um: refused (exit 9), nothing written ...
    export = ["export", "--db", str(db.path), "--run", str(s.run_id), "--tool", "gripper", str(out)]
    assert station_main(export) == 9 and not out.exists()
    assert "--force" in capsys.readouterr().err
    # ... unless --force, which writes the warning into the file
    assert station_main([*export, "--force"]) == 0
    doc = json.loads(out.read_text(encoding="utf-8"))
    assert doc["interpolation_bound_um"] > doc["max_interpolation_um"] and "--force" in doc["warning"]
    assert doc["tool"] == "gripper" and doc["tcp_mm_deg"] == [50.0, 0.0, -200.0, 0.0, 0.0, 0.0]
    data = table_from_json(doc["table"])
    assert isinstance(data, CorrectionTableData) and f"{data.crc32():08x}" == s.tools[0].crc32
    assert data.axes[2].start == 150.0  # the gripper's own grid heights
    assert re.search(r"tool 'gripper' correction \(table CRC-32 [0-9a-f]{8}\)", capsys.readouterr().out)
    with pytest.raises(ConfigError, match="no tool 'drill'"):
        tool_export(db, s.run_id, "drill")
    assert station_main(["export", "--db", str(db.path), "--run", str(s.run_id), "--tool", "drill", str(out)]) == 2


def test_the_stored_figures_follow_from_the_run_database(run):
    """The tool's figures are recomputed alike from the stored plan and identification (the
    joint scatter is seeded by the simulator's seed)."""
    cfg, db, s, srv = run["cfg"], run["db"], run["summary"], run["srv"]
    p_true = reference_params(cfg, srv.cell.truth)
    steps = stored_plan(db, s.run_id)
    ident = db.load_result(s.run_id, "identification")
    ev = evaluate_tool(cfg, cfg.tools[0], np.asarray(ident["params"]), steps, None, p_ref=p_true,
                       judge=CellJudge(srv.cell.truth))
    stored = db.load_result(s.run_id, result_key("gripper"))
    np.testing.assert_allclose(ev.oracle_um, np.array(stored["oracle_um"], dtype=float), rtol=1e-9)
    np.testing.assert_allclose(ev.own_um, np.array(stored["after_um"], dtype=float), rtol=1e-9)
