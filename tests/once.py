"""A fixture's value built once per test session however many xdist workers ask (issue 42)."""

from __future__ import annotations

import os
import pickle
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

import pytest
from filelock import FileLock


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


_T = TypeVar("_T")


def once_per_session(tmp_path_factory: pytest.TempPathFactory, name: str,
                     build: Callable[[Path], _T]) -> _T:
    """``build(folder)`` run once for the whole session and its result (pickled) read by every
    xdist worker that asks: a session or module fixture is otherwise built once per worker that
    runs one of its tests (three times under README's ``-n 3 --dist worksteal``). The first worker
    builds under a lock while the others wait on it; the folder and the pickle live in the
    session's own temporary root (shared by its workers, never by another session).
    Without workers, ``build`` is simply called. What ``build`` returns must be picklable, and a
    test that writes into its files copies them first (``FinishedRun.copy_to``)."""
    session = os.environ.get("PYTEST_XDIST_TESTRUNUID")  # one per pytest run, the same in its workers
    if session is None:
        return build(tmp_path_factory.mktemp(name))
    # named by the run too: a --basetemp given again keeps the folders of an earlier run
    root = tmp_path_factory.getbasetemp().parent / f"once-per-session-{session}"
    root.mkdir(exist_ok=True)
    kept = root / f"{name}.pickle"
    with FileLock(str(root / f"{name}.lock")):
        if kept.exists():
            with kept.open("rb") as f:
                return pickle.load(f)  # noqa: S301 - written by this session's own worker
        result = build(tmp_path_factory.mktemp(name))
        part = kept.with_suffix(".part")  # a result that cannot be pickled leaves no empty file
        with part.open("wb") as f:
            pickle.dump(result, f)
        part.replace(kept)
        return result
