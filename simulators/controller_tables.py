"""The simulated robot program's correction tables: staged, active and previous.

Implements the table commands of the handshake (``docs/protocols.md``, section "Correction
table") on the staging area of the register image, and the correction that the active table
adds to the nominal inverse kinematics of a Cartesian target. Used by
:class:`simulators.controller_server.SimulatedController`, which holds its lock around every call.
"""

from __future__ import annotations

import zlib
from typing import Sequence

import numpy as np

from drivers.controller_map import (
    TABLE_DATA_ADDRESS,
    Command,
    ErrorCode,
    StatusBit,
    WordOrder,
    decode_f32_array,
    register_span,
)
from drivers.correction_table import CorrectionTableData, TableError

__all__ = ["TableSlots"]

_HDR_FIRST, _HDR_COUNT = register_span("table_format", "table_crc")


class TableSlots:
    """The three tables of the robot program. Not thread-safe: the caller holds its lock."""

    def __init__(self, crc_little_endian: bool = False) -> None:
        #: fault injection (quirk ``crc_mismatch``): the CRC over little-endian f32 bytes, which
        #: the protocol forbids; False is the documented big-endian rule
        self.crc_little_endian = crc_little_endian
        self.staged: CorrectionTableData | None = None
        self.active: CorrectionTableData | None = None
        self.previous: CorrectionTableData | None = None

    def stage(self, regs: Sequence[int], word_order: WordOrder, n_joints: int) -> ErrorCode:
        """TABLE_STAGE: check header and CRC of the staging area in the register image ``regs``
        and keep it as the staged table."""
        header = regs[_HDR_FIRST:_HDR_FIRST + _HDR_COUNT]
        try:
            h = CorrectionTableData.decode_header(header, word_order)
        except TableError:
            return ErrorCode.TABLE_SHAPE_INVALID
        data = regs[TABLE_DATA_ADDRESS:TABLE_DATA_ADDRESS + 2 * h["n_values"]]
        vals = decode_f32_array(data, word_order)
        if h["n_joints"] != n_joints or not np.all(np.isfinite(vals)):
            return ErrorCode.TABLE_SHAPE_INVALID
        byte_order = "<f4" if self.crc_little_endian else ">f4"
        if zlib.crc32(vals.astype(byte_order).tobytes()) & 0xFFFFFFFF != h["crc"]:
            return ErrorCode.TABLE_CRC_MISMATCH
        shape = (h["n_configs"], *[a.count for a in h["axes"]], h["n_joints"])
        self.staged = CorrectionTableData(h["axes"], vals.reshape(shape))
        return ErrorCode.NONE

    def switch(self, cmd: Command) -> ErrorCode:
        """TABLE_ACTIVATE, TABLE_DEACTIVATE or TABLE_ROLLBACK (anything else is a bad command)."""
        if cmd is Command.TABLE_ACTIVATE:
            if self.staged is None:
                return ErrorCode.TABLE_NOT_STAGED
            self.previous, self.active, self.staged = self.active, self.staged, None
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
        when no table is active). Raises :class:`drivers.correction_table.TableRangeError`."""
        table = self.active
        if table is None:
            return q
        cfg = 0 if (elbow == 1 or table.n_configs == 1) else 1
        point = np.array([pose[0], pose[1], pose[2], pose[5]])[:len(table.axes)]
        return q + table.interpolate(point, cfg)
