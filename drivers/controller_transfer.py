"""The transfer block of map 2: the correction table in pages, and the info pages.

Everything that does not fit the 128-register window travels through one block of it
(``xfer_seq .. page_data``, :mod:`drivers.controller_map`): the PC writes a request - a new
``xfer_seq``, the operation, the page index, and for a write the page's length, CRC-32 and data -
in ONE FC 16 request; the robot program carries it out and answers with ``xfer_ack = xfer_seq``
and ``xfer_error`` (0 done). For a read it first fills the page fields with its stored page. A
request is never re-sent automatically (a missing answer raises :class:`HandshakeTimeout`).

:class:`TablePager` is mixed into :class:`drivers.controller.ModbusController`; it uses only the
driver's register I/O (``_read``/``_write`` at window offsets).
"""

from __future__ import annotations

import threading
import time
from typing import Callable, Sequence

import numpy as np

from .controller_errors import HandshakeTimeout
from .controller_map import (
    INFO_PAGES,
    MAX_TABLE_VALUES,
    PAGE_DATA_REGISTERS,
    REG,
    TABLE_HDR,
    TABLE_HEADER_REGISTERS,
    ErrorCode,
    RegisterDecodeError,
    WordOrder,
    XferOp,
    decode,
    encode,
    registers_crc32,
)
from .correction_table import TablePageError, WireTable, n_value_pages, table_from_registers

__all__ = ["TablePager", "PageRead"]

_ACK = REG["xfer_ack"].address
_SEQ = REG["xfer_seq"].address
_END = REG["page_data"].end
#: one read from xfer_ack to the end of the page data (85 registers) carries answer and page
_SPAN = _END - _ACK
_LEN_AT = REG["page_len"].address - _ACK
_CRC_AT = REG["page_crc"].address - _ACK
_DATA_AT = REG["page_data"].address - _ACK
_INDEX_AT = REG["page_index"].address - _ACK


_SLOT_OPS = {None: (XferOp.READ_HEADER, XferOp.READ_PAGE),
             "staged": (XferOp.READ_STAGED_HEADER, XferOp.READ_STAGED_PAGE),
             "active": (XferOp.READ_ACTIVE_HEADER, XferOp.READ_ACTIVE_PAGE),
             "previous": (XferOp.READ_PREVIOUS_HEADER, XferOp.READ_PREVIOUS_PAGE)}


class PageRead:
    """One page as the controller filled it: index, used data registers and its CRC-32."""

    def __init__(self, index: int, data: list[int], crc: int):
        self.index, self.data, self.crc = index, data, crc


class TablePager:
    """The transfer-block side of the driver (mixin; the host supplies the attributes below)."""

    word_order: WordOrder
    ack_timeout: float
    poll_interval: float
    _xfer_seq: int
    _xfer_lock: threading.RLock

    # what the host (the driver) supplies: declared, not defined, so nothing here can shadow it
    _read: Callable[[int, int], list[int]]
    _write: Callable[[int, Sequence[int]], None]
    _check_link: Callable[[], None]
    table_crcs: Callable[[], dict[str, int]]

    # -- one request -----------------------------------------------------------------------
    def _xfer(self, op: XferOp, index: int, data: Sequence[int] | None = None) -> list[int]:
        """Send one transfer request and wait for its answer; returns the registers
        ``xfer_ack .. page_data`` read with the answer. Raises :class:`TablePageError` when
        the program refuses it, :class:`HandshakeTimeout` when it does not answer."""
        with self._xfer_lock:
            seq = self._xfer_seq % 0xFFFF + 1
            self._xfer_seq = seq  # consumed even if the write fails: never reuse a number
            block = [seq, int(op), int(index)]
            if data is not None:
                if len(data) > PAGE_DATA_REGISTERS:
                    raise ValueError(f"a page holds at most {PAGE_DATA_REGISTERS} registers, got {len(data)}")
                block += [len(data)] + encode("page_crc", registers_crc32(data), self.word_order) + list(data)
            self._write(_SEQ, block)
            deadline = time.monotonic() + self.ack_timeout
            while True:
                regs = self._read(_ACK, _SPAN)
                if regs[0] == seq:
                    break
                if time.monotonic() >= deadline:
                    raise HandshakeTimeout(
                        f"transfer {op.name} page {index} (xfer_seq {seq}) was not answered within "
                        f"{self.ack_timeout:.3g} s (xfer_ack is {regs[0]}); it was NOT re-sent: check that "
                        f"the robot program serves the transfer block (docs/robot-program.md)")
                time.sleep(self.poll_interval)
        err = regs[1]
        if err:
            try:
                what = ErrorCode(err).name
            except ValueError:
                what = f"unknown error code {err}"
            raise TablePageError(f"the controller refused transfer {op.name} of page {index}: {what}; "
                                 f"nothing was staged from it: upload the table again")
        return regs

    def _read_page(self, op: XferOp, index: int) -> PageRead:
        """A read request: the controller's stored page ``index``, its CRC checked."""
        regs = self._xfer(op, index)
        n = regs[_LEN_AT]
        got = regs[_INDEX_AT]
        if got != index or n > PAGE_DATA_REGISTERS:
            raise TablePageError(f"read-back of {op.name} page {index}: the controller filled page {got} "
                                 f"with {n} registers: the robot program does not serve reads as documented")
        data = regs[_DATA_AT:_DATA_AT + n]
        crc = int(decode("page_crc", regs[_CRC_AT:_CRC_AT + 2], self.word_order))
        if registers_crc32(data) != crc:
            raise TablePageError(f"read-back of {op.name} page {index}: its data have CRC-32 "
                                 f"{registers_crc32(data):#010x}, the page says {crc:#010x}: the link "
                                 f"corrupts data; upload the table again")
        return PageRead(index, data, crc)

    # -- info pages ------------------------------------------------------------------------
    def _read_info_raw(self, name: str) -> list[int]:
        """The raw registers of info entry ``name`` (``soft_limits``, ``act_pose``)."""
        number, reg = INFO_PAGES[name]
        page = self._read_page(XferOp.READ_INFO, number)
        if len(page.data) < reg.end:
            raise RegisterDecodeError(f"info page {number} ({name}) holds {len(page.data)} registers, "
                                      f"expected {reg.end}")
        return page.data[reg.address:reg.end]

    def _read_info(self, name: str) -> np.ndarray:
        return np.asarray(decode(INFO_PAGES[name][1], self._read_info_raw(name), self.word_order), dtype=float)

    # -- the table -------------------------------------------------------------------------
    def _send_table_pages(self, header: list[int], pages: list[list[int]]) -> None:
        self._xfer(XferOp.WRITE_HEADER, 0, header)
        for k, page in enumerate(pages):
            self._xfer(XferOp.WRITE_PAGE, k, page)

    def _read_table_pages(self, slot: str | None = None) -> tuple[list[int], list[int]]:
        """Header page and all value registers as the controller stores them: the transfer
        buffer (``slot`` None: the read-back of an upload), or the table in slot ``staged``,
        ``active`` or ``previous``."""
        op_header, op_page = _SLOT_OPS[slot]
        header = self._read_page(op_header, 0).data
        if len(header) < TABLE_HEADER_REGISTERS:
            raise TablePageError(f"the controller's header page holds {len(header)} registers, expected "
                                 f"{TABLE_HEADER_REGISTERS}: no table was uploaded")
        r = TABLE_HDR["table_n_values"]
        n_values = int(decode(r, header[r.address:r.end], self.word_order))
        if n_values > MAX_TABLE_VALUES:
            raise TablePageError(f"the controller's header page says {n_values} values; at most "
                                 f"{MAX_TABLE_VALUES} are possible: the stored header is not a table")
        data: list[int] = []
        for k in range(n_value_pages(n_values)):
            data += self._read_page(op_page, k).data
        return header, data

    def read_slot_table(self, slot: str) -> WireTable | None:
        """The table the controller holds in ``slot`` (``staged``, ``active`` or ``previous``),
        each page's CRC and the whole table's CRC-32 checked; None when the slot is empty. Reads
        only: the upload interlock is not touched."""
        if slot not in ("staged", "active", "previous"):
            raise ValueError(f"slot must be staged, active or previous, got {slot!r}")
        self._check_link()
        if not self.table_crcs()[slot]:
            return None
        header, data = self._read_table_pages(slot)
        return table_from_registers(header, data, self.word_order)
