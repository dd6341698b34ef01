"""The controller's table slots as the conformance kit found them, and how it puts them back.

Before its first command the kit reads the three slots (staged, active, previous): each one's
CRC-32 and, for a slot that holds a table, the table itself through the slot reads
(``READ_<SLOT>_HEADER`` / ``READ_<SLOT>_PAGE``). When a table cannot be read, the kit changes no
slot at all (:attr:`_KitBase.why_not_tables`): it would destroy a table it cannot put back.

After the checks the slots are rebuilt with the map's own slot rules, from empty: a staged
table is replaced by a zero table and activated (only an activation empties the staged slot),
then deactivate and discard the previous table; the previous table P (if any): upload, stage,
activate (active P, previous none); the active table A (if any): upload, stage, activate
(active A, previous P); with no A but a P: deactivate (active none, previous P); finally the
staged table S (if any): upload and stage. The three CRCs are then compared with those found:
any difference fails ``slots_restored`` and leaves a loud note.
"""

from __future__ import annotations

import numpy as np

from drivers.controller_errors import ControllerConnectionError
from drivers.controller_map import Command, ControllerError
from station.cell.conformance.kit import _KitBase
from station.core.table.values import CorrectionTableData, TableAxis

__all__ = ["SLOTS", "fmt_crcs"]

SLOTS = ("staged", "active", "previous")


def fmt_crcs(crcs: dict[str, int]) -> str:
    return ", ".join(f"{k} {crcs[k]:#010x}" for k in SLOTS)


class _NotRestored(Exception):
    pass


class _SlotKeeper(_KitBase):
    def read_slots(self) -> None:
        """The slots as found; sets :attr:`why_not_tables` when a table cannot be read back."""
        link, r = self.link, self.req["slot_reads"]
        self.crc0 = link.table_crcs()
        self.found = {}
        unread: list[str] = []
        for slot in SLOTS:
            crc = self.crc0[slot]
            self.found[slot] = None
            if not crc:
                continue
            ops = f"READ_{slot.upper()}_HEADER / READ_{slot.upper()}_PAGE"
            try:
                table = link.read_slot_table(slot)
            except ControllerConnectionError:
                raise
            except ControllerError as exc:
                unread.append(f"the {slot} table (CRC-32 {crc:#010x}) cannot be read back ({exc})")
                r.failed(f"{ops} for the {slot} table found (CRC-32 {crc:#010x}): {exc}",
                         f"serve {ops}: the header page and value pages of the {slot} table, regenerated from it")
                continue
            if table is None or table.crc32() != crc:
                got = "no table" if table is None else f"a table with CRC-32 {table.crc32():#010x}"
                unread.append(f"the {slot} slot read answered {got}, not the slot's {crc:#010x}")
                r.failed(f"{ops} answered {got}; table_{slot}_crc is {crc:#010x}",
                         f"answer {ops} with the table in the {slot} slot")
                continue
            self.found[slot] = CorrectionTableData.from_table(table)
            r.passed(f"{ops}: the {slot} table found ({table.n_values} values, CRC-32 {crc:#010x})")
        self.why_not_tables = ("; ".join(unread) + ": the kit changes no table slot, so it never destroys a table "
                               "it could not put back") if unread else ""

    # -- putting them back ------------------------------------------------------------------
    def _do(self, code: Command) -> None:
        a = self._command(code)
        if a.result != "done":
            raise _NotRestored(a.describe())

    def _restage(self, t: CorrectionTableData) -> None:
        self.link.upload_table(t)
        self.link.verify_table()
        self._do(Command.TABLE_STAGE)
        staged = self.link.table_crcs()["staged"]
        if staged != t.crc32():
            raise _NotRestored(f"table {t.crc32():#010x} staged as {staged:#010x}")

    def _rebuild(self) -> None:
        if self.link.table_crcs()["staged"]:
            # only an activation empties the staged slot: of a zero table (nothing moves meanwhile)
            self._restage(CorrectionTableData((TableAxis(0.0, 1.0, 1),), np.zeros((1, 1, self.g))))
            self._do(Command.TABLE_ACTIVATE)
        self._do(Command.TABLE_DEACTIVATE)
        self._do(Command.TABLE_DISCARD_PREVIOUS)
        staged, active, previous = (self.found.get(k) for k in SLOTS)
        if previous is not None:
            self._restage(previous)
            self._do(Command.TABLE_ACTIVATE)  # active P, previous none
        if active is not None:
            self._restage(active)
            self._do(Command.TABLE_ACTIVATE)  # active A, previous P (or none)
        elif previous is not None:
            self._do(Command.TABLE_DEACTIVATE)  # active none, previous P
        if staged is not None:
            self._restage(staged)

    def restore_slots(self) -> None:
        """Put the slots back as found (when the kit changed them and may), then compare."""
        r = self.req["slots_restored"]
        if not self.crc0:
            r.not_checked("the slots were not read")
            return
        link = self.link
        problem = ""
        if link.table_crcs() != self.crc0 and not self.why_not_tables:
            try:
                self._rebuild()
            except ControllerConnectionError:
                raise
            except (_NotRestored, ControllerError) as exc:
                problem = f" (putting them back stopped: {exc})"
        after = link.table_crcs()
        if after == self.crc0:
            r.passed(f"slots as found: {fmt_crcs(after)}")
            return
        r.failed(f"the slots hold {fmt_crcs(after)}; the kit found {fmt_crcs(self.crc0)}{problem}",
                 "put the controller's tables back by hand before the next run (upload the operator's table with "
                 "the station, or roll back on the controller); then fix the slot rules the other requirements "
                 "name (docs/robot-program.md)")
        self.notes.append(f"THE CONTROLLER'S TABLE SLOTS ARE NOT AS THE KIT FOUND THEM: now {fmt_crcs(after)}, found "
                          f"{fmt_crcs(self.crc0)}: restore them before the robot moves with a correction table")
