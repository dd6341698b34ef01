"""The correction table's design (station.core.table.design, issue 27): steps chosen per axis
within the capacity, the bound checked on the sampled robots' own tables, refined for the
identified robot, and an honest refusal with numbers when no grid fits."""

from __future__ import annotations

import math

import numpy as np
import pytest

from station.core.table.build import build_correction_table
from station.core.table.design import Region, curvature, design_table, prior_robots, refine_for
from station.core.units import ARCSEC
from station.io.robot.files import load_robot

#: a few working targets of the SR 800 (base frame, mm), well inside its reach
TARGETS = np.array([[420.0, -150.0, 300.0], [500.0, 60.0, 340.0], [450.0, 200.0, 300.0]])


@pytest.fixture(scope="module")
def robot():
    return load_robot("sr800")


@pytest.fixture(scope="module")
def robots(robot):
    return prior_robots(robot, 3, length_sigma_mm=0.04, offset_sigma_rad=150 * ARCSEC, tilt_sigma_rad=150 * ARCSEC,
                        angle_sigma_rad=150 * ARCSEC)


@pytest.fixture(scope="module")
def region():
    return Region.around(TARGETS, 10.0, (1,), round_mm=5.0)


def test_region_around_targets_with_margin_and_outside(region):
    assert region.x_mm == (410.0, 510.0) and region.y_mm == (-160.0, 210.0) and region.z_mm == (290.0, 350.0)
    off = region.outside(np.array([[400.0, 0.0, 300.0], [450.0, 0.0, 300.0], [450.0, 0.0, 360.0]]))
    assert off.tolist() == [[-10.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 10.0]]


def test_curvature_estimate_scales_with_the_square_of_the_step(robot, robots, region):
    c = curvature(robot, robots[:1], region, lattice=(3, 3, 2, 6))
    e1 = c.estimate([20.0, 20.0, 30.0, math.pi / 6])
    e2 = c.estimate([10.0, 10.0, 15.0, math.pi / 12])
    assert e1 > 0 and e2 == pytest.approx(e1 / 4, rel=1e-9)


def test_design_meets_the_bound_for_every_sampled_robot_within_capacity(robot, robots, region):
    d = design_table(robot, robots, region, 5.0, capacity=32000)
    assert d.feasible and d.n_values <= 32000
    assert len(d.bounds_um) == 3 and max(d.bounds_um) <= 5.0
    assert min(d.bounds_um) <= d.predicted_bound_um <= d.worst_bound_um
    # the bound is the one the run computes: over the cells the targets' boxes touch
    again = region.bound_um(build_correction_table(robot, robots[0], d.grid))
    assert again == pytest.approx(d.bounds_um[0], rel=1e-6)
    assert "predicted bound" in d.describe()


def test_no_grid_within_capacity_is_refused_with_what_would_fit(robot, robots, region):
    d = design_table(robot, robots, region, 0.05, capacity=2000)
    assert not d.feasible
    assert d.best_bound_um > 0.05  # the bound the finest grid within the capacity reaches
    assert d.region_scale is None or 0.1 <= d.region_scale < 1.0


def test_refine_for_the_identified_robot(robot, robots, region):
    coarse = design_table(robot, robots, region, 1000.0, capacity=32000, counts=(2, 2, 2, 4))
    tight = type(coarse)(**{**coarse.__dict__, "limit_um": 4.0})
    table, design, bound = refine_for(robot, robots[1], tight)
    assert np.prod(design.counts) > np.prod(coarse.counts)
    assert bound <= 4.0 and table.data.grid_shape == design.counts
