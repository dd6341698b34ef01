"""A crash or an INTERNALERROR in one test never hides the rest of the run (issue 42).

A throwaway suite of 18 tests runs under xdist with README's options: one test kills its worker
(``os._exit``), one test's report cannot be made (a plugin raises while it is made, as pytest's
traceback formatter did on a frame without a line number). Every other test must still run and
the count must name both as failed. Without tests/report_guard.py the second ends the session:
``1 failed, 15 passed`` and an INTERNALERROR, two tests never run."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

TESTS = """
import os
import pytest

@pytest.mark.parametrize("i", range(8))
def test_fine(i):
    assert i >= 0

def test_kills_its_worker():
    os._exit(1)

def test_whose_report_breaks():
    assert False, "the test's own failure"

@pytest.mark.parametrize("i", range(7))
def test_after(i):
    assert i >= 0
"""

CONFTEST = """
import pytest

@pytest.hookimpl(tryfirst=True)
def pytest_runtest_makereport(item, call):  # the planted fault
    if item.name == "test_whose_report_breaks" and call.when == "call":
        raise RuntimeError("the report's formatter broke")
"""


def test_a_crashed_worker_and_a_broken_report_leave_every_other_test_run(tmp_path):
    (tmp_path / "test_planted.py").write_text(TESTS)
    (tmp_path / "conftest.py").write_text(CONFTEST)
    # README's options on two workers, the guard loaded as tests/conftest.py loads it for the suite
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-n", "2", "--dist", "worksteal", "--tb=native",
                        "-p", "no:cacheprovider", "-p", "tests.report_guard", str(tmp_path)],
                       cwd=tmp_path, env=dict(os.environ, PYTHONPATH=str(ROOT)), capture_output=True, text=True,
                       timeout=540)
    out = r.stdout + r.stderr
    assert "INTERNALERROR" not in out, out[-4000:]
    assert re.search(r"\b2 failed, 15 passed\b", out), out[-4000:]
    assert "test_kills_its_worker" in out and "crashed" in out
    assert "the report of this test could not be made" in out and "the report's formatter broke" in out
    assert "the test's own failure" in out  # the test's own traceback is kept beside it
    assert r.returncode == 1
