"""The conformance check of the correction-table commands: write and read back, CRC-32, stage,
activate, roll back; afterwards the controller's original active table restored (checked by CRC)
and the staging area's contents written back.
"""

from __future__ import annotations

import numpy as np

from drivers.controller_map import REG, Command, ErrorCode, encode, register_span
from drivers.correction_table import CorrectionTableData, TableAxis
from station.cell.conformance_kit import _KitBase
from station.cell.conformance_report import Requirement

_HDR_FIRST, _HDR_COUNT = register_span("table_format", "table_crc")


class _TableChecks(_KitBase):
    def table(self) -> None:
        r = self.req["table"]
        link, g = self.link, self.g
        crc0 = link.table_crcs()
        header0 = link.read_registers(_HDR_FIRST, _HDR_COUNT)
        data0: list[int] = []
        try:
            h0 = CorrectionTableData.decode_header(header0, link.word_order)
            data0 = link.read_registers(REG["table_data"].address, 2 * h0["n_values"])
        except Exception:  # noqa: BLE001 - no valid table in the staging area: nothing to keep
            h0 = None
        pattern = (np.arange(2 * 3 * g, dtype=float).reshape(2, 3, g) - 3.0 * g) * 1.0e-4
        t1 = CorrectionTableData((TableAxis(300.0, 50.0, 3),), pattern)
        t0 = CorrectionTableData((TableAxis(0.0, 1.0, 1),), np.zeros((1, 1, g)))
        crc_fix = ("compute the CRC-32 (zlib / ISO-HDLC, check value CRC('123456789') = 0xCBF43926) over the values as "
                   "big-endian IEEE-754 f32 bytes in C order, independent of the link's word order")
        try:
            # write and read back
            link.upload_table(t1)
            back = link.read_table()
            diff = t1.first_difference(back)
            hcrc = CorrectionTableData.decode_header(link.read_registers(_HDR_FIRST, _HDR_COUNT), link.word_order)["crc"]
            if diff is not None or hcrc != t1.crc32():
                r.failed(f"read-back of a {t1.n_values}-value test table: {diff or f'header CRC {hcrc:#010x}'}",
                         "keep the table header and data registers exactly as the PC wrote them")
                return
            r.passed(f"{t1.n_values}-value test table written and read back bit for bit")
            # a wrong CRC is refused
            bad = t1.crc32() ^ 0xFFFFFFFF
            link.write_registers(REG["table_crc"].address, encode("table_crc", bad, link.word_order))
            a = self._command(Command.TABLE_STAGE)
            if a.error_is(ErrorCode.TABLE_CRC_MISMATCH):
                r.passed("a header CRC that does not match the data: TABLE_CRC_MISMATCH")
            else:
                r.failed(f"TABLE_STAGE with a wrong header CRC: {a.describe()}",
                         "on TABLE_STAGE compute the CRC-32 of the data area and refuse a mismatch with "
                         "TABLE_CRC_MISMATCH (7)")
            link.write_registers(REG["table_crc"].address, encode("table_crc", t1.crc32(), link.word_order))
            if not self._stage(t1, r, crc_fix):
                return
            # activate (a zero table: harmless if it were ever activated again)
            link.upload_table(t0)
            if t0.first_difference(link.read_table()) is not None or not self._stage(t0, r, crc_fix):
                return
            a = self._command(Command.TABLE_ACTIVATE)
            crcs = link.table_crcs()
            if a.result != "done" or crcs["active"] != t0.crc32() or crcs["previous"] != crc0["active"] \
                    or crcs["staged"] != 0:
                r.failed(f"TABLE_ACTIVATE: {a.describe()}; CRCs now {self._crcs(crcs)}, expected active "
                         f"{t0.crc32():#010x}, previous {crc0['active']:#010x}, staged 0",
                         "TABLE_ACTIVATE: previous := active, active := staged, staged := none; publish the three CRCs")
                return
            r.passed("TABLE_ACTIVATE: active, previous and staged CRCs as documented")
            self._rollback(r, crc0["active"], t0.crc32())
        finally:
            self._restore(r, crc0, header0, data0, h0)

    def _crcs(self, crcs: dict[str, int]) -> str:
        return ", ".join(f"{k} {v:#010x}" for k, v in crcs.items())

    def _stage(self, t: CorrectionTableData, r: Requirement, crc_fix: str) -> bool:
        a = self._command(Command.TABLE_STAGE)
        staged = self.link.table_crcs()["staged"]
        if a.error_is(ErrorCode.TABLE_CRC_MISMATCH):
            r.failed(f"TABLE_STAGE of a correct table (CRC-32 {t.crc32():#010x}): TABLE_CRC_MISMATCH", crc_fix)
            return False
        if a.result != "done" or staged != t.crc32() or not self.link.status().table_staged:
            r.failed(f"TABLE_STAGE: {a.describe()}; table_staged_crc {staged:#010x}, expected {t.crc32():#010x}",
                     "on TABLE_STAGE keep the checked table as the staged one, publish its CRC in table_staged_crc "
                     "and set the TABLE_STAGED bit")
            return False
        r.passed(f"TABLE_STAGE: staged CRC-32 {staged:#010x} matches")
        return True

    def _rollback(self, r: Requirement, active0: int, crc_t0: int) -> None:
        link = self.link
        fix = "TABLE_ROLLBACK swaps active and previous; refuse it with NO_PREVIOUS_TABLE (14) when there is none"
        if active0 != 0:
            a = self._command(Command.TABLE_ROLLBACK)
            crcs = link.table_crcs()
            if a.result == "done" and crcs["active"] == active0 and crcs["previous"] == crc_t0:
                r.passed("TABLE_ROLLBACK: the original table is active again")
            else:
                r.failed(f"TABLE_ROLLBACK: {a.describe()}; CRCs now {self._crcs(crcs)}", fix)
            return
        a = self._command(Command.TABLE_ROLLBACK)  # no previous table after activating over none
        if not a.error_is(ErrorCode.NO_PREVIOUS_TABLE):
            r.failed(f"TABLE_ROLLBACK with no previous table: {a.describe()}", fix)
        b = self._command(Command.TABLE_DEACTIVATE)
        c = self._command(Command.TABLE_ROLLBACK)
        crcs = link.table_crcs()
        if b.result == "done" and c.result == "done" and crcs["active"] == crc_t0 and crcs["previous"] == 0:
            r.passed("TABLE_DEACTIVATE then TABLE_ROLLBACK: the table is active again; NO_PREVIOUS_TABLE without one")
        else:
            r.failed(f"TABLE_DEACTIVATE, TABLE_ROLLBACK: {b.describe()}, {c.describe()}; CRCs now {self._crcs(crcs)}",
                     fix + "; TABLE_DEACTIVATE: previous := active, active := none")
        self._command(Command.TABLE_DEACTIVATE)

    def _restore(self, r: Requirement, crc0: dict[str, int], header0: list[int], data0: list[int],
                 h0: dict | None) -> None:
        """Bring the active table back to the original one, and the staging area's contents."""
        link = self.link
        crcs = link.table_crcs()
        if crcs["active"] != crc0["active"]:
            self._command(Command.TABLE_ROLLBACK if crc0["active"] != 0 else Command.TABLE_DEACTIVATE)
            crcs = link.table_crcs()
        if crcs["active"] != crc0["active"]:
            r.failed(f"the original active table (CRC {crc0['active']:#010x}) could not be restored: active is "
                     f"{crcs['active']:#010x}",
                     "restore the controller's table by hand (re-upload it with the station) before moving the robot")
            self.notes.append("THE CONTROLLER'S ACTIVE CORRECTION TABLE IS NOT THE ORIGINAL ONE")
        if data0:
            link.write_registers(REG["table_data"].address, data0)
        link.write_registers(_HDR_FIRST, header0)
        if crc0["staged"] != 0 and h0 is not None and h0["crc"] == crc0["staged"]:
            self._command(Command.TABLE_STAGE)
        crcs = link.table_crcs()
        if crcs["staged"] != crc0["staged"]:
            self.notes.append(f"the staged table could not be restored (staged CRC {crcs['staged']:#010x}, was "
                              f"{crc0['staged']:#010x}): upload it again before activating")
        if crcs["previous"] != crc0["previous"]:
            self.notes.append(f"the roll-back slot now holds {crcs['previous']:#010x} (was {crc0['previous']:#010x}): "
                              f"the protocol cannot restore it")
