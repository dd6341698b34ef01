"""Fixtures shared by the cell tests."""

from __future__ import annotations

from pathlib import Path

import pytest

from station.ui.cli.main import main


@pytest.fixture(scope="session")
def good_db(tmp_path_factory) -> Path:
    """One finished simulated calibration (sr800: 4 joints, a head of 6 probes), run once per
    worker and copied by each test that damages it (tests/cell/damaged_runs.py)."""
    db = tmp_path_factory.mktemp("good") / "runs.sqlite"
    assert main(["calibrate", "--simulated", "--seed", "1", "--db", str(db)]) == 0
    return db
