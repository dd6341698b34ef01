"""The plan preview (station plan): what is known before anything moves."""

from __future__ import annotations

import json
import math

import pytest

from simulators import start_simulated_cell
from simulators.reference_cell import cell_config_text
from station.cell.config.cell_config import parse_text
from station.cell.pipeline.preview import describe, preview
from station.cell.plan.measurement_plan import build_plan
from station.cell.plan.steps import StepKind
from station.ui.cli.main import main


@pytest.fixture(scope="module")
def text():
    with start_simulated_cell(seed=1) as sim:
        return cell_config_text(sim, 1)


def test_preview_states_what_a_run_needs_and_can_reach(text):
    cfg = parse_text(text)
    p = preview(cfg)
    n_ident = sum(1 for s in build_plan(cfg).identification if s.kind is StepKind.IDENTIFICATION)
    assert p.n_identification == n_ident
    assert p.min_valid_identification == math.ceil(0.8 * n_ident)
    assert len(p.identifiable) == 20 and 1 < p.condition < 100
    lo, mean, hi = p.sigma_position_um
    assert 0 < lo <= mean <= hi < 50  # a few µm from 6 µm noise over ~140 poses
    for s in p.steps:  # every planned target lies inside the soft limits
        assert min(s.limit_margin) >= 0
    lines = "\n".join(describe(p))
    assert "at least" in lines and "parameter uncertainty only" in lines


def test_preview_names_points_it_cannot_reach(text):
    cfg = parse_text(text.replace("[-140.0, 140.0]", "[0.0, 140.0]"))  # no elbow -1 pose is possible
    p = preview(cfg)
    assert sum(e == -1 for _, e, _ in p.rejected) == len(cfg.point_ids)  # every elbow -1 pose, named
    assert all(s.step.elbow == 1 for s in p.steps)
    assert any("NOT measured" in line and "joint 2" in line for line in describe(p))


def test_station_plan_json(text, tmp_path, capsys):
    cfg = tmp_path / "cell.toml"
    cfg.write_text(text)
    assert main(["plan", str(cfg), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["min_valid_identification"] > 0 and d["steps"][0]["order"] == 1
    assert d["units"]["limit_margin"] == "deg | mm"


def test_preview_estimates_the_motion_time_from_the_robot_files_speeds(text):
    import dataclasses

    import numpy as np

    from station.cell.pipeline.preview import motion_seconds

    cfg = parse_text(text)
    p = preview(cfg)
    assert p.motion_s_estimate is not None and p.motion_s_estimate > 0
    assert "estimated duration" in "\n".join(describe(p))
    # half the joint speed doubles the motion time; no speeds in the robot file: no estimate
    slow = dataclasses.replace(cfg, model=dataclasses.replace(cfg.model, max_speed=cfg.model.max_speed / 2))
    steps = tuple(s.step for s in p.steps)
    assert motion_seconds(slow, steps) == pytest.approx(2 * p.motion_s_estimate, rel=1e-9)
    none = dataclasses.replace(cfg, model=dataclasses.replace(cfg.model, max_speed=None))
    assert motion_seconds(none, steps) is None
    assert "not estimated" in "\n".join(describe(preview(none)))
    # one step's moves: approach, above, touch, retract, each at its slowest joint
    one = steps[:1]
    q = np.array(one[0].q)
    from station.cell.plan.measurement_plan import all_motion_poses, retracted
    path = np.array([*all_motion_poses(cfg, q, 1), retracted(cfg, q)])
    expect = np.sum(np.max(np.abs(np.diff(path, axis=0)) / (cfg.model.max_speed * cfg.plan.speed), axis=1))
    assert motion_seconds(cfg, one) == pytest.approx(expect)


def test_the_bodys_cmm_uncertainty_widens_the_predicted_accuracy():
    import dataclasses
    from pathlib import Path

    import numpy as np

    from station.cell.config.cell_config import load_config

    cfg = load_config(Path(__file__).resolve().parents[2] / "examples" / "scara600" / "cell.toml")
    assert cfg.body_sigma is not None and np.all(cfg.body_sigma > 0)
    with_body = preview(cfg).sigma_position_um
    exact = preview(dataclasses.replace(cfg, body_sigma=np.zeros_like(cfg.body_sigma))).sigma_position_um
    assert with_body[1] > 1.1 * exact[1]


def test_reach_margin_of_each_step_against_the_arm_lengths(text):
    """The reach margin is the wrist axis's distance inside the stretched (L1 + L2) or folded
    (|L1 - L2|) arm: checked against the planar geometry of the SR 800 (445 mm + 355 mm)."""
    import numpy as np

    from station.core.kinematics.forward import forward

    cfg = parse_text(text)
    p = preview(cfg)
    s = p.steps[0]
    T = forward(cfg.model, np.array([s.step.q]), setup=False)[0]
    K = cfg.model.nominal[-6:]
    # the wrist axis: the tool point less K's xy offset turned by the tool's yaw
    yaw = np.arctan2(T[1, 0], T[0, 0]) - K[5]
    w = T[:2, 3] - np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]]) @ K[:2]
    r = np.hypot(*w)
    assert s.reach_margin_mm == pytest.approx(min(800.0 - r, r - 90.0), abs=0.5)
    assert all(x.reach_margin_mm is not None and x.reach_margin_mm > 0 for x in p.steps)
    assert "smallest reach margin" in "\n".join(describe(p))
