"""The TUI's next step after too few valid identification poses names the setting to change and
its value, as the pipeline's message does, and offers the one-key continue only where a resume can
carry the fix (issue 37): a residual bound (the stored readings are judged again) or cleaned probes
(the invalid poses are measured again); probes out of their stroke need [plan] recenter_attempts or
the set-up, which change how poses are measured: a new run. The messages are the pipeline's own
(:func:`station.cell.pipeline.invalid_poses.invalid_advice`)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from test_tui_signoff import CTX
from textual.content import Content

from station.cell.pipeline.calibration import min_valid_identification
from station.cell.pipeline.invalid_poses import invalid_advice
from station.cell.pipeline.outcomes import failure_summary
from station.cell.records.run_records import MeasurementRecord
from station.errors import IdentificationError
from station.ui.tui.invalid_next import TOO_FEW_VALID
from station.ui.tui.result_panel import can_continue, next_step, summary_markup

PLAN = SimpleNamespace(max_residual_um=0.8, recenter_attempts=2, remeasure_attempts=1, setup_uncertainty_mm=5.0)


def _record(i: int, ok: bool, residual: float | None, message: str = "") -> MeasurementRecord:
    pose = None if residual is None else np.eye(4)
    return MeasurementRecord(1, i, "identification", f"P{i}", "", np.zeros(4), np.zeros(4), b"", None, None, pose,
                             residual, ok, message, "")


def _stopped(bad: list[MeasurementRecord]):
    """The run's summary after the pipeline's refusal: 20 identification poses, 10 valid."""
    records = [_record(i, True, 0.5) for i in range(10)] + bad
    needed = min_valid_identification(len(records))
    message = (f"only 10 of {len(records)} {TOO_FEW_VALID}, {needed} are needed (80%); no correction was identified. "
               f"Of the invalid: {invalid_advice(SimpleNamespace(plan=PLAN), records, needed)}")
    return failure_summary(IdentificationError(message), run_id=7, log_dir=".")


def _next(summary) -> str:
    text = Content.from_markup(summary_markup(summary, 3, CTX, 60, "identify")).plain
    lines = [line for line in text.splitlines() if line.startswith("Next: ")]
    assert len(lines) == 1, text
    assert lines[0] == f"Next: {next_step(summary, CTX, 'identify')}"
    return " ".join(lines[0].split())


def test_a_residual_bound_too_tight_names_the_value_and_continues():
    summary = _stopped([_record(10 + i, False, 1.9, "plane residual 1.90 µm") for i in range(10)])
    line = _next(summary)
    assert f"in {CTX.config}: set [plan] max_residual_um = 2.1 (20 poses valid with it)" in line
    assert "press c: run #7 judges the stored readings again" in line and "new run" not in line
    assert can_continue(summary, "identify")


@pytest.mark.parametrize("why", ["probe 3 out of its stroke", "no valid reading from probe 2"])
def test_probes_out_of_their_stroke_name_recenter_attempts_and_a_new_run(why):
    summary = _stopped([_record(10 + i, False, None, why) for i in range(10)])
    line = _next(summary)
    assert "set [plan] recenter_attempts = 4 (probes out of their stroke)" in line
    assert "[robot] setup" in line and "setup_uncertainty_mm" in line
    assert "start a new run (s)" in line and "press c" not in line  # a resume refuses [plan] changed
    assert not can_continue(summary, "identify")


def test_poses_the_probes_disagreed_on_are_measured_again_after_cleaning():
    summary = _stopped([_record(10 + i, False, None, "the redundant probes disagree by 40 µm") for i in range(10)])
    line = _next(summary)
    assert "clean and check the probes" in line and "press c: run #7" in line
    assert "[plan] remeasure_attempts = 2 and start a new run (s)" in line
    assert can_continue(summary, "identify")
