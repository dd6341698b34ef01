"""A SCARA's Cartesian touch arrives from the approach side whatever the table corrects (issue 40).

Verification with the table active ends in a Cartesian move: the controller adds the table's
joint correction Δq to its nominal inverse kinematics. The touch comes down from the pose above
the point (``measurement_plan.cartesian_above``), its revolute joints a quarter of the approach
offset (0.125°) on the approach side. Around the nominal joints, a Δq beyond that quarter against
the approach made those joints arrive from the other side and land on the other flank of their
backlash (the built-in cell's seed 4: 100 touches, its oracle's after 9.1 -> 56.4 µm). The runner
moves the pose above by the table's Δq (``runner.AboveCartesian``), so the last move is the
quarter from the approach side, as the identification's touches arrive.

Driven through the real :class:`Runner`'s guard (the controller's own rule) and the real
procedure; the head reads a perfect touch wherever it is, so each visit is one touch.
"""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from station.cell.config.cell_config import load_config
from station.cell.plan.measurement_plan import CARTESIAN_SIDE, approach_offsets, head_targets_world, joints_for
from station.cell.run.runner import (
    AboveCartesian,
    MoveCartesian,
    MoveJoints,
    ReadJoints,
    ReadProbes,
    RecentReadings,
    Runner,
    approach_and_read,
    head_of,
)
from station.core.kinematics.transforms import invert, matrix_to_pose, pose_to_matrix
from station.core.probe.geometry import readings_from_pose
from station.core.table.values import CorrectionTableData, TableAxis

ARC = Path(__file__).resolve().parents[2] / "examples" / "scara_arc" / "cell.toml"
POINT = 5


def _table_around(pose: np.ndarray, dq: np.ndarray) -> CorrectionTableData:
    """A table that adds ``dq`` (g,) everywhere on a small grid around ``pose``'s x, y, z."""
    axes = tuple(TableAxis(float(v) - 50.0, 50.0, 3) for v in pose[:3]) + (
        TableAxis(-np.pi, np.pi / 4, 8, periodic=True),)
    values = np.broadcast_to(dq, (1, 3, 3, 3, 8, dq.size)).copy()
    return CorrectionTableData(axes, values)


def _moves(dq_rad: float) -> tuple[list[tuple[str, np.ndarray]], np.ndarray, object]:
    """The joints commanded by one Cartesian touch at :data:`POINT` with a table of ``dq_rad`` in
    every revolute joint: (why, joints) per move, the nominal joints and the configuration."""
    cfg = load_config(ARC)
    geom = head_of(cfg)
    target = head_targets_world(cfg)[POINT]
    q = joints_for(cfg, target, 1)[0]
    pose = matrix_to_pose(invert(pose_to_matrix(cfg.model.nominal[:6])) @ target)
    rev = np.array([k == "revolute" for k in cfg.model.joint_types])
    runner = Runner(cfg, SimpleNamespace(), SimpleNamespace(), lambda e: None)
    runner.guard.table = _table_around(pose, np.where(rev, dq_rad, 0.0))
    perfect = readings_from_pose(geom, geom.nominal_contact_pose())
    n_channels = int(geom.probe_channels.max())
    values = np.zeros(n_channels)
    values[geom.probe_channels - 1] = perfect / geom.probe_scales
    proc = approach_and_read(cfg, q, 1, cartesian=(pose, 1))
    moves: list[tuple[str, np.ndarray]] = []
    value = None
    try:
        while True:
            msg = proc.send(value)
            value = None
            if isinstance(msg, AboveCartesian):
                moves.append((msg.why, runner._above_corrected(msg)))
            elif isinstance(msg, MoveJoints) and msg.q is not None:
                moves.append((msg.why, np.asarray(msg.q, dtype=float)))
            elif isinstance(msg, MoveCartesian):
                moves.append((msg.why, runner.guard.commanded_joints(msg.pose, msg.elbow, msg.expected_q)))
            elif isinstance(msg, ReadProbes):
                value = SimpleNamespace(raw=b"", values_mm=values, status=["ok"] * n_channels)
            elif isinstance(msg, ReadJoints):
                value = moves[-1][1]
            elif isinstance(msg, RecentReadings):
                value = ()
    except StopIteration as stop:
        assert stop.value.ok, stop.value.message
    return moves, q, cfg


# ±0.3°: beyond the quarter of the 0.5° approach offset (0.125°), within the offset itself
@pytest.mark.parametrize("dq_deg", [-0.3, -0.1, 0.0, 0.3])
def test_the_last_move_sweeps_the_quarter_from_the_approach_side(dq_deg):
    moves, q, cfg = _moves(np.deg2rad(dq_deg))
    whys = [w for w, _ in moves]
    i = whys.index("touch (Cartesian)")
    assert whys[i - 1] == "above the point"
    above, touch = moves[i - 1][1], moves[i][1]
    rev = np.array([k == "revolute" for k in cfg.model.joint_types])
    a = approach_offsets(cfg, 1)
    # the controller's joints: nominal + the table's Δq; the last move into them is the quarter
    np.testing.assert_allclose(touch[rev], q[rev] + np.deg2rad(dq_deg), atol=1e-12)
    np.testing.assert_allclose((touch - above)[rev], CARTESIAN_SIDE * a[rev], atol=1e-12)
    assert np.all(np.sign(touch - above)[rev] == np.sign(a[rev]))  # as the identification's last moves
    assert np.all(touch[~rev] < above[~rev])  # the quill comes down to the point


def test_a_correction_against_the_approach_beyond_the_quarter_needs_the_shift():
    """The case the shift is for: above the nominal joints, a Δq of −0.3° would be arrived at from
    the other side (the step the unshifted pose leaves is negative)."""
    moves, q, cfg = _moves(np.deg2rad(-0.3))
    rev = np.array([k == "revolute" for k in cfg.model.joint_types])
    whys = [w for w, _ in moves]
    touch = moves[whys.index("touch (Cartesian)")][1]
    from station.cell.plan.measurement_plan import cartesian_above

    unshifted = cartesian_above(cfg, q, 1)
    assert np.all((touch - unshifted)[rev] < 0)
