"""The verified upload of a correction table: the one owner of the sequence and its events.

Upload → read back and compare → stage → activate → active CRC-32 checked, with a roll back
when activation fails. The comparisons themselves are the driver's (``verify_table`` compares
value by value and the CRC-32; ``activate_table`` refuses a table that was not read back
identical or whose staged CRC differs, and checks the active CRC): the station never activates
a table on its own judgement, and the driver's interlock holds for any other caller too. This
module decides the order, the roll back policy, and what the operator is told (every step is an
event).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

from drivers.correction_table import TableVerifyError
from station.cell.run.devices import TableController
from station.cell.run.facts.events import Event, Notice, PhaseChanged
from station.core.table.values import CorrectionTableData

__all__ = ["TableState", "UploadReport", "restore_table", "verified_upload"]


@dataclass(frozen=True)
class UploadReport:
    """A verified upload (times in seconds; CRC-32 values as reported by the controller)."""

    crc32: int
    n_values: int
    upload_s: float
    readback_s: float
    stage_s: float
    activate_s: float
    total_s: float
    staged_crc32: int | None = None
    active_crc32: int | None = None
    previous_crc32: int | None = None


#: attempts at reading the controller's table CRCs (a read changes nothing, so it may be repeated)
CRC_READ_ATTEMPTS = 3


def _crcs(controller: TableController) -> dict[str, int] | None:
    """The controller's staged/active/previous CRC-32, or None when it cannot be read."""
    for _ in range(CRC_READ_ATTEMPTS):
        try:
            return {k: int(v) for k, v in controller.table_crcs().items()}
        except Exception:  # noqa: BLE001 - a state read must not mask the error being handled
            continue
    return None


def verified_upload(controller: TableController, table: CorrectionTableData,
                    emit: Callable[[Event], None]) -> UploadReport:
    """Upload ``table`` and activate it only once the controller holds it identically.

    Raises :class:`TableVerifyError` (nothing activated) when the read-back or a CRC differs.
    If activation fails, the previous table is made active again with ``rollback_table``
    unless the controller reports that its active table did not change; the original error is
    re-raised with a note saying which.
    """
    crc = table.crc32()
    t_start = time.perf_counter()
    emit(PhaseChanged("upload", f"{table.n_values} values, CRC-32 {crc:#010x}"))

    t0 = time.perf_counter()
    controller.upload_table(table)
    t_up = time.perf_counter() - t0
    emit(Notice("info", f"table uploaded ({table.n_values} values) in {t_up:.2f} s; reading back"))

    t0 = time.perf_counter()
    try:
        controller.verify_table()
    except TableVerifyError as exc:
        emit(Notice("warning", f"read-back differs, the table was NOT activated: {exc}"))
        raise
    t_rb = time.perf_counter() - t0
    emit(Notice("info", f"read back {table.n_values} values identical, CRC-32 {crc:#010x}"))

    t0 = time.perf_counter()
    controller.stage_table()
    t_st = time.perf_counter() - t0
    before = _crcs(controller)
    if before is None:
        # Without the active CRC before activation, a failed activation could not be told from one
        # that took effect, and a roll back might activate an older table: do not activate.
        msg = (f"the controller's table CRCs could not be read ({CRC_READ_ATTEMPTS} attempts): the table was "
               f"staged but NOT activated; check the link, then resume to upload again")
        emit(Notice("warning", msg))
        raise TableVerifyError(msg)

    t0 = time.perf_counter()
    try:
        controller.activate_table()
    except BaseException as exc:
        now = _crcs(controller)
        unchanged = (before is not None and now is not None
                     and now.get("active") == before.get("active") and now.get("active") != crc)
        if unchanged:
            note = "activation failed; the controller's previous table is still active (no roll back needed)"
            emit(Notice("warning", f"{note}: {exc}"))
        else:
            emit(Notice("warning", f"activation failed ({exc}); rolling back to the previous table"))
            try:
                controller.rollback_table()
                note = "rolled back to the previous table"
            except Exception as rb_exc:  # noqa: BLE001 - reported, the original error is raised
                note = f"roll back failed too ({rb_exc}); deactivate the table on the controller before moving"
            emit(Notice("warning", note))
        exc.add_note(note)
        raise
    t_act = time.perf_counter() - t0
    final = _crcs(controller) or {}
    total = time.perf_counter() - t_start
    emit(Notice("info", f"correction table active, CRC-32 {crc:#010x} ({total:.2f} s)"))
    return UploadReport(crc, table.n_values, t_up, t_rb, t_st, t_act, total,
                        staged_crc32=None if before is None else before.get("staged"),
                        active_crc32=final.get("active"), previous_crc32=final.get("previous"))


def _crc_text(crc: int | None) -> str:
    return "none" if not crc else f"{crc:08x}"


@dataclass(frozen=True)
class TableState:
    """Which correction table the controller applies: the CRC-32 of its active table as 8 hex
    digits, or ``"none"``. A run records it before it changes anything and again at its end."""

    active: str

    @classmethod
    def read(cls, controller: TableController) -> TableState | None:
        crcs = _crcs(controller)
        return None if crcs is None else cls(_crc_text(crcs.get("active")))


def restore_table(controller: TableController, wanted: TableState, emit: Callable[[Event], None],
                  data: CorrectionTableData | None = None) -> TableState:
    """Make ``wanted`` the active table again: the table the operator had before this run, or
    none. The controller keeps the table active before the last activation as its previous one
    (``docs/robot-program.md``), so the table of the start of a run is either still active,
    bypassed by a deactivation, or the previous one: a roll back or a deactivation brings it back,
    and its CRC-32 confirms it. Where the controller no longer holds it (the oracle check of a
    simulated run pushes it out), ``data`` - the table as read from the controller when the run
    started - is uploaded again through the verified upload. Raises :class:`TableVerifyError`
    naming the CRCs when neither is possible (nothing else is activated then)."""
    now = _crcs(controller)
    if now is None:
        raise TableVerifyError(f"the controller's table CRCs could not be read: restore table {wanted.active} by hand "
                               f"(station export of the run that uploaded it), then check 'station check'")
    if _crc_text(now.get("active")) == wanted.active:
        return wanted
    if wanted.active == "none":
        controller.deactivate_table()
    elif _crc_text(now.get("previous")) == wanted.active:
        controller.rollback_table()
    elif data is not None and _crc_text(data.crc32()) == wanted.active:
        verified_upload(controller, data, emit)
    else:
        raise TableVerifyError(
            f"the table that was active before this run (CRC-32 {wanted.active}) is no longer on the controller "
            f"(active {_crc_text(now.get('active'))}, previous {_crc_text(now.get('previous'))}); nothing else was "
            f"activated: upload it again from the run that made it")
    after = TableState.read(controller)
    if after is None or after.active != wanted.active:
        raise TableVerifyError(f"restoring table {wanted.active} did not take: the controller reports "
                               f"{'unreadable CRCs' if after is None else after.active}; check the robot program")
    emit(Notice("info", "the table active before this run is active again" if wanted.active != "none"
                else "no correction table is active, as before this run"))
    return after
