"""The motion guard (station.cell.limits.motion_guard): property-based tests of the safety invariants."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from station.cell.limits.motion_guard import MotionGuard
from station.core.table.values import CorrectionTableData, TableAxis
from station.errors import ConfigError, UnreachableError

LIMITS = np.array([[-2.0, 2.0], [-2.4, 2.4], [-190.0, -10.0], [-6.0, 6.0]])
finite = st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False)
anything = st.floats(allow_nan=True, allow_infinity=True)


@settings(max_examples=300, derandomize=True)
@given(st.lists(anything, min_size=4, max_size=4))
def test_a_joint_target_is_commanded_only_when_finite_and_inside(q):
    guard = MotionGuard(LIMITS)
    q = np.array(q)
    inside = bool(np.all(np.isfinite(q)) and np.all(q >= LIMITS[:, 0]) and np.all(q <= LIMITS[:, 1]))
    if inside:
        np.testing.assert_array_equal(guard.check_joints(q, "t"), q)
    else:
        with pytest.raises(UnreachableError, match="not commanded"):
            guard.check_joints(q, "t")


@settings(max_examples=200, derandomize=True)
@given(st.lists(st.tuples(anything, anything), min_size=1, max_size=6))
def test_limits_must_be_finite_and_ordered(pairs):
    lim = np.array(pairs, dtype=float)
    ok = bool(np.all(np.isfinite(lim)) and np.all(lim[:, 0] < lim[:, 1]))
    if ok:
        MotionGuard(lim)
    else:
        with pytest.raises(ConfigError, match="limits.joints: joint"):
            MotionGuard(lim)


@pytest.mark.parametrize("bad", [[math.nan, 2.0], [-2.0, math.inf], [2.0, -2.0], [1.0, 1.0]])
def test_nan_inf_or_swapped_limits_are_refused(bad):
    lim = LIMITS.copy()
    lim[0] = bad
    with pytest.raises(ConfigError, match="joint 1"):
        MotionGuard(lim)


def _table(delta_q1: float) -> CorrectionTableData:
    """A table over x 0..100, y 0..100, z 0..100, yaw (periodic) that adds ``delta_q1`` to joint 1."""
    axes = (TableAxis(0.0, 100.0, 2), TableAxis(0.0, 100.0, 2), TableAxis(0.0, 100.0, 2),
            TableAxis(-math.pi, math.pi / 2, 4, periodic=True))
    values = np.zeros((2, 2, 2, 2, 4, 4), dtype=np.float32)
    values[..., 0] = delta_q1
    return CorrectionTableData(axes, values)


@settings(max_examples=200, derandomize=True)
@given(q1=st.floats(-2.0, 2.0), delta=st.floats(-0.5, 0.5), x=st.floats(0.0, 100.0), yaw=finite)
def test_a_cartesian_target_is_checked_after_the_active_table(q1, delta, x, yaw):
    guard = MotionGuard(LIMITS)
    guard.table = _table(delta)
    q_nom = np.array([q1, 0.0, -50.0, 0.0])
    pose = np.array([x, 50.0, 50.0, 0.0, 0.0, yaw])
    corrected = q1 + np.float32(delta)
    if -2.0 <= corrected <= 2.0:
        q = guard.check_cartesian(pose, 1, q_nom, "t")
        assert q[0] == pytest.approx(corrected, abs=1e-6)
    else:  # inside nominally, outside after the correction: refused
        with pytest.raises(UnreachableError, match="joint 1"):
            guard.check_cartesian(pose, 1, q_nom, "t")


def test_a_cartesian_target_outside_the_table_or_not_finite_is_refused():
    guard = MotionGuard(LIMITS)
    guard.table = _table(0.1)
    with pytest.raises(UnreachableError, match="outside the active correction table"):
        guard.check_cartesian(np.array([500.0, 50.0, 50.0, 0, 0, 0]), 1, np.zeros(4) - [0, 0, 50, 0], "t")
    with pytest.raises(UnreachableError, match="six finite numbers"):
        guard.check_cartesian(np.array([50.0, math.nan, 50.0, 0, 0, 0]), 1, np.zeros(4), "t")
    guard.table = None  # without a table the nominal joints are what the controller commands
    np.testing.assert_array_equal(guard.check_cartesian(np.array([500.0, 0, 0, 0, 0, 0]), 1,
                                                        np.array([0.0, 0, -50, 0]), "t"), [0, 0, -50, 0])


def test_plan_refuses_a_point_whose_later_repetitions_would_leave_the_soft_limits():
    """A run approaches each point a little differently in each repetition and re-measure; the
    widest of those approaches must be inside the soft limits before anything moves, not only
    the first (the runner's motion guard would otherwise stop the run half way)."""
    import dataclasses

    from simulators import start_simulated_cell
    from simulators.reference_cell import cell_config_text
    from station.cell.config.cell_config import parse_text
    from station.cell.plan.measurement_plan import all_motion_poses, approach_pose, build_plan, widest_motion_poses

    with start_simulated_cell(seed=1) as sim:
        cfg = parse_text(cell_config_text(sim, 1))
    plan = build_plan(cfg)
    t = plan.verification[0]
    q = t.joints
    widest = widest_motion_poses(cfg, q)[0]
    last = max(cfg.plan.repeats, cfg.plan.verification_cycles) - 1
    assert np.all(np.abs(widest - q) >= np.abs(approach_pose(cfg, q, 1, last) - q) - 1e-12)
    # soft limits that admit the first approach of that point, not its widest one
    first = all_motion_poses(cfg, q)[0]
    j = 0  # joint 1 approaches from below: its widest approach is its lowest value
    assert widest[j] < first[j]
    soft = cfg.soft_limits.copy()
    soft[j, 0] = 0.5 * (widest[j] + first[j])
    tight = dataclasses.replace(cfg, soft_limits=soft)
    rejected = {(pid, e) for pid, e, _ in build_plan(tight).rejected}
    assert (t.point_id, t.elbow) in rejected
