"""Issue 40's six-axis "done when" on examples/puma560_obstacles: the plan keeps both arm
configurations the limits allow (+1 shoulder front, +7 shoulder back), collides nowhere in the
station's check, and is as identifiable as the same cell's plan without the obstacles (condition
within 10 %). Its robot file holds the PUMA 560's own joint-3 range (the 90° it cannot turn lie
around the fold, not around the stretched arm: tests/cell/test_puma_fold.py), so the shoulder
changes over the stretched arm. The rehearsal to SUCCESS with the simulator's independent check is
tests/simulators/test_sim_collision.py's."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from station.cell.config.cell_config import load_config
from station.cell.pipeline.preview import preview
from station.cell.plan.measurement_plan import build_plan
from station.cell.plan.run_path import check_plan, plan_path

pytest.importorskip("fcl")

CELL = Path(__file__).resolve().parents[2] / "examples" / "puma560_obstacles" / "cell.toml"


@pytest.fixture(scope="module")
def cell():
    cfg = load_config(CELL)
    return cfg, build_plan(cfg)


def test_the_plan_keeps_both_configurations_and_collides_nowhere(cell):
    cfg, plan = cell
    assert {t.elbow for t in plan.identification} == {1, 7}
    assert {t.elbow for t in plan.verification} == {1, 7}
    assert len(cfg.obstacles) == 2
    report = check_plan(cfg, plan)  # raises on any clash of a pose or a path
    assert report.clash is None and report.vias > 0
    poses = plan_path(cfg, plan)
    q3 = np.array([q[2] for q, _l, _p in poses])
    lim = cfg.soft_limits[2]
    assert np.all((q3 >= lim[0]) & (q3 <= lim[1]))
    # every change of configuration turns joint 3 over the stretched arm (-90°), none through the fold
    over = np.flatnonzero(np.diff(np.sign(q3 + np.pi / 2)) != 0)
    changes = [i for i in over if poses[i][1].split(" elbow ")[1][:2] != poses[i + 1][1].split(" elbow ")[1][:2]]
    assert len(changes) >= 2 and len(changes) == len(over)


def test_the_obstacles_cost_no_identifiability():
    cfg = load_config(CELL)
    with_them = preview(cfg)
    without = preview(dataclasses.replace(cfg, obstacles=()))
    assert len(with_them.identifiable) == len(without.identifiable) == 30
    assert abs(with_them.condition / without.condition - 1.0) <= 0.10, (with_them.condition, without.condition)
    # the σ in the robot's base frame is that of the two-configuration plan, not one's (~46 µm)
    assert with_them.sigma_position_um[2] < 1.1 * without.sigma_position_um[2]


def test_plan_says_a_point_the_design_left_out_is_not_out_of_reach(capsys):
    """The P2 cube is reachable in configuration +1 (no 'NOT measured' line there), but with two
    configurations the I-optimal design meets its noise rule without it: the warning says so, and
    does not send the user to the set-up or the limits."""
    from station.ui.cli.main import main

    assert main(["plan", str(CELL)]) == 0
    said = capsys.readouterr()
    out = said.out + said.err
    assert not any(line.strip().startswith("NOT measured: P2a configuration +1") for line in out.splitlines())
    warning = next(line for line in out.splitlines() if "measured in no pose" in line)
    assert "P2a, P2b, P2c, P2d (each has poses the plan could measure" in warning, warning
    assert "chose none of them" in warning and "check [robot].setup" not in warning
