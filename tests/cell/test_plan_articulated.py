"""The built-in six-axis robot file and the plan for an articulated arm (issue 9)."""

from __future__ import annotations

import numpy as np
import pytest

from simulators.six_axis_cell import six_axis_cell, six_axis_config_text
from station.cell.config.cell_config import CellConfig, parse_text
from station.cell.plan.arm_motion import OUTWARD_DIAGONAL, retract_pose
from station.cell.plan.articulated import articulated_candidates, head_orientations
from station.cell.plan.measurement_plan import all_motion_poses, build_plan, order_by_travel, retracted
from station.core.identification.identifiability import analyze
from station.core.kinematics.forward import forward
from station.core.kinematics.ik import configuration
from station.core.kinematics.poses import spread_joints
from station.core.kinematics.transforms import invert, rotation_log
from station.core.measurement.measurements import synthetic_set
from station.core.probe.geometry import default_probe_head, readings_from_pose
from station.io.robot.files import builtin_robots, load_robot


class _Servers:
    """What six_axis_config_text reads of running servers (no servers needed to plan)."""

    def __init__(self, cell) -> None:
        self.cell = cell
        self.probe_port = "socket://127.0.0.1:1"
        self.controller_host = "127.0.0.1"
        self.controller_port = 1502


@pytest.fixture(scope="module")
def cfg() -> CellConfig:
    return parse_text(six_axis_config_text(_Servers(six_axis_cell(1)), 1), "<six-axis test>")


@pytest.fixture(scope="module")
def plan(cfg):
    return build_plan(cfg)


# --- the robot file -----------------------------------------------------------------------------

def _flange(model, q_deg) -> np.ndarray:
    """World←tool0 (A6's joint frame): the chain without the head K."""
    p = model.nominal.copy()
    p[-6:] = 0.0
    return forward(model, np.deg2rad(np.atleast_2d(q_deg)), params=p, setup=False)[0]


def test_irb2600_is_built_in_with_the_data_sheet_geometry():
    assert "irb2600" in builtin_robots()
    m = load_robot("irb2600")
    assert m.joint_types == ("revolute",) * 6 and not m.is_scara
    np.testing.assert_allclose(np.degrees(m.joint_limits),
                               [[-180, 180], [-95, 155], [-180, 75], [-400, 400], [-120, 120], [-400, 400]])
    # zeros: upper arm vertical, forearm horizontal; flange at a1 + d4 + d6 forward, d1 + a2 + a3 up,
    # tool0 z out of the flange (base +x), x down (ABB's tool0)
    T = _flange(m, [0, 0, 0, 0, 0, 0])
    np.testing.assert_allclose(T[:3, 3], [150 + 795 + 85, 0, 445 + 700 + 115], atol=1e-9)
    np.testing.assert_allclose(T[:3, 2], [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(T[:3, 0], [0, 0, -1], atol=1e-12)
    # axis 2 forward by 90°: the upper arm lies forward, the forearm hangs down
    T = _flange(m, [0, 90, 0, 0, 0, 0])
    np.testing.assert_allclose(T[:3, 3], [150 + 700 + 115, 0, 445 - 795 - 85], atol=1e-9)
    # axis 3 up by 90° (negative): the forearm points up, the a3 offset backwards
    T = _flange(m, [0, 0, -90, 0, 0, 0])
    np.testing.assert_allclose(T[:3, 3], [150 - 115, 0, 445 + 700 + 795 + 85], atol=1e-9)
    # axis 5 down by 90°: the flange points down from the wrist centre
    T = _flange(m, [0, 0, 0, 0, 90, 0])
    np.testing.assert_allclose(T[:3, 3], [150 + 795, 0, 1260 - 85], atol=1e-9)
    np.testing.assert_allclose(T[:3, 2], [0, 0, -1], atol=1e-12)
    # axis 1 turns the arm about the vertical
    T = _flange(m, [90, 0, 0, 0, 0, 0])
    np.testing.assert_allclose(T[:3, 3], [0, 1030, 1260], atol=1e-9)
    # the reach: the wrist centre stretched is a1 + a2 + sqrt(a3² + d4²) ≈ 1.65 m from axis 2's line
    assert 150 + 700 + np.hypot(115, 795) == pytest.approx(1653.3, abs=0.1)


@pytest.mark.parametrize(("objective", "count"), [("pose", 30), ("position", 25), ("distance", 19)])
def test_irb2600_identifiable_counts(objective, count):
    """30 from poses; 25 from positions and 19 from distances with the head origin on axis 6."""
    from station.core.measurement.distance_pairs import make_pairs

    m = load_robot("irb2600")
    assert m.minimal_param_count == 30
    q = spread_joints(m, 40, np.random.default_rng(3))
    pairs = make_pairs(len(q), "cap", cap=300, seed=3) if objective == "distance" else None
    a = analyze(m, synthetic_set(m, objective, q, m.nominal, pairs=pairs), prefer=m.prefer)
    assert a.rank == count
    # the preferred, physically readable set is taken where it raises the rank
    if objective == "pose":
        assert {"K.x", "K.y", "K.z", "K.roll", "K.pitch", "K.yaw", "A2.x", "A3.y", "A4.x", "A4.y",
                "A2.pitch", "A3.yaw", "A4.pitch", "A5.pitch"} <= set(a.chosen)


# --- head orientations and motion ---------------------------------------------------------------

def test_head_orientations_turn_about_the_corner_within_the_stroke(cfg):
    Ms = head_orientations(cfg)
    head = default_probe_head(cube_edge_mm=cfg.cube_edge_mm)
    M0 = head.nominal_contact_pose()
    np.testing.assert_allclose(Ms[0], M0)
    assert len(Ms) >= 5
    angles = []
    for M in Ms:
        np.testing.assert_allclose(M[:3, 3], M0[:3, 3], atol=1e-12)  # the corner stays where it was
        angles.append(np.degrees(np.linalg.norm(rotation_log(M0[:3, :3].T @ M[:3, :3]))))
        r = readings_from_pose(head, M)
        assert np.all(np.abs(r) < 0.5 * head.stroke_mm - 2.5), r  # well inside the ±5 mm stroke
    assert max(angles) <= 5.0 and sorted(set(np.round(angles[1:], 6))) != [0.0]
    # one pair turns about the diagonal itself
    axes = [rotation_log(M0[:3, :3].T @ M[:3, :3]) for M in Ms[1:]]
    assert any(abs(abs(a @ OUTWARD_DIAGONAL) - np.linalg.norm(a)) < 1e-9 for a in axes)


def test_every_motion_retracts_along_the_diagonal_and_arrives_from_below(cfg, plan):
    st = plan.identification[0]
    q = st.q
    retract, short, target = all_motion_poses(cfg, q)
    np.testing.assert_array_equal(target, q)
    assert np.all(target - short > 0)  # every joint's last move is positive (from below)
    T = forward(cfg.model, np.stack([q, retract]), setup=True)
    np.testing.assert_allclose(T[1][:3, :3], T[0][:3, :3], atol=1e-9)  # orientation kept
    M = default_probe_head(cube_edge_mm=cfg.cube_edge_mm).nominal_contact_pose()
    d = T[1][:3, 3] - T[0][:3, 3]
    np.testing.assert_allclose(d, T[0][:3, :3] @ M[:3, :3] @ OUTWARD_DIAGONAL * cfg.plan.clearance_mm, atol=1e-6)
    # away from the cube: the corner's outward diagonal points up and out of the body
    assert d[2] > 0
    # retracting from the touch retracts; retracting again, or from a travel pose, does not move
    np.testing.assert_allclose(retracted(cfg, q), retract, atol=1e-9)
    np.testing.assert_array_equal(retracted(cfg, retract), retract)
    np.testing.assert_allclose(retract_pose(cfg, q), retract, atol=1e-12)


# --- the plan -----------------------------------------------------------------------------------

def test_plan_visits_orientations_and_configurations_at_the_corners(cfg, plan):
    Ms = head_orientations(cfg)
    seen_orient = set()
    codes = set()
    for st in plan.identification:
        T = forward(cfg.model, st.q[None], setup=True)[0]
        M = invert(T) @ cfg.body_points[st.point]  # the contact the nominal robot makes
        k = int(np.argmin([np.linalg.norm(M - Mk) for Mk in Ms]))
        np.testing.assert_allclose(M, Ms[k], atol=1e-6)
        seen_orient.add(k)
        codes.add(st.elbow)
        assert np.all(st.q >= cfg.soft_limits[:, 0]) and np.all(st.q <= cfg.soft_limits[:, 1])
        conf = configuration(cfg.model, st.q[None])[0]
        assert st.elbow * (1 if conf[1] > 0 else -1) > 0  # the code's sign is the elbow
    assert seen_orient == set(range(len(Ms)))
    assert len(codes) >= 2  # the wrist flips at least
    # verification: the nominal orientation only, several configurations
    assert plan.verification
    for t in plan.verification:
        M = invert(forward(cfg.model, t.joints[None], setup=True)[0]) @ cfg.body_points[t.point]
        np.testing.assert_allclose(M, Ms[0], atol=1e-6)
    ident_targets = {(s.point, tuple(np.round(s.q, 9))) for s in plan.identification}
    assert not ident_targets & {(t.point, tuple(np.round(t.joints, 9))) for t in plan.verification}


def test_plan_is_deterministic_and_the_selection_keeps_the_model_identifiable(cfg, plan):
    again = build_plan(cfg)
    assert [s.to_record() for s in again.identification] == [s.to_record() for s in plan.identification]
    n = cfg.plan.select
    distinct = {(s.point, tuple(s.joints)) for s in plan.identification}
    assert len(distinct) == n  # [plan] select = N: the N most informative candidates
    q = np.array([s.q for s in plan.identification[:n]])
    a = analyze(cfg.model, synthetic_set(cfg.model, "pose", q, cfg.model.nominal, sigma=cfg.identification.pose_sigma()))
    assert a.rank == 30


def test_travel_order_is_shorter_than_the_candidate_order(cfg):
    cands, _orient, _rej = articulated_candidates(cfg)

    def travel(ts):
        q = np.array([t.joints for t in ts])
        return float(np.sum(np.abs(np.diff(q, axis=0))))

    ordered = order_by_travel(cands)
    assert sorted(id(t) for t in ordered) == sorted(id(t) for t in cands)
    shuffled = [cands[i] for i in np.random.default_rng(0).permutation(len(cands))]
    assert travel(ordered) < 0.7 * travel(cands)
    assert travel(ordered) < 0.3 * travel(shuffled)
