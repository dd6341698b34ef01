"""The collision check on the examples' plans (issue 40): the touch is its approach, touch and
retract, where the tips may press on the cube and the probes' bodies keep a smaller margin; a SCARA
travels with the head's lowest point, not its contact, above the highest cube."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from station.cell.config.cell_config import load_config
from station.cell.plan.assembly import nominal_contact
from station.cell.plan.collision import TOUCH_MARGIN_MM, check_path
from station.cell.plan.collision_shapes import head_depth_mm
from station.cell.plan.measurement_plan import build_plan, point_joints, travel_joints
from station.cell.plan.run_path import plan_path

pytest.importorskip("fcl")

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def _steps(poses, first: int, last: int):
    """The poses of steps ``first`` … ``last`` (1-based, as labelled)."""
    return [p for p in poses if first <= int(p[1].split()[1]) <= last]


def test_a_touch_lets_the_tips_press_and_keeps_the_bodies_clear():
    cfg = load_config(EXAMPLES / "puma560" / "cell.toml")
    poses = _steps(plan_path(cfg, build_plan(cfg)), 1, 1)  # approach, above the point, touch, retract
    assert [p[1].rsplit(": ", 1)[1] for p in poses] == ["approach", "above the point", "touch", "retract"]
    report = check_path(cfg, poses)
    assert report.clash is None
    touch = report.closest_touch  # None: every probe's body stayed farther than its watch distance
    assert touch is None or (touch.limit_mm == TOUCH_MARGIN_MM and "tip" not in touch.a
                             and TOUCH_MARGIN_MM <= touch.clearance_mm)
    # the same poses as travel (no measuring point): the tips on the cube are a clash at the full margin
    as_travel = check_path(cfg, [(q, label, -1) for q, label, _ in poses])
    assert as_travel.clash is not None and "tip" in as_travel.clash.a
    assert as_travel.clash.limit_mm == cfg.plan.collision_margin_mm


def test_a_scara_travels_with_the_lowest_probe_clear_of_the_highest_cube():
    cfg = load_config(EXAMPLES / "scara600" / "cell.toml")
    head = cfg.head
    M = nominal_contact(cfg)
    # the head file's lowest probe: Y2, 20 mm below the contact, with its 1 mm tip
    lowest = max(float(M[2, 3] - p[2]) + r + s / 2 * max(0.0, -d[2])
                 for p, d, r, s in zip(head.mount_points, head.directions, head.tip_radii, head.strokes))
    assert head_depth_mm(cfg) == pytest.approx(lowest)
    q = point_joints(cfg, cfg.plan.elbows[0])
    top = float(np.nanmax(q[:, 2]))
    t = travel_joints(cfg)[2]
    assert t == pytest.approx(min(cfg.soft_limits[2, 1], top + cfg.plan.clearance_mm + lowest))
    # P5b to P3c then P3b: at a travel height of the contact 20 mm over the highest cube, probe Y2
    # dragged 1 mm into the cube of P3a; with the head's depth it clears it by the margin
    report = check_path(cfg, _steps(plan_path(cfg, build_plan(cfg)), 12, 14))
    assert report.clash is None, report.clash.describe()
