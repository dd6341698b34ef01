"""Faults the simulated controller plays: Modbus exceptions on request, and the quirks of a
robot program that gets one rule of ``docs/protocols.md`` wrong (for ``station conformance``).
Used by :class:`simulators.controller_server.SimulatedController`."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["QUIRKS", "ModbusFault"]

#: Fault injection for the conformance kit: a robot program that gets one rule of
#: ``docs/protocols.md`` wrong. ``SimulatedController(..., quirks={"no_heartbeat"})``.
QUIRKS: dict[str, str] = {
    "swapped_word_order": "every 32-bit value (limits, joints, pose, table, CRCs) is written and read with its "
                          "two words in the other order than the link's word_order",
    "ack_without_seq": "ack_seq is set to 1 (a flag) instead of the command's sequence number",
    "no_heartbeat": "hb_robot never advances (the program does not run its heartbeat)",
    "crc_mismatch": "TABLE_STAGE computes the CRC-32 over little-endian i32 bytes instead of big-endian ones, "
                    "so a correct table is refused with TABLE_CRC_MISMATCH",
    "done_before_motion": "done_seq is written when a motion starts, not when it has arrived (observable with "
                          "time_scale > 0)",
    "page_crc_ignored": "a written page is stored without checking its page CRC (never PAGE_CRC_MISMATCH)",
    "no_slot_reads": "the slot reads READ_{STAGED,ACTIVE,PREVIOUS}_{HEADER,PAGE} are answered PAGE_INVALID, as by "
                     "a program that serves only the transfer buffer",
    "activate_drops_previous": "TABLE_ACTIVATE with no active table empties the previous slot (previous := active "
                               "even when none is active)",
}


@dataclass
class ModbusFault:
    """Reply with Modbus exception ``code`` to the next ``times`` requests touching ``address``
    (with function code ``function_code``, or any if None)."""

    address: int
    function_code: int | None
    code: int
    times: int
