"""Fixtures shared by the whole suite.

A simulated calibration of the built-in cell costs about 16 s of CPU (33 s of wall time beside other
work on 2 cores), and a dozen modules need one finished run of seed 1 to read, damage, recheck or
report on. ``seed1_run`` (uploaded) and ``seed1_not_uploaded`` (``--no-upload --json``) run once per
test session (tests/once.py: the first xdist worker that asks runs it, the others read its result);
a test that writes into the run database or the report works on ``run.copy_to(folder)``, never on
the original, which every worker reads.
"""

from __future__ import annotations

import io
import os
import shutil
import sys
import tempfile
from pathlib import Path

import pytest

# seed1_run and seed1_not_uploaded are built once per session, not once per xdist worker (issue 42)
from tests.once import FinishedRun, once_per_session

# a test whose report cannot be made fails alone instead of ending the run in INTERNALERROR (issue 42)
from tests.report_guard import pytest_runtest_makereport  # noqa: F401

DESIGN_CACHE_ENV = "STATION_DESIGN_CACHE"  # station.cell.correction.design_cache.CACHE_ENV


def pytest_configure(config: pytest.Config) -> None:
    """One correction-design cache for this test session, shared by its workers and every station
    process they start (a cell is designed once per session, not once per process: ~7 s of CPU
    each), fresh for each session (never the user's own ~/.cache), removed at its end."""
    if os.environ.get(DESIGN_CACHE_ENV) is None and not hasattr(config, "workerinput"):
        folder = tempfile.mkdtemp(prefix="station-design-cache-")
        os.environ[DESIGN_CACHE_ENV] = folder
        config.stash[_OWN_CACHE] = folder


def pytest_unconfigure(config: pytest.Config) -> None:
    folder = config.stash.get(_OWN_CACHE, None)
    if folder is not None:
        shutil.rmtree(folder, ignore_errors=True)
        os.environ.pop(DESIGN_CACHE_ENV, None)


_OWN_CACHE = pytest.StashKey[str]()


def _calibrate(root: Path, *options: str) -> FinishedRun:
    """``station calibrate --simulated --seed 1 --db ROOT/runs.sqlite --report ROOT/rep OPTIONS``
    in this process, its streams kept (capsys is per test, and these runs serve many tests)."""
    from station.ui.cli.main import main

    db, report = root / "runs.sqlite", root / "rep"
    out, err = io.StringIO(), io.StringIO()
    streams = pytest.MonkeyPatch()
    streams.setattr(sys, "stdout", out)
    streams.setattr(sys, "stderr", err)
    try:
        code = main(["calibrate", "--simulated", "--seed", "1", "--db", str(db), "--report", str(report), *options])
    finally:
        streams.undo()
    return FinishedRun(code, out.getvalue(), err.getvalue(), db, report)


@pytest.fixture(scope="session")
def seed1_run(tmp_path_factory) -> FinishedRun:
    """The built-in cell's seed-1 calibration, uploaded and verified (exit 0)."""
    run = once_per_session(tmp_path_factory, "seed1-run", _calibrate)
    assert run.code == 0, run.err[-3000:]
    return run


@pytest.fixture(scope="session")
def seed1_not_uploaded(tmp_path_factory) -> FinishedRun:
    """The same calibration with ``--no-upload --json``: NOT_UPLOADED (exit 11), its one JSON object
    on stdout and the human summary on stderr, and its report."""
    run = once_per_session(tmp_path_factory, "seed1-not-uploaded",
                           lambda root: _calibrate(root, "--no-upload", "--json"))
    assert run.code == 11, run.err[-3000:]
    return run


# --- issue 42 (tui): the built-in cell with a short plan, one per session ---------------------------

@pytest.fixture(scope="session")
def short_cell(tmp_path_factory) -> Path:
    """The built-in simulated cell's file with one visit per identification pose and one verification
    cycle (tests/short_plan.py), for the tests about keys, pipes and signals, not accuracy."""
    from tests.short_plan import built_in_short

    return built_in_short(tmp_path_factory.mktemp("short-cell"))
