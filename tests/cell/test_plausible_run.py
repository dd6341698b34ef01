"""The calibration run refuses a converged but implausible identification (issue 36, §3): exit 3,
the parameter, its value and σ named, no table uploaded."""

from __future__ import annotations

import pytest

from station.cell.pipeline.calibration import run_calibration
from station.cell.pipeline.outcomes import classify
from station.errors import IdentificationError, Outcome


def test_an_identification_beyond_the_plausible_limits_ends_the_run_with_exit_3(cell, monkeypatch):
    import station.core.identification.plausibility as plausibility

    # limits far below the simulated robot's own errors (40 µm, 150″): its fit now counts as implausible
    monkeypatch.setattr(plausibility, "PLAUSIBLE_LENGTH_MM", 1e-6)
    monkeypatch.setattr(plausibility, "PLAUSIBLE_ANGLE_RAD", 1e-9)
    monkeypatch.setattr(plausibility, "PRIOR_FACTOR", 0.0)
    with pytest.raises(IdentificationError, match="far from its robot file") as exc:
        run_calibration(cell.cfg, cell.probe, cell.ctrl, cell.db, cell.events.append)
    assert classify(exc.value) is Outcome.IDENTIFICATION_FAILED
    msg = str(exc.value)
    assert " at σ " in msg and "Likely cause" in msg and "A" in msg.split("=")[0]
    assert cell.srv.controller_server.active_table is None
