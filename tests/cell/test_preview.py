"""The plan preview (station plan): what is known before anything moves."""

from __future__ import annotations

import json
import math

import pytest

from simulators import start_simulated_cell
from simulators.reference_cell import cell_config_text
from station.cell.config import parse_text
from station.cell.plan import build_plan
from station.cell.preview import describe, preview
from station.cell.steps import StepKind
from station.ui.cli import main


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

    from station.cell.preview import motion_seconds

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
    from station.cell.plan import all_motion_poses, retracted
    path = np.array([*all_motion_poses(cfg, q, 1), retracted(cfg, q)])
    expect = np.sum(np.max(np.abs(np.diff(path, axis=0)) / (cfg.model.max_speed * cfg.plan.speed), axis=1))
    assert motion_seconds(cfg, one) == pytest.approx(expect)
