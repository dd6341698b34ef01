"""The measurements a :class:`~station.cell.records.rundb.RunDB` has already read, parsed and
checked, served again while their rows on disk are unchanged (issue 42: one simulated calibration
with its report read a run's measurements 19 times, each read parsing and checking every row again,
~1.7 s of ~38 s under the profiler).

A record is served again only while its row is the same row: kept per (run id, step index) beside
the row exactly as SQLite returned it (every column, the probe's raw frames included), a row that
differs in any column (``record_measurement(replace=True)``, a resume in another process, an edit
with another tool) is parsed and checked anew, and a step no longer stored drops out. The checks of
a record also read the run's plan, so a run's records are dropped when its stored plan text
changes. The rows themselves are read from the file on every call (one SELECT): the cache saves the
parsing and checking, never the read. Records are frozen with read-only arrays, so callers may
share them.
"""

from __future__ import annotations

import threading
from typing import Callable, Sequence

from station.cell.records.run_records import MeasurementRecord

__all__ = ["MeasurementCache"]

#: the runs kept, the most recently read (a served RunDB, the dashboard's or OPC UA's, reads many runs
#: over its life; a calibration and its report read one): the simulated SCARA run's 305 rows hold
#: 0.28 MB of text and bytes, its records as much again
MAX_RUNS = 4

#: per step: the row as read and its record
_Steps = dict[int, tuple[tuple, MeasurementRecord]]


class MeasurementCache:
    """Parsed and checked measurement records of the runs one RunDB has read."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._runs: dict[int, tuple[object, _Steps]] = {}  # run id -> (plan text, its steps)

    def records(self, run_id: int, plan_text: object, rows: Sequence[tuple],
                parse: Callable[[tuple], MeasurementRecord]) -> tuple[list[MeasurementRecord], list[MeasurementRecord]]:
        """All rows as records (in the rows' order) and those of them parsed now (to be checked).
        Call :meth:`keep` once they have passed the checks."""
        with self._lock:
            text, known = self._runs.get(run_id, (None, {}))
        if text != plan_text:
            known = {}
        out: list[MeasurementRecord] = []
        new: list[MeasurementRecord] = []
        for row in rows:
            hit = known.get(row[1])
            if hit is not None and hit[0] == row:
                out.append(hit[1])
            else:
                rec = parse(row)
                out.append(rec)
                new.append(rec)
        return out, new

    def keep(self, run_id: int, plan_text: object, rows: Sequence[tuple],
             records: Sequence[MeasurementRecord]) -> None:
        """Remember the run's checked records beside their rows (only the steps stored now)."""
        steps = {row[1]: (row, rec) for row, rec in zip(rows, records)}
        with self._lock:
            self._runs.pop(run_id, None)  # re-inserted last: the dict's order is the order of reading
            self._runs[run_id] = (plan_text, steps)
            while len(self._runs) > MAX_RUNS:
                del self._runs[next(iter(self._runs))]
