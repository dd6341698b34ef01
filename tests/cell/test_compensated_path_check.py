"""An articulated arm's verification path as the controller will move it (issue 40): its correction is
no table but compensated Cartesian targets, whose joints (the controller's nominal inverse kinematics of
the command) differ from the plan's by the identified errors, a path the pre-motion check never saw.
Before any verification motion the run checks the remaining steps at those joints, from where the step
before them leaves the robot (station/cell/plan/moved_path/compensated_check.py), and refuses a path that collides,
as a SCARA's shifted table path (tests/cell/test_shifted_path_check.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from station.cell.config.cell_config import parse_text
from station.cell.pipeline.articulated import articulated_targets
from station.cell.pipeline.outcomes import classify, hint_for
from station.cell.plan.measurement_plan import above_offset, build_plan
from station.cell.plan.moved_path.compensated_check import check_compensated, compensated_path, standing_at
from station.cell.plan.moved_path.shifted_check import ShiftedPathCollides, preceding, remeasures
from station.cell.plan.run_path import check_plan
from station.cell.plan.steps import StepKind
from station.errors import Outcome

pytest.importorskip("fcl")

CELL = Path(__file__).resolve().parents[2] / "examples" / "puma560" / "cell.toml"

#: the example's plan, one repetition and one verification cycle (tests/short_plan.py's idea: this
#: example's plan lines are its own)
SHORT = {"repeats = 2": "repeats = 1", "verification_cycles = 3": "verification_cycles = 1"}

#: a 10 mm cube of a post beside the head's mount at the verification touch of P1c (elbow +1), 31 mm
#: from the head frame's origin along the way a joint-1 zero error of +0.15° moves the compensated head
#: there (1.9 mm), 50 mm over it: the nominal path clears it by 2.7 mm, over the 2 mm margin, the
#: compensated one by 1.8 mm
POST = """
[[obstacle]]
name = "post"
shape = "box"
frame = "body"
pose = [126.455, -256.252, 150.0, 0.0, 0.0, 0.0]
size_mm = [10.0, 10.0, 10.0]
"""


def _cell(extra: str = ""):
    text = CELL.read_text(encoding="utf-8")
    for old, new in SHORT.items():
        assert old in text, f"the example has no {old!r} to shorten"
        text = text.replace(old, new)
    cfg = parse_text(text + extra, str(CELL))
    plan = build_plan(cfg)
    return cfg, plan, plan.run_steps(cfg.plan.verification_cycles, False)


def _joint1_error(cfg, deg: float) -> np.ndarray:
    """The robot's parameters with joint 1's zero off by ``deg`` (A1's rotation about its z)."""
    p = np.array(cfg.model.nominal, dtype=float)
    p[cfg.model.param_names.index("A1.yaw")] += np.radians(deg)
    return p


@pytest.fixture(scope="module")
def post_cell():
    return _cell(POST)


def test_compensated_targets_that_push_a_verification_touch_into_an_obstacle_are_refused(post_cell):
    cfg, plan, steps = post_cell
    R = cfg.model.nominal[:6]
    # the pre-motion check passes: the plan's path at its nominal joints clears the post over the margin
    pre = check_plan(cfg, plan)
    assert pre.clash is None
    # no error to compensate: the targets are the plan's joints, the path as planned, clear
    zero = articulated_targets(cfg, steps, cfg.model.nominal, R)
    first = next(st for st in steps if st.kind is StepKind.VERIFY_AFTER and st.label == "P1c elbow +1")
    np.testing.assert_allclose(zero[first.point, first.elbow][0], first.q, atol=1e-7)
    clear = check_compensated(cfg, steps, zero, {StepKind.VERIFY_AFTER})
    assert clear is not None and clear.clash is None and clear.vias > 0
    post = dict(clear.by_step)[first.index]
    assert post is not None and "post" in post.b and cfg.plan.collision_margin_mm < post.clearance_mm < 4.0
    # +0.15° of joint 1's zero: the controller's joints for the compensated command, each pose as the runner moves it
    large = articulated_targets(cfg, steps, _joint1_error(cfg, 0.15), R)
    q = large[first.point, first.elbow][0]
    assert abs(np.degrees(q - first.q)[0]) == pytest.approx(0.15, abs=1e-6)
    path = compensated_path(cfg, [first], large)
    assert [p[1] for p in path] == [f"step {first.index + 1} ({first.label}): {w}"
                                    for w in ("approach", "above the point", "touch", "retract")]
    np.testing.assert_allclose(path[2][0], q)
    np.testing.assert_allclose(path[1][0], q + above_offset(cfg, first.cycle))  # short of it by the approach offset
    np.testing.assert_allclose(path[0][0], path[3][0])  # an arm's approach and retract: its retract pose
    # refused before any of it moves, naming the step, the pair and the clearance, exit 2
    with pytest.raises(ShiftedPathCollides) as exc:
        check_compensated(cfg, steps, large, {StepKind.VERIFY_AFTER})
    msg = str(exc.value)
    assert f"step {first.index + 1} ({first.label})" in msg and "obstacle 'post'" in msg
    assert "under the margin of 2 mm" in msg and "compensated" in msg
    assert classify(exc.value) is Outcome.CONFIG_ERROR and exc.value.exit_code == 2
    assert "collision_margin_mm" in hint_for(exc.value) and "compensation" in hint_for(exc.value)
    # without the post the same compensation is clear: it is the post, not the body, that refuses it
    cfg0, _plan0, steps0 = _cell()
    assert check_compensated(cfg0, steps0, articulated_targets(cfg0, steps0, _joint1_error(cfg0, 0.15), R),
                             {StepKind.VERIFY_AFTER}).clash is None
    # steps already measured (a resume past them) leave nothing to check; a SCARA's are check_shifted's
    done = {st.index for st in steps if st.kind is StepKind.VERIFY_AFTER}
    assert check_compensated(cfg, steps, large, {StepKind.VERIFY_AFTER}, done) is None


def test_the_path_begins_where_the_step_before_leaves_the_robot(post_cell):
    """The transition: the first compensated step's path starts at the retract of the last step before
    correction, and the travel from there (depart, arrive over the compensated approach) is in it."""
    cfg, _plan, steps = post_cell
    R = cfg.model.nominal[:6]
    before = articulated_targets(cfg, steps, None, R)
    prev = preceding(steps, {StepKind.VERIFY_AFTER})
    assert prev is not None and prev.kind is StepKind.VERIFY_BEFORE
    assert preceding(steps, {StepKind.VERIFY_AFTER}, {st.index for st in steps}) is None
    start = standing_at(cfg, prev, before)
    assert start is not None and start[1] == f"step {prev.index + 1} ({prev.label}): retract"
    first = next(st for st in steps if st.kind is StepKind.VERIFY_AFTER)
    large = articulated_targets(cfg, steps, _joint1_error(cfg, 0.15), R)
    path = compensated_path(cfg, [first], large, start)
    names = [p[1] for p in path]
    assert names[0] == start[1] and names[1].endswith("depart") and names[2] == f"step {first.index + 1} " \
        f"({first.label}): arrive"
    report = check_compensated(cfg, steps, articulated_targets(cfg, steps, cfg.model.nominal, R),
                               {StepKind.VERIFY_AFTER}, start=start)
    assert report is not None and report.poses == len(compensated_path(
        cfg, [st for st in steps if st.kind is StepKind.VERIFY_AFTER],
        articulated_targets(cfg, steps, cfg.model.nominal, R), start))


#: a 10 x 10 x 30 mm post at the travel height (z 333 mm), 80 mm from where the head comes down to the
#: first verification touch after correction (P1c elbow +1 in the short plan without the post): the
#: transition from the last step before correction passes it by the margin, and with the targets
#: compensated for a set-up 5 mm off toward it the descent over P1c's approach brings link A3 under
#: the margin (the post stands in other steps' travel, which the cell would refuse before motion: this
#: is the transition's check alone, on the plan without it)
TRANSIT_POST = POST.replace("126.455, -256.252, 150.0", "199.82, -160.23, 333.0").replace(
    "size_mm = [10.0, 10.0, 10.0]", "size_mm = [10.0, 10.0, 30.0]")


def test_the_move_into_the_first_compensated_step_is_checked():
    cfg0, _plan, steps = _cell()
    cfg = parse_text(cfg0.source_text + TRANSIT_POST, str(CELL))
    R = cfg.model.nominal[:6]
    toward = np.array([np.sqrt(0.5), np.sqrt(0.5), 0.0])
    off = np.concatenate([R[:3] - 5.0 * toward, R[3:]])  # the targets compensated in a set-up 5 mm off
    first = next(st for st in steps if st.kind is StepKind.VERIFY_AFTER)
    assert first.label == "P1c elbow +1"
    later = {st.index for st in steps if st.kind is StepKind.VERIFY_AFTER and st.index != first.index}
    start = standing_at(cfg, preceding(steps, {StepKind.VERIFY_AFTER}), articulated_targets(cfg, steps, None, R))
    zero = articulated_targets(cfg, steps, cfg.model.nominal, R)
    large = articulated_targets(cfg, steps, cfg.model.nominal, off)
    # no correction: the move from the step before, and the first step, clear the post over the margin
    clear = check_compensated(cfg, steps, zero, {StepKind.VERIFY_AFTER}, later, start=start)
    assert clear is not None and clear.clash is None
    # the step alone, compensated, clears it too: what the check saw before the transition was in it
    assert check_compensated(cfg, steps, large, {StepKind.VERIFY_AFTER}, later).clash is None
    # with the transition: refused, on the move down over the compensated approach, naming the post
    with pytest.raises(ShiftedPathCollides) as exc:
        check_compensated(cfg, steps, large, {StepKind.VERIFY_AFTER}, later, start=start)
    msg = str(exc.value)
    assert "obstacle 'post'" in msg and f"step {first.index + 1} ({first.label}): arrive" in msg
    assert exc.value.exit_code == 2


def test_a_redundant_heads_re_measure_is_in_the_arms_path():
    """A seven-probe head touches again where its probes disagree ([plan] remeasure_attempts = 1), standing
    short of the target by a wider approach offset (the runner's _touch): those poses are in the path."""
    head = Path(__file__).resolve().parents[2] / "examples" / "heads" / "seven-probe.toml"
    cfg, _plan, steps = _cell()
    cfg = parse_text(cfg.source_text.replace('file = "head.toml"', f'file = "{head.as_posix()}"'), str(CELL))
    assert cfg.head.n_probes == 7 and remeasures(cfg) == cfg.plan.remeasure_attempts == 1
    steps = build_plan(cfg).run_steps(cfg.plan.verification_cycles, False)
    first = next(st for st in steps if st.kind is StepKind.VERIFY_AFTER)
    targets = articulated_targets(cfg, steps, _joint1_error(cfg, 0.05), cfg.model.nominal[:6])
    path = compensated_path(cfg, [first], targets)
    name = f"step {first.index + 1} ({first.label})"
    whats = ("approach", "above the point", "touch", "retract")
    assert [p[1] for p in path] == [f"{name}: {w}{again}" for again in ("", " (re-measure 1)") for w in whats]
    q = targets[first.point, first.elbow][0]
    np.testing.assert_allclose(path[5][0], q + above_offset(cfg, first.cycle, 1))  # wider than the first touch's
    assert np.abs(path[5][0] - q).max() > np.abs(path[1][0] - q).max()
    report = check_compensated(cfg, steps, targets, {StepKind.VERIFY_AFTER})
    n_after = sum(1 for st in steps if st.kind is StepKind.VERIFY_AFTER)
    assert report is not None and report.poses - report.vias == 8 * n_after


@pytest.mark.slow  # an end-to-end six-axis session to its identification (12 s here, more beside the suite)
def test_a_refused_compensated_path_moves_no_verification_step(tmp_path, monkeypatch):
    """The run refuses before any verification motion (exit 2, the failure's hint), as a SCARA's."""
    import station.cell.pipeline.shifted as shifted
    from station.cell.records.rundb import RunDB
    from station.cell.session.calibrate import CellRequest, run_calibration_session
    from station.ui.simulated_cell import load_cell

    real, asked = shifted.check_compensated, []

    def check(cfg, steps, targets, kinds, done=(), what="", start=None, R_world_base=None):
        asked.append((set(kinds), start is not None))
        report = real(cfg, steps, targets, kinds, done, what, start, R_world_base)  # the real check runs first
        assert report is not None and report.clash is None
        raise ShiftedPathCollides(f"with {what} active the verification path collides (test)", "a hint")

    monkeypatch.setattr(shifted, "check_compensated", check)
    db = str(tmp_path / "six.sqlite")
    s = run_calibration_session(CellRequest(simulated=True, robot="irb2600", seed=1, db=db), lambda e: None,
                                load=load_cell)
    assert s.outcome is Outcome.CONFIG_ERROR and s.failure is not None
    assert s.failure.error_type == "ShiftedPathCollides" and s.failure.hint == "a hint"
    assert asked == [({StepKind.VERIFY_AFTER}, True)]  # from where the last step before correction leaves it
    with RunDB(db) as rdb:
        measured = {r.kind for r in rdb.measurements(s.run_id)}
    assert StepKind.IDENTIFICATION.value in measured
    assert not measured & {k.value for k in (StepKind.VERIFY_BEFORE, StepKind.VERIFY_AFTER, StepKind.REFERENCE)}
