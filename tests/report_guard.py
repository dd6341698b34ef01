"""A test whose report cannot be made is a failed test, not the end of the run (issue 42).

Under load a failing end-to-end rehearsal once ended README's run in INTERNALERROR while pytest
formatted its traceback: with ``-n 3`` the worker's INTERNALERROR ends the whole session
(xdist's controller asserts on the worker's unfinished item), and 40 % of the suite never ran.
``--tb=native`` (pyproject's addopts) takes Python's own printer for the traceback; this hook
wrapper catches whatever still goes wrong while the report is made and reports the test as failed
with both tracebacks as plain text, so every other test still runs and the count says what failed.
tests/conftest.py imports it; tests/test_suite_resilience.py plants the fault.
"""

from __future__ import annotations

import traceback
from collections.abc import Generator

import pytest
from _pytest.reports import TestReport


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]) -> Generator[None, TestReport, TestReport]:
    try:
        return (yield)
    except Exception as broke:  # noqa: BLE001 - any failure to report is this test's failure
        text = "".join(traceback.format_exception(broke))
        if call.excinfo is not None:  # what the test itself raised, printed the plain way
            text = "".join(traceback.format_exception(call.excinfo.value)) + "\n" + text
        return TestReport(item.nodeid, item.location, dict.fromkeys(item.keywords, 1), "failed",
                          f"the report of this test could not be made (issue 42):\n{text}", call.when, [],
                          call.duration, call.start, call.stop)
