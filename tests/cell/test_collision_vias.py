"""Plans that cannot hit anything (issue 40), the station's side: the vias make the PUMA 560
example's plan clear where its direct joint moves dragged the head through the cubes, the runner
commands the same vias, the pre-motion check of 'plan' and 'calibrate' refuses a plan that collides
(and a check it cannot do), and 'station plan' prints what the check found."""

from __future__ import annotations

import dataclasses
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from station.cell.config.cell_config import load_config
from station.cell.config.sections import ObstacleConfig
from station.cell.plan import collision_shapes, run_path
from station.cell.plan.collision import check_path
from station.cell.plan.measurement_plan import build_plan
from station.cell.plan.run_path import check_plan, plan_path
from station.cell.plan.vias import travel_height_mm, travel_vias
from station.errors import ConfigError, UnreachableError

pytest.importorskip("fcl")

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


@pytest.fixture(scope="module")
def puma():
    cfg = load_config(EXAMPLES / "puma560" / "cell.toml")
    return cfg, build_plan(cfg)


def _is_via(label: str) -> bool:
    return label.endswith(run_path.VIA_NAMES)


def test_the_vias_clear_the_puma_plan_whose_direct_moves_collide(puma):
    cfg, plan = puma
    poses = plan_path(cfg, plan)
    vias = [p for p in poses if _is_via(p[1])]
    assert vias, "an articulated arm travels between corners through vias"
    report = check_plan(cfg, plan)
    assert report.clash is None and report.vias == len(vias)
    # the same plan without its vias: the head goes through the cubes on the direct joint moves
    direct = check_path(cfg, [p for p in poses if not _is_via(p[1])])
    assert direct.clash is not None and "cube" in direct.clash.a + direct.clash.b
    assert direct.clashing_moves > 10
    # the depart and arrive poses hold the head's lowest point at the travel height over the body
    from station.cell.plan.vias import head_low_mm

    lifted = np.array([q for q, label, _ in vias if label.endswith(("depart", "arrive"))])
    assert np.allclose(head_low_mm(cfg, lifted), travel_height_mm(cfg), atol=1e-3)
    # every via inside the soft limits, as the runner's guard requires of every move
    lim = cfg.soft_limits
    assert all(np.all((q >= lim[:, 0]) & (q <= lim[:, 1])) for q, _, _ in vias)


def test_the_pose_design_leaves_out_the_configuration_the_head_cannot_reach_clear(puma):
    cfg, plan = puma
    codes = {t.elbow for t in plan.identification} | {t.elbow for t in plan.verification}
    assert codes == {1}
    why = [r[2] for r in plan.rejected if "cannot be reached" in r[2]]
    assert why and all("+7" in w and "collision" in w for w in why)


def test_the_runner_commands_the_vias_the_plan_checked(puma):
    from station.cell.run.runner import Runner, Travel

    cfg, plan = puma
    steps = plan.run_steps(cfg.plan.verification_cycles, with_oracle=False)
    poses = plan_path(cfg, plan)
    # the first move between two corners in the plan: its retract, its vias, the next approach
    k = next(i for i, p in enumerate(poses) if p[1].endswith("depart"))
    start = poses[k - 1][0]
    planned = []
    for q, label, _ in poses[k:]:
        planned.append(q)
        if label.endswith("approach"):
            break
    moved = []

    class Controller:
        def read_joints(self):
            return start

        def move_joints(self, q, speed=None):
            moved.append(np.array(q))
            return type("Done", (), {"wait": lambda self, timeout=None: None})()

    runner = Runner.__new__(Runner)  # only what a move needs: the guard, the controller, the clock
    from station.cell.limits.motion_guard import MotionGuard

    runner.cfg, runner.controller, runner._last_q = cfg, Controller(), None
    runner.guard = MotionGuard(cfg.soft_limits, joint_types=cfg.model.joint_types)
    runner.timing = {"motion": 0.0}
    runner._do(Travel(planned[-1], "approach"), 0)
    assert len(moved) == len(planned) >= 3
    assert all(np.allclose(a, b, atol=1e-9) for a, b in zip(moved, planned))
    assert len(steps) > 1


def test_the_check_refuses_a_plan_that_hits_an_obstacle_naming_it(puma):
    cfg, plan = puma
    shapes, _ = collision_shapes.cell_shapes(cfg)
    cube = next(s for s in shapes.fixed if s.name.startswith("cube of"))
    e = cfg.cube_edge_mm
    # a post beside the cube's corner, flush with its top: the touches there hit it
    pose = cube.local.copy()
    pose[:3, 3] += cube.local[:3, :3] @ np.array([e / 2 + 4.0, e / 2 + 4.0, 0.0])
    post = ObstacleConfig("post", "cylinder", "base", pose, (3.0, e))
    with pytest.raises(ConfigError) as err:
        check_plan(dataclasses.replace(cfg, obstacles=(post,)), plan)
    text = str(err.value)
    assert "the plan collides" in text and "obstacle 'post'" in text and "nothing was moved" in text
    assert "mm of each other" in text and "step " in text and "[collision]" in text


def test_a_slab_over_the_body_leaves_no_way_to_travel_and_says_what_is_in_it(puma):
    cfg, plan = puma
    pose = np.eye(4)
    pose[:3, 3] = [0.0, 0.0, travel_height_mm(cfg) + 40.0]  # over the body, where the arm travels
    slab = ObstacleConfig("lamp", "box", "body", pose, (2000.0, 2000.0, 60.0))
    with pytest.raises((ConfigError, UnreachableError)) as err:
        check_plan(dataclasses.replace(cfg, obstacles=(slab,)), plan)
    assert "obstacle 'lamp'" in str(err.value)  # the pair that blocks the way, named


def test_without_python_fcl_the_check_is_refused_not_skipped(puma, monkeypatch):
    cfg, plan = puma
    monkeypatch.setitem(sys.modules, "fcl", None)  # import fcl now raises ImportError
    with pytest.raises(ConfigError, match="python-fcl"):
        check_plan(dataclasses.replace(cfg), plan)


def test_travel_vias_of_a_scara_are_none_and_of_one_corner_none(puma):
    cfg, _ = puma
    scara = load_config(EXAMPLES / "scara600" / "cell.toml")
    q = np.zeros(scara.model.n_joints)
    assert travel_vias(scara, q, q + 0.5) == []
    step = build_plan(cfg).identification[0]
    from station.cell.plan.arm_motion import retract_pose

    r = retract_pose(cfg, step.q)
    assert travel_vias(cfg, r, r + np.radians(0.5)) == []  # the head turned at the same corner: direct


def test_station_plan_prints_the_collision_check(capsys):
    from station.ui.cli.main import main

    assert main(["plan", str(EXAMPLES / "scara600" / "cell.toml")]) == 0
    out = capsys.readouterr().out
    assert "collision check:" in out and "least clearance" in out and "margin 2 mm" in out
    assert "0 of them vias" in out  # a SCARA's quill rises to the travel height: no vias


def test_the_report_in_json_says_its_units(puma):
    cfg, plan = puma
    doc = json.loads(json.dumps(check_plan(cfg, plan).to_json()))
    assert doc["clash"] is None and doc["margin_mm"] == 2.0 and doc["vias"] > 0
    assert doc["samples"] >= doc["evaluated"] >= doc["poses"] > 0
    assert doc["closest"] is None or doc["closest"]["clearance_mm"] >= doc["margin_mm"]
