"""Fixtures shared by the whole suite.

A simulated calibration of the built-in cell costs half a minute of CPU, and a dozen modules need
one finished run of seed 1 to read, damage, recheck or report on. ``seed1_run`` runs it once per
process (each xdist worker runs it once, the first time one of its tests asks); a test that writes
into the run database or the report works on ``seed1_run.copy_to(folder)``, never on the original.
"""

from __future__ import annotations

import io
import shutil
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest


@dataclass(frozen=True)
class FinishedRun:
    """``station calibrate --simulated --seed 1 --db DB --report REPORT``, finished: its exit code,
    what it printed on each stream, its run database and its report folder."""

    code: int
    out: str
    err: str
    db: Path
    report: Path

    def copy_to(self, folder: Path, db_name: str = "runs.sqlite", report_name: str = "rep") -> FinishedRun:
        """The same run in ``folder`` (the database and the report copied), for a test that writes."""
        folder.mkdir(parents=True, exist_ok=True)
        db = folder / db_name
        shutil.copy(self.db, db)
        report = folder / report_name
        shutil.copytree(self.report, report)
        return FinishedRun(self.code, self.out, self.err, db, report)


@pytest.fixture(scope="session")
def seed1_run(tmp_path_factory) -> FinishedRun:
    from station.ui.cli.main import main

    root = tmp_path_factory.mktemp("seed1-run")
    db, report = root / "runs.sqlite", root / "rep"
    out, err = io.StringIO(), io.StringIO()
    streams = pytest.MonkeyPatch()  # capsys is per test; this run's streams are kept for the tests that read them
    streams.setattr(sys, "stdout", out)
    streams.setattr(sys, "stderr", err)
    try:
        code = main(["calibrate", "--simulated", "--seed", "1", "--db", str(db), "--report", str(report)])
    finally:
        streams.undo()
    assert code == 0, err.getvalue()[-3000:]
    return FinishedRun(code, out.getvalue(), err.getvalue(), db, report)
