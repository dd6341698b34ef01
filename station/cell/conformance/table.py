"""The conformance checks of the correction table on register map 3: the table through the
transfer block (pages written and read back, the page CRC and page refusals, the whole-table
CRC-32, TABLE_STAGE), the slot reads, and the slot rules of TABLE_ACTIVATE, TABLE_DEACTIVATE,
TABLE_ROLLBACK and TABLE_DISCARD_PREVIOUS. The slots the kit found are put back afterwards by
:mod:`station.cell.conformance.slots`; nothing here changes a slot unless that is possible.
"""

from __future__ import annotations

import numpy as np

from drivers.controller_map import (
    MAX_TABLE_VALUES,
    PAGE_DATA_REGISTERS,
    TABLE_HDR,
    Command,
    ErrorCode,
    XferOp,
    encode,
    registers_crc32,
)
from drivers.correction_table import (
    TableError,
    header_registers,
    n_value_pages,
    value_pages,
)
from station.cell.conformance.kit import _KitBase
from station.cell.conformance.report import FAILED, Requirement
from station.cell.conformance.slots import SLOTS, fmt_crcs
from station.core.table.values import CorrectionTableData, TableAxis

_CRC_FIX = ("compute the CRC-32 (zlib / ISO-HDLC, check value CRC('123456789') = 0xCBF43926) over the values as "
            "big-endian i32 (each raw count's four two's-complement bytes, most significant first) in C order, "
            "independent of the link's word order")
_SLOT_FIX = ("TABLE_ACTIVATE: if a table is active, previous := active; active := staged; staged := none. "
             "TABLE_DEACTIVATE: if a table is active, previous := active; active := none. TABLE_ROLLBACK: swap "
             "active and previous, NO_PREVIOUS_TABLE (14) without a previous table. Publish the three CRCs and the "
             "TABLE_* status bits")


class _SlotStepFailed(Exception):
    """A step of the slot checks did not end as the rules say: the later steps, which start from
    its result, are not run."""


class _TableChecks(_KitBase):
    def _tables(self) -> tuple[CorrectionTableData, CorrectionTableData, CorrectionTableData]:
        """The kit's test tables: ``t1`` (three value pages, never activated) and two zero tables
        of different sizes (different CRCs), the only ones the kit ever activates."""
        g = self.g
        n = 2 * 8 * g
        t1 = CorrectionTableData((TableAxis(300.0, 50.0, 8),), (np.arange(n, dtype=float).reshape(2, 8, g) - n / 2) * 1e-4)
        z1 = CorrectionTableData((TableAxis(0.0, 1.0, 1),), np.zeros((1, 1, g)))
        z2 = CorrectionTableData((TableAxis(0.0, 1.0, 2),), np.zeros((1, 2, g)))
        return t1, z1, z2

    # -- the table through the transfer block ------------------------------------------------
    def table(self) -> None:
        r = self.req["table"]
        link = self.link
        t1, _z1, _z2 = self._tables()
        link.upload_table(t1)
        try:
            link.verify_table()
        except TableError as exc:
            r.failed(f"read-back of a {t1.n_values}-value test table: {exc}",
                     "keep the header page and every value page exactly as the PC wrote them, and serve READ_HEADER "
                     "and READ_PAGE with them (page_len, page_crc, page_data)")
            return
        r.passed(f"{t1.n_values}-value test table written in {len(value_pages(t1))} value pages and read back bit "
                 f"for bit")
        if self.why_not_tables:
            r.not_checked(f"TABLE_STAGE: {self.why_not_tables}", "serve the slot reads, then run the kit again")
            return
        # a header whose CRC-32 does not match the values: every page is right, so only the
        # whole-table CRC can tell
        header = header_registers(t1, link.word_order)
        crc = TABLE_HDR["table_crc"]
        header[crc.address:crc.end] = encode(crc, t1.crc32() ^ 0xFFFFFFFF, link.word_order)
        errors = [link.raw_transfer(XferOp.WRITE_HEADER, 0, header)]
        errors += [link.raw_transfer(XferOp.WRITE_PAGE, k, p) for k, p in enumerate(value_pages(t1, link.word_order))]
        a = self._command(Command.TABLE_STAGE)
        if any(errors):
            r.failed(f"pages of a table with a wrong header CRC were refused: xfer_error {errors}",
                     "store every page whose page CRC matches; check the whole-table CRC only on TABLE_STAGE")
        elif a.error_is(ErrorCode.TABLE_CRC_MISMATCH):
            r.passed("a header CRC-32 that does not match the values: TABLE_STAGE refused with TABLE_CRC_MISMATCH")
        else:
            r.failed(f"TABLE_STAGE with a wrong header CRC-32: {a.describe()}",
                     "on TABLE_STAGE compute the CRC-32 of the stored values and refuse a mismatch with "
                     "TABLE_CRC_MISMATCH (7)")
        link.upload_table(t1)
        link.verify_table()
        if self._stage(t1, r):
            self._slot_read("staged", t1)

    def _stage(self, t: CorrectionTableData, r: Requirement, quiet: bool = False) -> bool:
        a = self._command(Command.TABLE_STAGE)
        staged = self.link.table_crcs()["staged"]
        if a.error_is(ErrorCode.TABLE_CRC_MISMATCH):
            r.failed(f"TABLE_STAGE of a correct table (CRC-32 {t.crc32():#010x}): TABLE_CRC_MISMATCH", _CRC_FIX)
            return False
        if a.result != "done" or staged != t.crc32() or not self.link.status().table_staged:
            r.failed(f"TABLE_STAGE: {a.describe()}; table_staged_crc {staged:#010x}, expected {t.crc32():#010x}",
                     "on TABLE_STAGE keep the checked table as the staged one, publish its CRC in table_staged_crc "
                     "and set the TABLE_STAGED bit")
            return False
        r.passed("" if quiet else f"TABLE_STAGE: staged CRC-32 {staged:#010x} matches")
        return True

    # -- page refusals ------------------------------------------------------------------------
    def pages(self) -> None:
        r = self.req["pages"]
        link = self.link
        t1, _z1, _z2 = self._tables()
        link.upload_table(t1)
        page = value_pages(t1, link.word_order)[0]
        flipped = [page[0] ^ 0x0001, *page[1:]]
        err = link.raw_transfer(XferOp.WRITE_PAGE, 0, flipped, crc=registers_crc32(page))
        if err == ErrorCode.PAGE_CRC_MISMATCH:
            r.passed("a value page with one bit flipped against its page CRC: PAGE_CRC_MISMATCH")
        else:
            r.failed(f"a value page whose data do not match its page CRC: xfer_error {err}",
                     "check every written page: CRC-32 over its page_len data registers, each high byte first, "
                     "must equal page_crc, else answer xfer_error = PAGE_CRC_MISMATCH (15) and keep the old page")
        no_page = n_value_pages(MAX_TABLE_VALUES)
        invalid = (("an unknown operation 99", 99, 0, page, None),
                   (f"page_len {PAGE_DATA_REGISTERS + 1}", XferOp.WRITE_PAGE, 0, page, PAGE_DATA_REGISTERS + 1),
                   (f"value page {no_page} (beyond a {MAX_TABLE_VALUES}-value table)", XferOp.WRITE_PAGE, no_page,
                    page, None),
                   ("a header page of 29 registers", XferOp.WRITE_HEADER, 0,
                    header_registers(t1, link.word_order)[:29], None))
        for what, op, index, data, length in invalid:
            err = link.raw_transfer(op, index, data, length=length)
            if err == ErrorCode.PAGE_INVALID:
                r.passed(f"{what}: PAGE_INVALID")
            else:
                r.failed(f"{what}: xfer_error {err}, expected PAGE_INVALID",
                         "answer xfer_error = PAGE_INVALID (16) for an unknown xfer_op, page_len > 58, a value page "
                         "beyond the store (>= 1104), a header page that is not page 0 with 30 registers")
        try:
            link.verify_table()
            r.passed("after the refusals the stored table is still the one written")
        except TableError as exc:
            r.failed(f"after the refused pages the stored table changed: {exc}",
                     "a refused page changes nothing: keep the pages stored before it")

    # -- the slots ----------------------------------------------------------------------------
    def _slot_read(self, slot: str, want: CorrectionTableData) -> None:
        r = self.req["slot_reads"]
        ops = f"READ_{slot.upper()}_HEADER / READ_{slot.upper()}_PAGE"
        try:
            got = self.link.read_slot_table(slot)
        except TableError as exc:
            r.failed(f"{ops} for the kit's table (CRC-32 {want.crc32():#010x}): {exc}",
                     f"serve {ops}: the header page and value pages of the {slot} table, regenerated from it")
            return
        if got is None or not want.same_as(got):
            r.failed(f"{ops} answered {'no table' if got is None else f'a table with CRC-32 {got.crc32():#010x}'}; "
                     f"the {slot} slot holds {want.crc32():#010x}",
                     f"answer {ops} with the table in the {slot} slot, not the transfer buffer or another slot")
        else:
            r.passed(f"{ops}: the {slot} table ({want.n_values} values, CRC-32 {want.crc32():#010x})")

    def _load(self, t: CorrectionTableData) -> None:
        self.link.upload_table(t)
        self.link.verify_table()
        if not self._stage(t, self.req["table"], quiet=True):
            raise _SlotStepFailed(f"the kit's table {t.crc32():#010x} could not be staged")

    def _switch(self, code: Command, want: dict[str, int], rid: str, what: str, fix: str = _SLOT_FIX,
                error: ErrorCode | None = None) -> None:
        """Send one table command; its requirement passes when it ends done (or refused with
        ``error``) and the three slots hold ``want``, else fails and the sequence stops."""
        a = self._command(code)
        crcs = self.link.table_crcs()
        st = self.link.status()
        bits = {"staged": st.table_staged, "active": st.table_active, "previous": st.table_previous}
        answered = a.error_is(error) if error is not None else a.result == "done"
        ok = answered and crcs == want and all(bits[k] == bool(want[k]) for k in SLOTS)
        detail = f"{what}: {a.describe()}; slots now {fmt_crcs(crcs)}"
        if ok:
            self.req[rid].passed(detail)
            return
        self.req[rid].failed(f"{detail}, expected {fmt_crcs(want)} (TABLE_* bits {bits})", fix)
        raise _SlotStepFailed(f"{what} did not end as the slot rules say")

    def switching(self) -> None:
        """From whatever the kit found to known slots, then every slot rule once (the kit's
        zero tables only; no motion is commanded meanwhile)."""
        blocked = self.why_not_tables or ("" if self.link.table_crcs()["staged"] == self._tables()[0].crc32()
                                          else "the kit's test table could not be staged (see table)")
        if blocked:
            for rid in ("activation", "discard_previous", "keep_previous") + (() if self.req["slot_reads"].detail
                                                                              else ("slot_reads",)):
                self.req[rid].not_checked(blocked, "serve the slot reads, then run the kit again"
                                          if self.why_not_tables else "fix TABLE_STAGE first")
            return
        _t1, z1, z2 = self._tables()
        none = 0
        done: set[str] = set()  # the requirements whose every step ran
        try:
            self._load(z1)
            # activating over the table found (or over none, keeping the previous one found)
            c = self.link.table_crcs()
            self._switch(Command.TABLE_ACTIVATE, dict(staged=none, active=z1.crc32(),
                                                      previous=c["active"] or c["previous"]),
                         "activation", "TABLE_ACTIVATE over the table the kit found")
            self._slot_read("active", z1)
            self._switch(Command.TABLE_DEACTIVATE, dict(staged=none, active=none, previous=z1.crc32()),
                         "activation", "TABLE_DEACTIVATE")
            self._slot_read("previous", z1)
            self._switch(Command.TABLE_DISCARD_PREVIOUS, dict(staged=none, active=none, previous=none),
                         "discard_previous", "TABLE_DISCARD_PREVIOUS",
                         "TABLE_DISCARD_PREVIOUS (14): previous := none, clear TABLE_PREVIOUS and table_previous_crc")
            done.add("discard_previous")
            self._switch(Command.TABLE_ROLLBACK, dict(staged=none, active=none, previous=none), "activation",
                         "TABLE_ROLLBACK with no previous table", error=ErrorCode.NO_PREVIOUS_TABLE)
            self._load(z1)
            self._switch(Command.TABLE_ACTIVATE, dict(staged=none, active=z1.crc32(), previous=none),
                         "activation", "TABLE_ACTIVATE with all slots empty")
            self._load(z2)
            self._switch(Command.TABLE_ACTIVATE, dict(staged=none, active=z2.crc32(), previous=z1.crc32()),
                         "activation", "TABLE_ACTIVATE over an active table")
            self._slot_read("active", z2)
            self._slot_read("previous", z1)
            self._switch(Command.TABLE_ROLLBACK, dict(staged=none, active=z1.crc32(), previous=z2.crc32()),
                         "activation", "TABLE_ROLLBACK")
            self._switch(Command.TABLE_DEACTIVATE, dict(staged=none, active=none, previous=z1.crc32()),
                         "activation", "TABLE_DEACTIVATE")
            done.add("activation")
            self._load(z2)
            self._switch(Command.TABLE_ACTIVATE, dict(staged=none, active=z2.crc32(), previous=z1.crc32()),
                         "keep_previous", "TABLE_ACTIVATE with no active table and a previous one",
                         "TABLE_ACTIVATE while no table is active leaves the previous table as it is (the one a "
                         "deactivation set aside stays the one a roll back revives)")
        except _SlotStepFailed as exc:
            for rid in ("activation", "discard_previous", "keep_previous"):
                if rid not in done and self.req[rid].status != FAILED:
                    self.req[rid].not_checked(f"an earlier slot step failed ({exc})", "fix that step first")
