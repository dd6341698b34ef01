"""The simulated robot program's correction tables: staged, active and previous.

Implements the table side of the robot program (``docs/protocols.md``, section "Correction
table"): the pages written through the transfer block (header page and value pages, each
checked against its page CRC), the table commands of the handshake on them, and the correction
that the active table adds to the nominal inverse kinematics of a Cartesian target. Words, header,
CRCs and interpolation are the program's own (:mod:`simulators.program_words`), not the driver's
codec. Used by
:class:`simulators.controller_server.SimulatedController`, which holds its lock around every call.
"""

from __future__ import annotations

import zlib
from typing import Callable

import numpy as np

from drivers.controller_map import (
    MAX_TABLE_VALUES,
    PAGE_DATA_REGISTERS,
    REG,
    Command,
    ErrorCode,
    StatusBit,
    WordOrder,
    XferOp,
)
from simulators.program_words import (
    HEADER_REGISTER_COUNT,
    PAGE_VALUE_COUNT,
    VALUE_SCALE,
    ProgramTable,
    counts_from_words,
    crc32_of_counts,
    crc32_of_registers,
    get_value,
    header_page,
    put_value,
    read_header,
    value_page_words,
    words_from_counts,
)

__all__ = ["TableSlots", "serve_transfer"]

#: value pages the store holds (a table of MAX_TABLE_VALUES values: 1104)
MAX_PAGES = -(-MAX_TABLE_VALUES // PAGE_VALUE_COUNT)


class TableSlots:
    """The three tables of the robot program. Not thread-safe: the caller holds its lock."""

    def __init__(self, crc_little_endian: bool = False, quirks: frozenset[str] = frozenset()) -> None:
        #: fault injection (quirk ``crc_mismatch``): the CRC over little-endian i32 bytes, which
        #: the protocol forbids; False is the documented big-endian rule
        self.crc_little_endian = crc_little_endian
        #: the table quirks of :data:`simulators.controller_faults.QUIRKS` it plays
        self.quirks = quirks
        #: the pages as the PC wrote them: the header page, value page k (data registers)
        self.header: list[int] | None = None
        self.pages: dict[int, list[int]] = {}
        self.staged: ProgramTable | None = None
        self.active: ProgramTable | None = None
        self.previous: ProgramTable | None = None

    def store(self, header: bool, index: int, data: list[int]) -> ErrorCode:
        """A page written through the transfer block (its page CRC already checked). A header
        page starts a new table: the stored value pages are dropped."""
        if header:
            if index != 0 or len(data) != HEADER_REGISTER_COUNT:
                return ErrorCode.PAGE_INVALID
            self.header, self.pages = list(data), {}
            return ErrorCode.NONE
        if not 0 <= index < MAX_PAGES or not data or len(data) % 2 or len(data) > PAGE_DATA_REGISTERS:
            return ErrorCode.PAGE_INVALID
        self.pages[index] = list(data)
        return ErrorCode.NONE

    def slot_page(self, slot: str, header: bool, index: int, word_order: WordOrder) -> list[int] | None:
        """Header page or value page ``index`` of the table in ``slot`` (staged, active,
        previous), as the PC would have sent it; None when the slot is empty or no such page."""
        table = getattr(self, slot)
        if table is None:
            return None
        if header:
            return header_page(table, word_order) if index == 0 else None
        pages = value_page_words(table, word_order)
        return pages[index] if 0 <= index < len(pages) else None

    def stored(self, header: bool, index: int) -> list[int] | None:
        """The stored header page, or value page ``index`` (None if there is none)."""
        if header:
            return self.header if index == 0 else None
        return self.pages.get(index)

    def stage(self, word_order: WordOrder, n_joints: int) -> ErrorCode:
        """TABLE_STAGE: check the stored header, that every value page is there, and the
        values' CRC-32, and keep the table as the staged one."""
        if self.header is None:
            return ErrorCode.TABLE_SHAPE_INVALID
        h = read_header(self.header, word_order)
        if h is None:
            return ErrorCode.TABLE_SHAPE_INVALID
        n_pages = -(-h["n_values"] // PAGE_VALUE_COUNT)
        if any(k not in self.pages for k in range(n_pages)) or h["n_joints"] != n_joints:
            return ErrorCode.TABLE_SHAPE_INVALID
        data = [w for k in range(n_pages) for w in self.pages[k]]
        if len(data) != 2 * h["n_values"]:
            return ErrorCode.TABLE_SHAPE_INVALID
        raw = counts_from_words(data, word_order)
        crc = (zlib.crc32(raw.astype("<i4").tobytes()) & 0xFFFFFFFF if self.crc_little_endian
               else crc32_of_counts(raw))
        if crc != h["crc"]:
            return ErrorCode.TABLE_CRC_MISMATCH
        shape = (h["n_configs"], *[a.count for a in h["axes"]], h["n_joints"])
        self.staged = ProgramTable(h["axes"], raw.reshape(shape))
        return ErrorCode.NONE

    def corrupt_value(self, index: int, delta: float, word_order: WordOrder) -> None:
        """Fault injection: value ``index`` of the stored pages changes by ``delta``."""
        page, at = divmod(index, PAGE_VALUE_COUNT)
        data = self.pages[page]
        raw = int(counts_from_words(data[2 * at:2 * at + 2], word_order)[0])
        data[2 * at:2 * at + 2] = words_from_counts([raw + int(round(delta / VALUE_SCALE))], word_order)

    def switch(self, cmd: Command) -> ErrorCode:
        """TABLE_ACTIVATE, TABLE_DEACTIVATE, TABLE_ROLLBACK or TABLE_DISCARD_PREVIOUS (anything
        else is a bad command); ``docs/robot-program.md`` gives the slot rules."""
        if cmd is Command.TABLE_ACTIVATE:
            if self.staged is None and "activate_unstaged" in self.quirks:
                return self.switch(Command.TABLE_DEACTIVATE)
            if self.staged is None:
                return ErrorCode.TABLE_NOT_STAGED
            # activating over none keeps the previous table: the one a deactivation set aside
            # (the operator's table during "verify before") stays the one a roll back revives
            if self.active is not None or "activate_drops_previous" in self.quirks:
                self.previous = self.active
            self.active, self.staged = self.staged, None
            return ErrorCode.NONE
        if cmd is Command.TABLE_DISCARD_PREVIOUS:
            self.previous = None
            return ErrorCode.NONE
        if cmd is Command.TABLE_DEACTIVATE:
            if self.active is not None:
                self.previous, self.active = self.active, None
            return ErrorCode.NONE
        if cmd is Command.TABLE_ROLLBACK:
            if self.previous is None:
                return ErrorCode.NO_PREVIOUS_TABLE
            self.previous, self.active = self.active, self.previous
            return ErrorCode.NONE
        return ErrorCode.BAD_COMMAND

    def status_bits(self, bits: StatusBit) -> StatusBit:
        """``bits`` with the three table bits set from the slots."""
        bits = bits | StatusBit.TABLE_ACTIVE if self.active is not None else bits & ~StatusBit.TABLE_ACTIVE
        bits = bits | StatusBit.TABLE_STAGED if self.staged is not None else bits & ~StatusBit.TABLE_STAGED
        bits = (bits | StatusBit.TABLE_PREVIOUS if self.previous is not None
                else bits & ~StatusBit.TABLE_PREVIOUS)
        return StatusBit(bits)

    def crcs(self) -> dict[str, int]:
        """CRC-32 per slot, 0 for an empty one (the ``table_<slot>_crc`` registers)."""
        return {k: 0 if t is None else t.crc32()
                for k, t in (("staged", self.staged), ("active", self.active), ("previous", self.previous))}

    def correct(self, q: np.ndarray, pose: np.ndarray, elbow: int) -> np.ndarray:
        """Nominal IK joints ``q`` for ``pose`` plus the active table's correction (``q`` itself
        when no table is active): the interpolation rule, step 3. Raises
        :class:`simulators.program_words.OutsideTable`."""
        table = self.active
        if table is None:
            return q
        cfg = 0 if (elbow == 1 or table.n_configs == 1) else 1
        point = [pose[0], pose[1], pose[2], pose[5]][:len(table.axes)]
        return q + table.correction(point, cfg)


_SLOT_READS = {XferOp.READ_STAGED_HEADER: ("staged", True), XferOp.READ_STAGED_PAGE: ("staged", False),
               XferOp.READ_ACTIVE_HEADER: ("active", True), XferOp.READ_ACTIVE_PAGE: ("active", False),
               XferOp.READ_PREVIOUS_HEADER: ("previous", True), XferOp.READ_PREVIOUS_PAGE: ("previous", False)}
_READS = {XferOp.READ_HEADER, XferOp.READ_PAGE, XferOp.READ_INFO, *_SLOT_READS}


def serve_transfer(regs: list[int], tables: TableSlots, word_order: WordOrder,
                   info_page: Callable[[int], list[int] | None], corrupt: bool = False) -> None:
    """Carry out the transfer request in the register image ``regs`` (by window offset): store
    a written page after checking its length and page CRC, or fill the page fields with a stored
    page or info page; then answer in ``xfer_error`` and ``xfer_ack``. ``corrupt``: the page
    arrived with one bit flipped (fault injection)."""

    def get(name: str) -> int:
        return int(get_value(regs, REG[name], word_order))

    def put(name: str, value: int) -> None:
        put_value(regs, REG[name], value, word_order)

    op, index, n = get("xfer_op"), get("page_index"), get("page_len")
    a = REG["page_data"].address
    error = ErrorCode.NONE
    if op in (XferOp.WRITE_HEADER, XferOp.WRITE_PAGE):
        data = regs[a:a + min(n, PAGE_DATA_REGISTERS)]
        if corrupt and data:
            data = [data[0] ^ 0x0001, *data[1:]]
        if n > PAGE_DATA_REGISTERS:
            error = ErrorCode.PAGE_INVALID
        elif crc32_of_registers(data) != get("page_crc") and "page_crc_ignored" not in tables.quirks:
            error = ErrorCode.PAGE_CRC_MISMATCH
        else:
            error = tables.store(op == XferOp.WRITE_HEADER, index, data)
    elif op in _SLOT_READS and "no_slot_reads" in tables.quirks:
        error = ErrorCode.PAGE_INVALID
    elif op in _READS:
        if op == XferOp.READ_INFO:
            page = info_page(index)
        elif op in (XferOp.READ_HEADER, XferOp.READ_PAGE):
            page = tables.stored(op == XferOp.READ_HEADER, index)
        else:
            slot, header = _SLOT_READS[XferOp(op)]
            page = tables.slot_page(slot, header, index, word_order)
        if page is None:
            error = ErrorCode.PAGE_INVALID
        else:
            regs[a:a + PAGE_DATA_REGISTERS] = list(page) + [0] * (PAGE_DATA_REGISTERS - len(page))
            put("page_len", len(page))
            put("page_crc", crc32_of_registers(page))
    else:
        error = ErrorCode.PAGE_INVALID
    put("xfer_error", int(error))
    put("xfer_ack", get("xfer_seq"))
