"""Fixtures shared by the cell tests."""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture(scope="session")
def good_db(seed1_run) -> Path:
    """One finished simulated calibration (sr800: 4 joints, a head of 6 probes): the suite's seed-1
    run (tests/conftest.py), never written to; each test that damages it copies it first
    (tests/cell/damaged_runs.py)."""
    return seed1_run.db
