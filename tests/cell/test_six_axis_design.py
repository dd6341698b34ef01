"""The six-axis plan's design (issue 22): I-optimal selection of the identification poses, spread
held-out targets, and the example cell from a modified-DH robot file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from station.cell.config.cell_config import load_config
from station.cell.plan.articulated import MIN_HELD_OUT, NOISE_FRACTION
from station.cell.plan.measurement_plan import build_plan
from station.cell.plan.steps import StepKind
from station.core.identification.pose_design import select_i_optimal, spread_indices

PUMA = Path(__file__).resolve().parents[2] / "examples" / "puma560" / "cell.toml"


def _mean_variance(J: np.ndarray, G: np.ndarray, chosen) -> float:
    info = sum(J[i].T @ J[i] for i in chosen)
    C = np.linalg.inv(info)
    return float(np.mean(np.einsum("msp,pq,msq->m", G, C, G)))


def test_i_optimal_beats_a_random_design_of_the_same_size_at_the_working_poses():
    rng = np.random.default_rng(3)
    J = rng.normal(size=(80, 6, 8)) * rng.uniform(0.1, 2.0, (80, 1, 1))
    G = rng.normal(size=(15, 3, 8))
    d = select_i_optimal(J, G, 12)
    assert len(set(d.chosen)) == 12
    assert np.all(np.diff(d.mean_variance) <= 1e-12)  # each addition lowers the criterion
    best = _mean_variance(J, G, d.chosen)
    np.testing.assert_allclose(d.mean_variance[-1], best, rtol=1e-8)
    np.testing.assert_allclose(np.mean(d.sigma**2), best, rtol=1e-8)
    randoms = [_mean_variance(J, G, rng.choice(80, 12, replace=False)) for _ in range(50)]
    assert best < min(randoms)


def test_i_optimal_weighs_where_accuracy_is_wanted():
    # two parameters; candidates see one or the other; the working pose needs only the second
    J = np.zeros((10, 1, 2))
    J[:5, 0, 0] = 1.0
    J[5:, 0, 1] = 1.0
    G = np.array([[[0.0, 1.0]]])
    d = select_i_optimal(J, G, 6, prior=1e-3)
    # the D-optimal start takes one of each kind (2p/r = 4 picks), then only the second kind helps
    assert sum(1 for i in d.chosen[4:] if i >= 5) == 2


def test_spread_indices_cover_every_group_and_stay_apart():
    x = np.concatenate([np.linspace(0, 1, 20)[:, None], np.linspace(0, 1, 10)[:, None]])
    groups = np.array([0] * 20 + [1] * 10)
    idx = spread_indices(x, 4, groups)
    assert len(idx) == 4 and sorted(idx) == list(idx)
    assert {int(groups[i]) for i in idx} == {0, 1}
    first = sorted(float(x[i, 0]) for i in idx if groups[i] == 0)
    assert first[-1] - first[0] > 0.9  # the ends of the range, not neighbours
    assert spread_indices(x, 0) == ()


@pytest.fixture(scope="module")
def puma():
    cfg = load_config(PUMA)
    return cfg, build_plan(cfg)


@pytest.mark.xfail(strict=True, reason="issue 40: the PUMA 560 plan keeps configuration +1 only: every way to the "
                   "shoulder-back one passes joint 3 through the fold, where the wrist centre lies 1.7 mm from joint 2's "
                   "axis, inside the shoulder (tests/cell/test_puma_fold.py); the condition stays within 10 % (212.0 "
                   "against 222.5 unchecked) and the held-out σ in the body frame at 3.8 µm RMS, but the σ in the robot's "
                   "base frame rose from 29.8 to 46.3 µm")
def test_puma_from_a_modified_dh_file_identifies_the_full_model(puma):
    cfg, plan = puma
    assert cfg.model.name == "puma560" and cfg.model.n_joints == 6
    from station.cell.pipeline.preview import preview

    p = preview(cfg)
    assert len(p.identifiable) == 30  # 4·6 + 6: the MDH import keeps every axis tilt
    assert p.sigma_position_um[2] < 2 * cfg.identification.sigma_position_um


def test_puma_held_out_targets_are_spread_and_independent(puma):
    cfg, plan = puma
    ver = plan.verification
    assert len(ver) >= min(MIN_HELD_OUT, 16)
    # every configuration the plan measures (the PUMA's shoulder-back one is left out since issue 40:
    # every way to it folds the elbow past the shoulder, through the shoulder's collision capsule)
    assert {t.elbow for t in ver} == {t.elbow for t in plan.identification}
    assert len({cfg.point_ids[t.point][-1] for t in ver}) >= 3  # several corners, not one per cube
    ident = {(s.point, tuple(np.round(s.q, 9))) for s in plan.identification}
    assert not ident & {(t.point, tuple(np.round(t.joints, 9))) for t in ver}
    n = len({(s.point, tuple(s.joints)) for s in plan.identification})
    assert n == plan.design.n_poses <= cfg.plan.select


def test_i_optimal_stops_once_the_predicted_variance_is_enough():
    rng = np.random.default_rng(5)
    J = rng.normal(size=(120, 6, 8))
    G = rng.normal(size=(20, 3, 8))
    full = select_i_optimal(J, G, 60)
    enough = float(full.mean_variance[20])
    short = select_i_optimal(J, G, 60, enough=enough)
    assert short.chosen == full.chosen[:len(short.chosen)]  # the same greedy order, cut short
    assert short.mean_variance[-1] <= enough < short.mean_variance[-2]
    assert select_i_optimal(J, G, 60, enough=0.0).chosen == full.chosen


def test_puma_takes_poses_until_the_noise_rule_is_met(puma):
    cfg, plan = puma
    d = plan.design
    assert d.stopped_by == "noise" and d.n_parameters == 30 and d.repeats == cfg.plan.repeats
    assert d.min_poses < d.n_poses < cfg.plan.select  # the rule, not the cap, decided
    assert d.sigma_work_um <= NOISE_FRACTION * cfg.identification.sigma_position_um + 1e-9
    assert d.sigma_held_um[0] <= d.sigma_held_um[1] <= d.sigma_held_um[2] < 2 * d.target_um
    from station.cell.pipeline.preview import describe, preview

    text = "\n".join(describe(preview(cfg)))
    assert f"{d.n_poses} identification poses" in text and "30 identifiable parameters" in text
    assert "1/4 of the 15 µm measurement σ" in text
    assert f"predicted accuracy at the {len(plan.verification)} held-out targets" in text


def test_verification_passes_change_configuration_once_per_configuration(puma):
    cfg, plan = puma
    cycles = cfg.plan.verification_cycles
    steps = plan.run_steps(cycles, with_oracle=True)
    ident = [s for s in steps if s.kind is StepKind.IDENTIFICATION]
    ver = [s for s in steps if s.kind is not StepKind.IDENTIFICATION]
    n_conf = len({t.elbow for t in plan.verification})
    assert n_conf >= 1  # one on the PUMA since issue 40 (its shoulder-back configuration collides on the way)
    assert ver[0].elbow == ident[-1].elbow  # the verification begins where the identification ends
    switches = sum(1 for a, b in zip(ver, ver[1:]) if a.elbow != b.elbow)
    assert switches == 3 * (n_conf - 1)  # before, after, oracle: each joins the last where it ended
    for kind in (StepKind.VERIFY_BEFORE, StepKind.VERIFY_AFTER, StepKind.REFERENCE):
        mine = [(s.point, s.elbow, s.cycle) for s in ver if s.kind is kind]
        assert sorted(mine) == sorted((t.point, t.elbow, c) for t in plan.verification for c in range(cycles))
    # consecutive visits of one target come from separate passes over its configuration's targets
    for a, b in zip(ver, ver[1:]):
        assert (a.point, a.elbow) != (b.point, b.elbow)


def test_travel_order_for_time_shortens_the_largest_joint_move(puma):
    cfg, plan = puma
    from station.cell.plan.articulated import order_by_travel, order_for_time

    def seconds(ts):  # the move time's metric: the largest joint change
        q = np.array([t.joints for t in ts])
        return float(np.sum(np.max(np.abs(np.diff(q, axis=0)), axis=1)))

    ts = list(plan.verification)
    ordered = order_for_time(ts)
    assert sorted(id(t) for t in ordered) == sorted(id(t) for t in ts)
    assert seconds(ordered) < seconds(order_by_travel(ts))
