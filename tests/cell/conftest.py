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


@pytest.fixture
def cell(tmp_path):
    """The example cell's simulated pipeline (tests/cell/test_pipeline.Cell) with the suite's short
    plan (tests/short_plan.py: one visit per identification pose, one verification cycle), for the
    tests of what a run does, stores and streams, not of its accuracy (issue 42). A module that
    needs the whole plan defines its own fixture."""
    from tests.cell.test_pipeline import SHORT, Cell

    c = Cell(tmp_path, **SHORT)
    yield c
    c.close()
