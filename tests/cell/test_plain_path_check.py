"""An articulated arm's verification before correction as the controller moves it (issue 40): the plain
Cartesian targets, commanded in the frame the uncorrected robot located the body in, and their path
checked at the joints the controller's nominal inverse kinematics gives them before any verification
motion (station/cell/plan/moved_path/plain_check.py). The built-in IRB 2600 cell at seed 5 commanded them through
the identified set-up (its turn about axis 1 merged with A1's zero): joint 1 0.43° from the plan's, and
the simulated controller's own collision check refused the first Cartesian move (UNREACHABLE)."""

from __future__ import annotations

import numpy as np
import pytest

from station.cell.pipeline.articulated import articulated_targets
from station.cell.pipeline.outcomes import classify, hint_for
from station.cell.plan.moved_path.plain_check import check_plain, joint_turn_deg
from station.cell.plan.moved_path.shifted_check import ShiftedPathCollides
from station.cell.plan.steps import StepKind
from station.core.kinematics.transforms import matrix_to_pose, pose_to_matrix
from station.errors import Outcome
from tests.cell.test_compensated_path_check import POST
from tests.cell.test_compensated_path_check import _cell as compensated_cell

pytest.importorskip("fcl")

#: POST: the compensated test's post, 10 mm beside the head's mount at P1c (elbow +1), where a turn of
#: joint 1 by -0.15° brings the head 1.9 mm toward it; the plan clears it by 2.7 mm


def _cell(extra: str = ""):
    """The short puma560 plan of tests/cell/test_compensated_path_check.py: its config and steps."""
    cfg, _, steps = compensated_cell(extra)
    return cfg, steps


def _turned(R: np.ndarray, deg: float) -> np.ndarray:
    """The set-up ``R`` (world ← base) turned about the base's z by ``deg``: plain targets through it
    turn the nominal robot's joint 1 by -deg, as through an identified set-up that took A1's share."""
    Rz = np.eye(4)
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    Rz[:2, :2] = [[c, -s], [s, c]]
    return matrix_to_pose(pose_to_matrix(R) @ Rz)


def test_plain_targets_turned_toward_an_obstacle_are_refused_before_they_move():
    cfg, steps = _cell(POST)
    R = cfg.model.nominal[:6]
    first = next(st for st in steps if st.kind is StepKind.VERIFY_BEFORE and st.label == "P1c elbow +1")
    # in the frame the plan was made in, the plain targets are the plan's joints and their path is clear
    plain = articulated_targets(cfg, steps, None, R)
    np.testing.assert_allclose(plain[first.point, first.elbow][0], first.q, atol=1e-7)
    clear = check_plain(cfg, steps, plain)
    assert clear is not None and clear.clash is None
    assert joint_turn_deg([st for st in steps if st.kind is StepKind.VERIFY_BEFORE], plain)[0] < 1e-5
    # through a set-up turned by +0.15° about the base's z, joint 1 turns -0.15°: the head 1.9 mm toward the post
    turned = articulated_targets(cfg, steps, None, _turned(R, 0.15))
    assert np.degrees(turned[first.point, first.elbow][0] - first.q)[0] == pytest.approx(-0.15, abs=1e-3)
    with pytest.raises(ShiftedPathCollides) as exc:
        check_plain(cfg, steps, turned)
    msg = str(exc.value)
    assert "before correction" in msg and f"step {first.index + 1} ({first.label})" in msg
    assert "obstacle 'post'" in msg and "under the margin of 2 mm" in msg and "joint 1 0.15°" in msg
    assert classify(exc.value) is Outcome.CONFIG_ERROR and exc.value.exit_code == 2
    assert "verification_every" in hint_for(exc.value)
    # without the post the same turn is clear (the post refuses it, not the body); steps done: nothing to check
    cfg0, steps0 = _cell()
    assert check_plain(cfg0, steps0, articulated_targets(cfg0, steps0, None, _turned(R, 0.15))).clash is None
    assert check_plain(cfg, steps, turned, {st.index for st in steps if st.kind is StepKind.VERIFY_BEFORE}) is None


@pytest.mark.slow  # an end-to-end six-axis session (30 s here)
def test_the_built_in_six_axis_cell_at_seed_5_moves_nothing_its_controller_refuses(tmp_path, monkeypatch):
    """Before the fix: MOVE_CARTESIAN seq 1407 (verification before correction, C1.a) refused by the
    controller's own collision check, probe 6's housing 0.5 mm into cube 1, the run UNREACHABLE."""
    import simulators.six_axis_cell as six
    from station.cell.session.calibrate import CellRequest, run_calibration_session
    from station.ui.simulated_cell import load_cell

    real, started = six.start_six_axis_cell, []

    def start(*args, **kwargs):  # the cell's servers, whose controller keeps every motion it refused
        started.append(real(*args, **kwargs))
        return started[-1]

    monkeypatch.setattr(six, "start_six_axis_cell", start)
    s = run_calibration_session(CellRequest(simulated=True, robot="irb2600", seed=5, db=str(tmp_path / "six.sqlite")),
                                lambda e: None, load=load_cell)
    (servers,) = started
    assert servers.controller_server.collisions == []
    assert s.outcome is Outcome.SUCCESS, s.failure
    checks = {c.check: c for c in s.clearances}
    before = checks["before (plain)"]
    assert before.poses > 400 and (before.least_mm is None or before.least_mm >= before.margin_mm)
    assert "after (compensated)" in checks


def test_the_next_move_line_of_a_step_before_correction_says_no_correction():
    from station.cell.run.facts.next_move import NextMove

    before = NextMove(3, 2.5, "probe 1", "cube of P1a", 4.0, 2.0, "before (plain)")
    assert before.text() == "next move, before correction: clearance 2.5 mm (probe 1 ↔ cube of P1a)"
    assert NextMove(3, None, "", "", 4.0, 2.0, "after (compensated)").text() == \
        "next move, with the correction: clearance over 4 mm"


@pytest.mark.slow  # an end-to-end six-axis session (30 s here)
def test_a_refused_oracle_path_leaves_the_runs_own_result_standing(tmp_path):
    """The built-in IRB 2600 cell at seed 8: the oracle's compensated path, checked on the nominal links
    shifted by the whole of the reference's correction, comes 1.8 mm from cube C5.a (under the 2 mm
    margin). The oracle is a simulated session's figure beside the result: it is not measured, a
    warning says why, and the run ends on its own verification (it ended CONFIG_ERROR before)."""
    from station.cell.run.facts.events import Notice
    from station.cell.session.calibrate import CellRequest, run_calibration_session
    from station.ui.simulated_cell import load_cell

    notices: list[str] = []

    def emit(ev):
        if isinstance(ev, Notice) and ev.level == "warning":
            notices.append(ev.message)

    s = run_calibration_session(CellRequest(simulated=True, robot="irb2600", seed=8, db=str(tmp_path / "six.sqlite")),
                                emit, load=load_cell)
    assert s.outcome is Outcome.SUCCESS, s.failure
    assert s.after is not None and s.gain is not None and s.gain > 20
    assert s.oracle is None
    (skipped,) = [n for n in notices if n.startswith("oracle reference not measured")]
    assert "C5.a" in skipped and "under the margin" in skipped
    assert "oracle (compensated)" not in {c.check for c in s.clearances}
