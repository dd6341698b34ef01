"""The bound ``identify`` advises after too few valid poses (issue 37 §4) is the smallest tenth of a
µm that admits the needed reading with its margin, not one step above it."""

from __future__ import annotations

import numpy as np
import pytest

from station.cell.pipeline.invalid_poses import BOUND_MARGIN, residual_bound_for
from station.cell.plan.steps import StepKind
from station.cell.records.run_records import MeasurementRecord


def _reading(step: int, residual_um: float) -> MeasurementRecord:
    return MeasurementRecord(
        run_id=1, step_index=step, kind=StepKind.IDENTIFICATION.value, point_id=f"P{step}", label="",
        joints_commanded=np.zeros(4), joints_read=None, raw_frames=b"", readings_mm=None,
        channel_status=None, pose=np.eye(4), pose_residual_um=residual_um, ok=residual_um <= 1.0,
        message="", t_utc="2026-12-07T00:00:00Z")


@pytest.mark.parametrize(("residual_um", "expected_um"), [(2.0, 2.2), (1.0, 1.1), (3.0, 3.3), (2.01, 2.3)])
def test_the_advised_bound_is_the_margin_rounded_up_to_a_tenth(residual_um: float, expected_um: float) -> None:
    records = [_reading(0, 0.5), _reading(1, residual_um), _reading(2, 50.0)]
    bound = residual_bound_for(records, needed=2)
    assert bound == pytest.approx(expected_um, abs=1e-12)
    # the advice admits the reading it was computed for
    assert residual_um * BOUND_MARGIN <= bound + 1e-12


def test_no_bound_when_too_few_poses_were_solved() -> None:
    assert residual_bound_for([_reading(0, 0.5)], needed=2) is None
