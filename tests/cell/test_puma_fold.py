"""Why the PUMA 560 example's plan keeps one arm configuration (issue 40): the proof in figures.

The example's robot file (examples/puma560/puma560.mdh.csv, Craig's modified DH) and its cell's
[limits] reach two configurations: +1 (shoulder front, elbow up) and +7 (shoulder back, elbow up).
Joint 3 takes them on either side of the angle where the forearm folds back onto the upper arm;
its range ends before the angle where the arm stretches. Every joint path from one to the other
therefore passes the fold, where the wrist centre lies on joint 2's axis (the forearm, |a3, d4| =
433.5 mm, is as long as the upper arm, a2 = 431.8 mm): inside the shoulder whatever the other five
joints, so no via, no wrist angle and no order of the poses makes the change of configuration
clear. A physical fact of this geometry, not a radius that is too large: the head's mount begins
at the wrist centre, so it would take a shoulder capsule of negative radius.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from station.cell.config.cell_config import load_config
from station.cell.plan.articulated import articulated_candidates
from station.cell.plan.collision import poses_clear
from station.core.kinematics.forward import chain_frames

pytest.importorskip("fcl")

PUMA = Path(__file__).resolve().parents[2] / "examples" / "puma560" / "cell.toml"


@pytest.fixture(scope="module")
def cell():
    return load_config(PUMA)


def _wrist_to_axis_mm(cfg, q3: np.ndarray) -> np.ndarray:
    """The wrist centre's distance [mm] from joint 2's axis at joint 3 = ``q3`` (the rest 0)."""
    Q = np.zeros((len(q3), cfg.model.n_joints))
    Q[:, 2] = q3
    F = chain_frames(cfg.model, Q, setup=False)
    joints = [t for t, spec in enumerate(cfg.model.transforms) if spec.joint is not None]
    axis, origin = F[:, joints[1], :3, 2], F[:, joints[1], :3, 3]
    wrist = F[:, joints[-1], :3, 3]  # the spherical wrist: axes 4-6 meet there
    return np.linalg.norm(np.cross(wrist - origin, axis), axis=1)


def test_every_way_between_the_two_configurations_passes_the_fold(cell):
    lim = cell.soft_limits[2]
    q3 = np.linspace(lim[0], lim[1], 26001)  # 0.01° steps over joint 3's soft range
    d = _wrist_to_axis_mm(cell, q3)
    fold = float(q3[np.argmin(d)])
    assert float(d.min()) < 5.0  # the wrist centre on joint 2's axis: 1.7 mm (|433.5 - 431.8| mm)
    assert 85.0 < np.degrees(fold) < 95.0
    # the stretched arm (the wrist farthest from the axis, 865 mm) is outside joint 3's range: the
    # shoulder cannot change over the upright arm as it does on an arm whose range holds the stretch
    assert float(d.max()) < 0.99 * 865.1
    cands, _orient, _ = articulated_candidates(cell)
    by = {c: np.array([t.joints[2] for t in cands if t.elbow == c]) for c in {t.elbow for t in cands}}
    assert set(by) == {1, 7}
    assert by[1].max() < fold < by[7].min()  # joint 3 is continuous (no wrap in a 260° range): it passes the fold


def test_at_the_fold_no_choice_of_the_other_joints_is_clear(cell):
    rng = np.random.default_rng(40)
    lim = cell.soft_limits
    q3 = np.linspace(lim[2, 0], lim[2, 1], 26001)
    fold = float(q3[np.argmin(_wrist_to_axis_mm(cell, q3))])
    n = 300
    Q = lim[:, 0] + rng.random((n, cell.model.n_joints)) * (lim[:, 1] - lim[:, 0])
    Q[:, 2] = fold
    why = poses_clear(cell, Q, np.full(n, -1))
    assert all(w is not None for w in why)  # every one of them collides
    # and with the shoulder: the head's mount, which begins at the wrist centre, inside it
    assert sum("head mount" in w and "link A2" in w for w in why) >= 0.9 * n, why[:3]
    # a little way off the fold the same draws are mostly clear: the check does not refuse everything
    Q[:, 2] = fold - np.deg2rad(60.0)
    assert sum(w is None for w in poses_clear(cell, Q, np.full(n, -1))) > n // 4


def test_the_plan_says_why_the_shoulder_back_configuration_goes(cell):
    from station.cell.plan.measurement_plan import build_plan
    from station.cell.plan.vias import fold_note

    why = [r[2] for r in build_plan(cell).rejected if r[1] == 7 and "cannot be reached" in r[2]]
    assert why and all("turns joint 3 through 92.7°" in w and "1.7 mm from joint 2's axis" in w
                       and "not the stretched arm (-87°)" in w and "limits in the robot file" in w for w in why)
    cands, _orient, _ = articulated_candidates(cell)
    front = [np.asarray(t.joints) for t in cands if t.elbow == 1]
    back = [np.asarray(t.joints) for t in cands if t.elbow == 7]
    assert fold_note(cell, front[0], back[0]).startswith(". Every way")
    assert fold_note(cell, front[0], front[-1]) == ""  # both on one side of the fold
    # the obstacles example's file has the PUMA 560's own joint-3 range: its change goes over the stretch
    other = load_config(PUMA.parents[1] / "puma560_obstacles" / "cell.toml")
    cands, _orient, _ = articulated_candidates(other)
    a = next(np.asarray(t.joints) for t in cands if t.elbow == 1)
    b = next(np.asarray(t.joints) for t in cands if t.elbow == 7)
    assert fold_note(other, a, b) == ""
