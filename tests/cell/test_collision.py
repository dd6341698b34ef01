"""The collision check (issue 40): an obstacle across a path is found and named before motion, a
folded arm hits itself, and a clear move passes. Shapes and distances are python-fcl's."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from station.cell.config.cell_config import load_config
from station.cell.config.sections import ObstacleConfig
from station.cell.plan.collision import check_path
from station.cell.plan.collision_shapes import cell_shapes
from station.core.kinematics.forward import forward

pytest.importorskip("fcl")

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


@pytest.fixture(scope="module")
def puma():
    return load_config(EXAMPLES / "puma560" / "cell.toml")


def _column(cfg, at_mm, radius=40.0):
    pose = np.eye(4)
    pose[:3, 3] = at_mm
    return dataclasses.replace(cfg, obstacles=(ObstacleConfig("column", "cylinder", "base", pose, (radius, 2000.0)),))


def test_an_obstacle_across_the_path_is_named_with_its_clearance(puma):
    q0 = np.radians([0.0, -45.0, 0.0, 0.0, 45.0, 0.0])
    q1 = np.radians([60.0, -45.0, 0.0, 0.0, 45.0, 0.0])
    poses = [(q0, "step 1: approach", -1), (q1, "step 2: approach", -1)]
    assert check_path(puma, poses).clash is None  # the same move, nothing in the way
    # a column where the head passes half-way: neither end pose touches it, the path does
    mid = forward(puma.model, np.radians([30.0, -45.0, 0.0, 0.0, 45.0, 0.0])[None], setup=False)[0, :3, 3]
    end = [forward(puma.model, q[None], setup=False)[0, :3, 3] for q in (q0, q1)]
    assert min(np.linalg.norm((e - mid)[:2]) for e in end) > 150.0
    report = check_path(_column(puma, mid), poses)
    assert report.clash is not None
    assert "obstacle 'column'" in (report.clash.a, report.clash.b)
    assert "on the move from step 1: approach" in report.clash.where
    assert report.clash.clearance_mm < puma.plan.collision_margin_mm
    assert report.samples > 2  # the path was sampled, not only its ends


def test_a_folded_arm_hits_itself(puma):
    straight = np.radians([0.0, -45.0, 0.0, 0.0, 45.0, 0.0])
    folded = np.radians([0.0, -45.0, 90.0, 0.0, 45.0, 0.0])  # the wrist folded back onto the shoulder
    assert check_path(puma, [(straight, "step 1: touch", -1)]).clash is None
    clash = check_path(puma, [(folded, "step 1: touch", -1)]).clash
    assert clash is not None
    assert clash.a.startswith(("link", "probe", "head")) and clash.b.startswith(("link", "probe", "head"))
    assert clash.clearance_mm < 0  # overlapping, by fcl's signed distance


def test_neighbouring_links_are_not_checked_against_each_other(puma):
    shapes, point_cube = cell_shapes(puma)
    groups = list(dict.fromkeys(s.group for s in shapes.moving))
    for a, b in zip(groups, groups[1:]):
        assert frozenset((a, b)) in shapes.allowed
    assert frozenset((groups[1], groups[3])) not in shapes.allowed
    assert len(set(point_cube)) == 6  # the body's six cubes, four corners each
