"""A run whose [identification] σ is below the noise its residuals show (issue 38): the σ it reports
are scaled by the a-posteriori variance factor s0, and its summary, --json and events say so."""

from __future__ import annotations

import pytest

from station.cell.pipeline.calibration import Options
from station.cell.run.facts.events import Notice
from station.errors import Outcome
from tests.cell.test_pipeline import SHORT, Cell


def test_a_sigma_below_the_residuals_is_scaled_and_said(tmp_path):
    # the built-in cell's 6 µm holds the robot's ≈ 5 µm repeatability; 3.5 µm leaves it out
    c = Cell(tmp_path, **SHORT, **{"sigma_position_um = 6.0": "sigma_position_um = 3.5"})
    try:
        summary = c.run(options=Options(upload=False))
    finally:
        c.close()
    assert summary.outcome is Outcome.NOT_UPLOADED
    ident = summary.identification
    assert ident is not None and ident.variance_factor_s0 is not None
    assert ident.variance_factor_s0 > ident.variance_limit_s0
    assert ident.sigma_scaled_by == pytest.approx(ident.variance_factor_s0) and ident.sigma_scaled_by > 1.1
    assert any("a-posteriori variance factor" in n for n in summary.notes)
    assert any(isinstance(e, Notice) and "σ are scaled by" in e.message for e in c.events)
    assert summary.to_json()["identification"]["sigma_scaled_by"] == pytest.approx(ident.sigma_scaled_by)
