"""A target at the table's edge, one node step inside it and one outside, per axis, through the
controller's interpolation (:func:`station.core.table.values.interpolate_table`, and the same rule at
one point, :meth:`CorrectionTableData.interpolate`) and through the motion guard that refuses a
Cartesian move the active table cannot correct (issue 42: an off-by-one in the cell index
survived every test).

Every node holds a different value, so a lower or upper node index one off reads a neighbour's
value and the comparison fails; a range check one step too wide lets the point one step outside
through, where it must be refused."""

from __future__ import annotations

import math

import numpy as np
import pytest

from station.cell.limits.motion_guard import MotionGuard
from station.core.table.values import CorrectionTableData, TableAxis, TableRangeError, interpolate_table
from station.errors import UnreachableError

#: x, y, z of different starts, steps and node counts, and yaw periodic (12 nodes, 30°)
AXES = (TableAxis(350.0, 30.0, 5), TableAxis(-250.0, 125.0, 4), TableAxis(250.0, 100.0, 3),
        TableAxis(-math.pi, math.pi / 6, 12, periodic=True))
#: interior node indices of the point's other coordinates (on nodes: their weights are 0 or 1)
ON = (2, 1, 1, 5)


def _table() -> CorrectionTableData:
    rng = np.random.default_rng(42)
    # distinct values of the order of a correction (0.1 mrad, 0.1 mm), every node its own
    values = rng.uniform(-1e-4, 1e-4, (2, *(a.count for a in AXES), 4))
    return CorrectionTableData(AXES, values)


def _point(axis: int, u: float) -> np.ndarray:
    """The point at node coordinate ``u`` along ``axis``, on the nodes ``ON`` along the others."""
    return np.array([a.start + a.step * (u if k == axis else ON[k]) for k, a in enumerate(AXES)])


def _node(table: CorrectionTableData, axis: int, i: int, config: int = 0) -> np.ndarray:
    idx = list(ON)
    idx[axis] = i
    return table.values[config][tuple(idx)]


def _both(table, point, config=0):
    """The production interpolation, vectorised and at one point."""
    got = interpolate_table(table, point[None], config)[0]
    np.testing.assert_allclose(got, table.interpolate(point, config), atol=1e-15)
    return got


@pytest.mark.parametrize("axis", [0, 1, 2])
@pytest.mark.parametrize("config", [0, 1])
def test_the_edges_and_one_step_inside_read_their_own_nodes(axis, config):
    table = _table()
    last = AXES[axis].count - 1
    for u in (0, 1, last - 1, last):  # both edges exactly, and one node step inside each
        np.testing.assert_allclose(_both(table, _point(axis, u), config), _node(table, axis, u, config),
                                   atol=1e-12, err_msg=f"axis {axis}, node {u}")
    # half a step inside each edge: the mean of the edge node and its neighbour
    for u, (i, j) in ((0.5, (0, 1)), (last - 0.5, (last - 1, last))):
        want = 0.5 * (_node(table, axis, i, config) + _node(table, axis, j, config))
        np.testing.assert_allclose(_both(table, _point(axis, u), config), want, atol=1e-12)


@pytest.mark.parametrize("axis", [0, 1, 2])
@pytest.mark.parametrize("u", [-1.0, -0.01, "last+0.01", "last+0.5", "last+1"])
def test_a_point_outside_the_table_is_refused_by_both_rules(axis, u):
    last = AXES[axis].count - 1
    u = float(u) if not isinstance(u, str) else last + float(u.split("+")[1])
    table = _table()
    point = _point(axis, u)
    with pytest.raises(TableRangeError, match=f"coordinate {axis} "):
        interpolate_table(table, point[None])
    with pytest.raises(TableRangeError, match=f"coordinate {axis} "):
        table.interpolate(point)


def test_the_tolerance_at_the_edges_is_a_millionth_of_a_step():
    # float32 node coordinates may sit a hair off the grid: 1e-7 step is the edge, 1e-5 outside
    table = _table()
    for axis in (0, 1, 2):
        last = AXES[axis].count - 1
        np.testing.assert_allclose(_both(table, _point(axis, last + 1e-7)), _node(table, axis, last), atol=1e-10)
        np.testing.assert_allclose(_both(table, _point(axis, -1e-7)), _node(table, axis, 0), atol=1e-10)
        for u in (last + 1e-5, -1e-5):
            with pytest.raises(TableRangeError):
                interpolate_table(table, _point(axis, u)[None])


def test_the_periodic_yaw_wraps_at_its_last_node():
    table = _table()
    n = AXES[3].count
    # node n is node 0 again, one turn further or back reads the same node
    for u in (0, n, -n, 2 * n):
        np.testing.assert_allclose(_both(table, _point(3, u)), _node(table, 3, 0), atol=1e-12)
    np.testing.assert_allclose(_both(table, _point(3, n - 1)), _node(table, 3, n - 1), atol=1e-12)
    # between the last node and the first: their mean, not a neighbour's
    want = 0.5 * (_node(table, 3, n - 1) + _node(table, 3, 0))
    np.testing.assert_allclose(_both(table, _point(3, n - 0.5)), want, atol=1e-12)
    np.testing.assert_allclose(_both(table, _point(3, -0.5)), want, atol=1e-12)


def _pose(point: np.ndarray) -> np.ndarray:
    return np.array([point[0], point[1], point[2], 0.0, 0.0, point[3]])


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_the_motion_guard_corrects_at_the_edge_and_refuses_one_step_outside(axis):
    table = _table()
    guard = MotionGuard(np.array([[-3.0, 3.0], [-3.0, 3.0], [-400.0, 0.0], [-7.0, 7.0]]))
    guard.table = table
    q_nominal = np.array([0.1, -0.2, -50.0, 0.3])
    last = AXES[axis].count - 1
    for u in (0, 1, last - 1, last):  # commanded: the nominal joints plus that node's correction
        for elbow, config in ((1, 0), (-1, 1)):
            q = guard.check_cartesian(_pose(_point(axis, u)), elbow, q_nominal, "t")
            np.testing.assert_allclose(q, q_nominal + _node(table, axis, u, config), atol=1e-12)
    for u in (-1, last + 1):  # one node step outside: not commanded
        with pytest.raises(UnreachableError, match="outside the active correction table"):
            guard.check_cartesian(_pose(_point(axis, u)), 1, q_nominal, "t")
