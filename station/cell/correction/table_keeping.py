"""The table the operator chose, at every step of a run (issue 17, part 4).

A calibration changes the controller's correction tables: it deactivates the operator's table
for its "verify before" measurement, activates its own, and in simulation the oracle's. Whatever
happens next - the operator declines the new table, aborts, a device fails, the run was planned
without the upload - the run ends with exactly the table that was active when it started (or
none), confirmed by its CRC-32. Only a kept correction (SUCCESS, or TARGET_MISSED with the
table verified) stays active.

So the table of the run's start is recoverable from any state the run can leave the controller
in: the run records its CRC and, read back from the controller's active slot, the table itself
in the run database before anything changes; :func:`station.cell.correction.upload.restore_table` then
rolls back, deactivates, or uploads that table again.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass

from drivers.controller_map import WordOrder
from drivers.correction_table import data_registers, header_registers, table_from_registers
from station.cell.correction.upload import TableState, restore_table
from station.cell.records.rundb import RunDB
from station.cell.records.summary import RunSummary, TableSummary
from station.cell.run.devices import TableController
from station.cell.run.facts.events import Event, Notice
from station.core.table.values import CorrectionTableData
from station.errors import Outcome

__all__ = ["TableAtStart", "table_at_start", "finish_tables", "restore_after_failure"]

log = logging.getLogger(__name__)

#: run-database result key of the table active when the run first started
RESULT_KEY = "table_at_start"


@dataclass(frozen=True)
class TableAtStart:
    """The controller's active table when the run first started: its CRC-32 and, where the
    controller could read it back, the table itself."""

    state: TableState
    data: CorrectionTableData | None = None

    def to_record(self) -> dict:
        rec: dict = {"active_crc32": self.state.active}
        if self.data is not None:  # registers in big word order: exact, whatever the link uses
            rec["header"] = header_registers(self.data, WordOrder.BIG)
            rec["values"] = data_registers(self.data, WordOrder.BIG)
        return rec

    @classmethod
    def from_record(cls, rec: dict) -> TableAtStart:
        data = None
        if "header" in rec and "values" in rec:
            data = CorrectionTableData.from_table(table_from_registers(rec["header"], rec["values"], WordOrder.BIG))
        return cls(TableState(str(rec["active_crc32"])), data)


def table_at_start(controller: TableController, db: RunDB, run_id: int,
                   emit: Callable[[Event], None]) -> TableAtStart | None:
    """The table of the run's first start: stored in the run database before anything changes
    (a resumed run keeps the one of its first start). None when the controller's table CRCs
    cannot be read (the run then cannot promise to put it back, and says so)."""
    stored = db.load_result(run_id, RESULT_KEY, default=None)
    if isinstance(stored, dict) and "active_crc32" in stored:
        try:
            return TableAtStart.from_record(stored)
        except Exception as exc:  # noqa: BLE001 - a damaged record: take the controller's state now
            emit(Notice("warning", f"run {run_id}: the stored table of the run's start is unreadable ({exc}); "
                                   f"taking the controller's active table now"))
    state = TableState.read(controller)
    if state is None:
        emit(Notice("warning", "the controller's table CRCs could not be read: the table active now cannot be "
                               "restored automatically if this run is declined or fails"))
        return None
    data = None
    if state.active != "none":
        try:
            held = controller.read_slot_table("active")
            data = None if held is None else CorrectionTableData.from_table(held)
        except Exception as exc:  # noqa: BLE001 - a program without slot reads: roll back only
            emit(Notice("warning", f"the active table {state.active} could not be read back ({exc}); it can be "
                                   f"restored by a roll back only"))
    start = TableAtStart(state, data)
    db.save_result(run_id, RESULT_KEY, start.to_record())
    return start


def _kept(summary: RunSummary) -> bool:
    """The run's own table stays active: it was uploaded, verified and not declined."""
    return summary.upload is not None and summary.outcome in (Outcome.SUCCESS, Outcome.TARGET_MISSED)


def finish_tables(controller: TableController, start: TableAtStart | None, summary: RunSummary,
                  emit: Callable[[Event], None]) -> RunSummary:
    """Put the table of the run's start back unless the run's own correction is kept; record in
    the summary which table is active at the end."""
    if start is None:
        return summary
    restored = False
    if not _kept(summary):
        restore_table(controller, start.state, emit, start.data)
        restored = True
    end = TableState.read(controller)
    return summary.replace(tables=TableSummary(start.state.active, "unknown" if end is None else end.active,
                                               restored))


def restore_after_failure(controller: TableController, start: TableAtStart | None,
                          emit: Callable[[Event], None]) -> str:
    """After an abort or a failure: put the table of the run's start back. Returns what the run
    record says about it (never raises: the failure itself is what must reach the operator)."""
    if start is None:
        return "the controller's table of the run's start is not known: check it before moving the robot"
    try:
        now = TableState.read(controller)
        if now is not None and now.active == start.state.active:
            return f"the controller's table is as at the run's start ({start.state.active})"
        restore_table(controller, start.state, emit, start.data)
        return f"the table of the run's start ({start.state.active}) is active again"
    except Exception as exc:  # noqa: BLE001 - reported, the original error is raised
        log.warning("restoring table %s after a failure failed: %s", start.state.active, exc)
        where = ("it is kept in the run database" if start.data is not None
                 else "the controller's previous slot may hold it")
        return (f"the table of the run's start ({start.state.active}) could NOT be restored ({exc}); {where}: "
                f"resume the run, or restore it before moving the robot")
