"""Correction tables (station.core.table.build, table_grid) and compensated targets
(station.core.kinematics.compensation)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from drivers.correction_table import MAX_TABLE_VALUES
from station.core.kinematics.compensation import compensated_targets
from station.core.kinematics.forward import forward, scara_ik
from station.core.kinematics.model import RobotModel, TransformSpec
from station.core.kinematics.transforms import pose_to_matrix, rotation_log
from station.core.table.build import build_correction_table, interpolation_error
from station.core.table.grid import GridSpec
from station.core.table.values import TableRangeError, interpolate_table
from station.core.units import ARCSEC, wrap_angle
from station.errors import ConfigError
from station.io.robot.files import load_robot

ARCMIN = math.pi / (180 * 60)


@pytest.fixture(scope="module")
def robot():
    return load_robot("sr800")


def perturbed(robot, seed=1, length_mm=0.04, angle_rad=2.5 * ARCMIN):
    """Identified parameters as the simulated cell's truth draws them (plus a set-up)."""
    rng = np.random.default_rng(seed)
    e = np.zeros((6, 6))
    e[1:, :3] = rng.normal(0.0, length_mm, (5, 3))
    e[1:, 3:] = rng.normal(0.0, angle_rad, (5, 3))
    e[0] = [-550.0, 3.0, -200.0, 0.001, -0.002, 0.3]  # R must not matter
    return robot.nominal + e.ravel()


@pytest.fixture(scope="module")
def identified(robot):
    return perturbed(robot)


@pytest.fixture(scope="module")
def table(robot, identified):
    return build_correction_table(robot, identified, GridSpec())


def random_points(grid: GridSpec, n, rng):
    return np.column_stack([rng.uniform(*grid.x_range, n), rng.uniform(*grid.y_range, n),
                            rng.uniform(*grid.z_range, n), rng.uniform(-math.pi, math.pi, n)])


def targets(points):
    pose = np.zeros((len(points), 6))
    pose[:, :3] = points[:, :3]
    pose[:, 5] = points[:, 3]
    return pose_to_matrix(pose)


# --- grid -------------------------------------------------------------------------------------

def test_default_grid_shape_and_size(table):
    g = GridSpec()
    assert g.shape == (11, 15, 2, 12)
    assert g.n_values(4) == 31680 <= MAX_TABLE_VALUES
    d = table.data
    assert d.values.shape == (2, 11, 15, 2, 12, 4)
    assert d.values.dtype == np.float32
    assert d.n_values == table.n_values == 31680
    assert [a.count for a in d.axes] == [11, 15, 2, 12]
    assert [a.periodic for a in d.axes] == [False, False, False, True]
    assert d.axes[0].start == 350.0 and d.axes[0].step == 30.0
    assert d.axes[1].start + d.axes[1].step * 14 == pytest.approx(250.0, abs=1e-4)


@pytest.mark.parametrize("kw, match", [
    (dict(x_step=70.0), "whole number"),
    (dict(x_step=-1.0), "step must be"),
    (dict(x_range=(700.0, 350.0)), "low, high"),
    (dict(yaw_step=1.0), "does not divide a full turn"),
    (dict(yaw_range=(0.0, 3.0)), "full turn"),
    (dict(elbows=(-1,)), "elbows"),
    (dict(elbows=(-1, 1)), "elbows"),
    (dict(x_range=(float("nan"), 650.0)), "finite"),
])
def test_grid_validation(kw, match):
    with pytest.raises(ConfigError, match=match):
        GridSpec(**kw)


def test_grid_over_capacity_is_refused(robot, identified):
    g = GridSpec(x_step=10.0)
    with pytest.raises(ConfigError, match="exceeds the controller's 32000"):
        build_correction_table(robot, identified, g, capacity=MAX_TABLE_VALUES)


def test_the_table_resolution_is_the_wire_resolution():
    """The core holds a table on the grid the register map carries it on (station.core.table.values's
    docstring): the two statements of the format must agree, or a read back would not compare."""
    from drivers import controller_map as cm
    from station.core.table import values as td

    assert td.VALUE_RESOLUTION == cm.TABLE_VALUE_SCALE and td.AXIS_RESOLUTION == cm.TABLE_AXIS_SCALE
    assert td.MAX_AXES == cm.MAX_TABLE_AXES


def test_a_table_over_the_controller_capacity_is_refused_before_sending():
    from drivers.correction_table import TableError, check_payload, header_registers
    from station.core.table.values import CorrectionTableData, TableAxis

    big = CorrectionTableData((TableAxis(0.0, 1.0, MAX_TABLE_VALUES + 1),), np.zeros((1, MAX_TABLE_VALUES + 1, 1)))
    with pytest.raises(TableError, match="holds at most 32000"):
        check_payload(big)
    with pytest.raises(TableError, match="holds at most 32000"):
        header_registers(big)


def test_full_workspace_grid_fits():
    g = GridSpec.full_workspace()
    assert g.x_range == (350.0, 750.0) and g.n_values(4) <= MAX_TABLE_VALUES


def test_non_scara_is_refused(robot, identified):
    six = RobotModel("six", (TransformSpec("R"),) + tuple(TransformSpec(f"A{i}", "revolute") for i in range(6))
                     + (TransformSpec("K"),), np.zeros(48), np.tile([-3.0, 3.0], (6, 1)))
    with pytest.raises(ConfigError, match="compensated_targets"):
        build_correction_table(six, np.zeros(48))


# --- values -----------------------------------------------------------------------------------

def test_zero_correction_for_the_nominal_robot(robot):
    t = build_correction_table(robot, robot.nominal, GridSpec(), n_check=200)
    assert np.max(np.abs(t.data.values)) < 1e-9
    assert t.unreachable_nodes == 0
    assert t.interpolation_bound_um < 1e-3


def test_node_values_are_ik_differences(robot, identified, table):
    axes = table.data.axes
    rng = np.random.default_rng(3)
    for _ in range(10):
        i = [int(rng.integers(a.count)) for a in axes]
        c = int(rng.integers(2))
        p = np.array([[a.nodes[k] for a, k in zip(axes, i)]])
        elbow = (1, -1)[c]
        q_id = scara_ik(robot, targets(p), elbow, identified, check_limits=False)
        q_nom = scara_ik(robot, targets(p), elbow, robot.nominal, check_limits=False)
        d = q_id - q_nom
        d[:, [0, 1, 3]] = wrap_angle(d[:, [0, 1, 3]])
        np.testing.assert_allclose(table.data.values[(c, *i)], d[0], atol=5.1e-9, rtol=1e-6)  # values on the wire's 1e-8 grid


def test_revolute_corrections_are_wrapped(table):
    # the yaw axis has a node at −π: raw q4 differences there would jump by 2π
    assert table.data.axes[3].start == pytest.approx(-math.pi, abs=1e-6)
    assert np.max(np.abs(table.data.values[..., [0, 1, 3]])) < 0.02
    assert table.max_correction.shape == (4,)
    assert np.all(table.max_correction[[0, 1, 3]] < 0.02)


def test_the_stations_interpolation_is_the_programs_rule(table):
    """The station's one implementation of the rule against the simulated robot program's own,
    written again from docs/protocols.md (simulators.program_words), on a built table: random
    points, yaw wrapped by whole turns, the exact corner nodes, and one node step outside."""
    from simulators.program_words import OutsideTable, ProgramAxis, ProgramTable

    rng = np.random.default_rng(5)
    g = GridSpec()
    pts = random_points(g, 50, rng)
    pts[:5, 3] += 2 * math.pi * rng.integers(-2, 3, 5)  # yaw outside (−π, π] wraps
    pts[5] = [350.0, -250.0, 250.0, -math.pi]  # exact corner nodes
    pts[6] = [650.0, 250.0, 450.0, math.pi]
    program = ProgramTable(tuple(ProgramAxis(round(a.start / 1e-6), round(a.step / 1e-6), a.count, a.periodic)
                                 for a in table.data.axes),
                           np.round(table.data.values.astype(np.float64) / 1e-8).astype(np.int64))
    for c in (0, 1):
        got = interpolate_table(table.data, pts, c)
        want = np.array([program.correction(p, c) for p in pts])
        # the program weighs counts × 1e-8 in float64, the station the float32 it holds: they
        # differ by float32's rounding of the value (≤ 6e-8 relative), far below a nanoradian
        np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-12)
        np.testing.assert_allclose(table.data.interpolate(pts[3], c), got[3], rtol=0, atol=0)
    x = table.data.axes[0]
    outside = np.array([[x.start + x.step * x.count, 0.0, 350.0, 0.0]])  # one node past the last
    with pytest.raises(OutsideTable):
        program.correction(outside[0], 0)
    with pytest.raises(TableRangeError):
        interpolate_table(table.data, outside, 0)


# --- interpolation error and its bound --------------------------------------------------------

def test_reported_bound_meets_the_design_target(table):
    assert table.unreachable_nodes == 0
    assert 0.0 < table.interpolation_bound_um < 5.0
    assert table.interpolation_bound_arcsec < 1.0
    assert table.check is not None and table.check.n_points > 4000


def test_corrected_robot_reaches_nominal_targets_within_bound(robot, identified, table):
    """The controller's rule, point by point: q = IK_nom + CorrectionTableData.interpolate."""
    rng = np.random.default_rng(11)
    pts = random_points(GridSpec(), 200, rng)
    for c, elbow in enumerate((1, -1)):
        T = targets(pts)
        q_nom = scara_ik(robot, T, elbow, robot.nominal, check_limits=False)
        corr = np.array([table.data.interpolate(p, c) for p in pts])
        reached = forward(robot, q_nom + corr, identified, setup=False)
        err_um = np.linalg.norm(reached[:, :3, 3] - T[:, :3, 3], axis=1) * 1e3
        assert err_um.max() <= table.interpolation_bound_um
        # yaw reached to the bound too (roll/pitch follow the axis tilts and are not corrected)
        exact = forward(robot, scara_ik(robot, T, elbow, identified, check_limits=False), identified,
                        setup=False)
        ang = np.linalg.norm(rotation_log(reached[:, :3, :3] @ np.swapaxes(exact[:, :3, :3], -1, -2)),
                             axis=1) / ARCSEC
        assert ang.max() <= table.interpolation_bound_arcsec
        # ... while without the table the robot misses by far more
        raw = forward(robot, q_nom, identified, setup=False)
        assert np.median(np.linalg.norm(raw[:, :3, 3] - T[:, :3, 3], axis=1)) * 1e3 > 50 * table.interpolation_bound_um


@pytest.mark.parametrize("seed", [2, 3])
def test_bound_holds_at_fresh_random_points(robot, seed):
    p = perturbed(robot, seed)
    t = build_correction_table(robot, p, GridSpec(), seed=seed)
    fresh = interpolation_error(t, robot, p, n_samples=6000, rng=np.random.default_rng(1000 + seed),
                                cell_centres=False)
    assert fresh.n_points == 6000
    assert fresh.max_position_um <= t.interpolation_bound_um
    assert fresh.max_orientation_arcsec <= t.interpolation_bound_arcsec
    assert 0 < fresh.rms_position_um < fresh.max_position_um
    assert len(fresh.worst) == 5


def test_bound_scales_with_grid_density(robot, identified, table):
    coarse = build_correction_table(robot, identified, GridSpec(x_step=60.0, y_step=500 / 7),
                                    n_check=500)
    assert coarse.interpolation_bound_um > 2 * table.interpolation_bound_um


def test_bound_at_per_target(robot, identified, table):
    rng = np.random.default_rng(2)
    pts = random_points(GridSpec(), 100, rng)
    b = table.bound_at(pts, elbow=-1)
    assert b.shape == (100,) and np.all(b <= table.interpolation_bound_um + 1e-12) and np.all(b > 0)


def test_unreachable_nodes_get_the_nearest_reachable_value(robot, identified):
    # x up to 850 mm lies beyond the 800 mm reach: those nodes are unreachable
    g = GridSpec(x_range=(350.0, 850.0), x_step=50.0, y_range=(-100.0, 100.0), y_step=50.0,
                 yaw_step=2 * math.pi / 4)
    t = build_correction_table(robot, identified, g, n_check=500)
    assert t.unreachable_nodes > 0
    assert t.unreachable_nodes == int((~t.reachable).sum())
    assert np.all(t.reachable[:, :8])  # x ≤ 700 reachable everywhere
    assert not np.any(t.reachable[:, 10])  # x = 850 nowhere
    v = t.data.values
    ix, iy, iz, iw = 10, 2, 1, 3
    assert not t.reachable[0, ix, iy, iz, iw]
    # nearest reachable node along x (index distance) holds the same value
    last = max(i for i in range(11) if t.reachable[0, i, iy, iz, iw])
    np.testing.assert_array_equal(v[0, ix, iy, iz, iw], v[0, last, iy, iz, iw])
    assert np.all(np.isfinite(v))
    assert math.isfinite(t.interpolation_bound_um)  # over the fully reachable cells


def test_grid_without_reachable_nodes(robot, identified):
    g = GridSpec(x_range=(900.0, 1000.0), x_step=50.0)
    with pytest.raises(ConfigError, match="no node"):
        build_correction_table(robot, identified, g, n_check=10)


def test_single_elbow_table(robot, identified):
    t = build_correction_table(robot, identified, GridSpec(elbows=(1,)), n_check=200)
    assert t.data.n_configs == 1 and t.data.values.shape[0] == 1


# --- compensated targets ----------------------------------------------------------------------

def test_compensated_targets_scara(robot, identified):
    rng = np.random.default_rng(4)
    pts = random_points(GridSpec(z_range=(250.0, 420.0), z_step=170.0), 20, rng)  # h3 ≤ 0
    T = targets(pts)
    q0 = np.zeros((20, 4))
    q0[:10, 1], q0[10:, 1] = 1.0, -1.0
    res = compensated_targets(robot, identified, T, q0)
    assert res.residual_um.max() < 1e-3
    assert np.all(np.sign(res.joints[:, 1]) == np.sign(q0[:, 1]))
    # the nominal controller given the commands solves to the same joints, so the real robot
    # ends on the intended target
    for e, sel in ((1, slice(0, 10)), (-1, slice(10, 20))):
        q_ctl = scara_ik(robot, res.commands[sel], e, robot.nominal)
        np.testing.assert_allclose(q_ctl, res.joints[sel], atol=1e-9)
        reached = forward(robot, q_ctl, identified, setup=False)
        np.testing.assert_allclose(reached[:, :3, 3], T[sel][:, :3, 3], atol=1e-6)


def test_compensated_targets_in_measurement_frame(robot, identified):
    T_base = targets(np.array([[500.0, 50.0, 300.0, 0.4]]))
    T_world = pose_to_matrix(identified[:6]) @ T_base
    res = compensated_targets(robot, identified, T_world, [[0.0, 1.0, 0.0, 0.0]], setup=True)
    reached = forward(robot, res.joints, identified, setup=True)
    np.testing.assert_allclose(reached[0, :3, 3], T_world[0, :3, 3], atol=1e-6)


def _six_axis():
    """A 6R arm (PUMA-like) in the six-parameter form."""
    specs = (TransformSpec("R"),) + tuple(TransformSpec(f"A{i + 1}", "revolute") for i in range(6)) + (
        TransformSpec("K"),)
    p = np.zeros((8, 6))
    p[1] = [0, 0, 400, 0, 0, 0]
    p[2] = [0, 0, 0, -math.pi / 2, 0, 0]
    p[3] = [450, 0, 0, 0, 0, 0]
    p[4] = [0, 400, 0, -math.pi / 2, 0, 0]  # wrist
    p[5] = [0, 0, 0, math.pi / 2, 0, 0]
    p[6] = [0, 0, 0, -math.pi / 2, 0, 0]
    p[7] = [0, 0, 100, 0, 0, 0]
    return RobotModel("six", specs, p.ravel(), np.tile([-3.0, 3.0], (6, 1)))


def test_compensated_targets_six_axes():
    six = _six_axis()
    rng = np.random.default_rng(8)
    ident = six.nominal.copy()
    ident[6:] += np.where(six.is_angle()[6:], rng.normal(0, 2 * ARCMIN, 42), rng.normal(0, 0.1, 42))
    q_true = rng.uniform(-0.8, 0.8, (10, 6)) + np.array([0, -0.3, 0.5, 0, 0.7, 0])
    T = forward(six, q_true, six.nominal, setup=False)  # targets the nominal model reaches
    res = compensated_targets(six, ident, T, q_true)
    reached = forward(six, res.joints, ident, setup=False)
    np.testing.assert_allclose(reached[:, :3, 3], T[:, :3, 3], atol=1e-6)
    assert res.residual_um.max() < 1e-3
    np.testing.assert_allclose(res.commands, forward(six, res.joints, six.nominal, setup=False))
    # a controller without correction would miss by the model error
    assert np.max(np.linalg.norm(res.commands[:, :3, 3] - T[:, :3, 3], axis=1)) > 0.05


# --- error terms beyond geometry in the table (issue 30) -----------------------------------------

def harmonics(amp_arcsec=((20.0, -10.0), (-8.0, 15.0), (0.0, 0.0), (0.0, 0.0))):
    """A gear harmonic of joints 1 and 2 at the commanded joints: δ(q) = a cos q + b sin q [rad]."""
    ab = np.asarray(amp_arcsec) * ARCSEC

    def delta(q):
        q = np.asarray(q, dtype=float)
        return ab[:, 0] * np.cos(q) * [1, 1, 0, 1] + ab[:, 1] * np.sin(q) * [1, 1, 0, 1]

    return delta


def test_a_node_with_terms_puts_the_robot_with_its_terms_on_target(robot, identified):
    """The fixed point q = IK_identified(T) − δ(q): the robot standing at q + δ(q) reaches every
    target to 1e-9 mm, where the geometric IK's joints miss by the terms' effect."""
    from station.core.table.build import node_joints

    delta = harmonics()
    T = targets(random_points(GridSpec(), 300, np.random.default_rng(21)))
    for elbow in (1, -1):
        q, ok = node_joints(robot, identified, T, elbow, delta)
        assert ok.all()
        reached = forward(robot, q + delta(q), identified, setup=False)
        assert np.max(np.linalg.norm(reached[:, :3, 3] - T[:, :3, 3], axis=1)) < 1e-9
        q_geo, _ = node_joints(robot, identified, T, elbow)
        exact = forward(robot, q_geo, identified, setup=False)  # the orientation the IK reaches (yaw; tilts uncorrectable)
        ang = np.linalg.norm(rotation_log(reached[:, :3, :3] @ np.swapaxes(exact[:, :3, :3], -1, -2)), axis=1)
        assert ang.max() < 1e-12
        missed = forward(robot, q_geo + delta(q_geo), identified, setup=False)
        assert np.median(np.linalg.norm(missed[:, :3, 3] - T[:, :3, 3], axis=1)) > 0.01  # mm


def test_a_table_with_terms_corrects_the_robot_with_its_terms_within_its_bound(robot, identified):
    delta = harmonics()
    grid = GridSpec(x_step=60.0, y_step=500 / 7)
    t = build_correction_table(robot, identified, grid, n_check=400, delta=delta)
    geo = build_correction_table(robot, identified, grid, n_check=400)
    assert t.with_terms and not geo.with_terms
    # the node values: the joints at which the robot with its terms reaches the node, minus the nominal IK
    p = np.array([[a.nodes[k] for a, k in zip(t.data.axes, (2, 3, 0, 5))]])
    q_nom = scara_ik(robot, targets(p), 1, robot.nominal, check_limits=False)
    q = q_nom + t.data.values[(0, 2, 3, 0, 5)]
    np.testing.assert_allclose(forward(robot, q + delta(q), identified, setup=False)[0, :3, 3],
                               targets(p)[0, :3, 3], atol=2e-5)  # mm: the wire's 1e-8 rad steps
    # the bound is the robot's with its terms: it holds at fresh points (the table's own δ) ...
    fresh = interpolation_error(t, robot, identified, n_samples=1500, rng=np.random.default_rng(7),
                                cell_centres=False)
    assert fresh.max_position_um <= t.interpolation_bound_um
    # ... where the geometric table leaves the terms' whole effect on the same robot
    missed = interpolation_error(geo, robot, identified, n_samples=1500, rng=np.random.default_rng(7),
                                 cell_centres=False, delta=delta)
    assert missed.rms_position_um > 5 * fresh.rms_position_um and missed.max_position_um > 20.0
