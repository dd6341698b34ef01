"""Faults the simulated controller plays: Modbus exceptions on request, and the quirks of a
robot program that gets one rule of ``docs/protocols.md`` wrong (for ``station conformance``).
Used by :class:`simulators.controller_server.SimulatedController`."""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Any

__all__ = ["QUIRKS", "ModbusFault", "FaultInjection"]

#: Fault injection for the conformance kit: a robot program that gets one rule of
#: ``docs/protocols.md`` wrong. ``SimulatedController(..., quirks={"no_heartbeat"})``.
QUIRKS: dict[str, str] = {
    "swapped_word_order": "every 32-bit value (limits, joints, pose, table, CRCs) is written and read with its "
                          "two words in the other order than the link's word_order",
    "ack_without_seq": "ack_seq is set to 1 (a flag) instead of the command's sequence number",
    "ack_after_answer": "ack_seq is written after the answer (when the next command arrives), so one status read "
                        "shows a command's done_seq / error_seq beside the previous ack_seq: as a program whose "
                        "tasks write the registers while a read copies them, without a lock",
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
    "activate_unstaged": "TABLE_ACTIVATE with nothing staged is accepted (as a deactivation: previous := active, "
                         "active := none) instead of refused with TABLE_NOT_STAGED",
    "claim_always_granted": "every claim request is granted, also while another station holds the controller (no "
                            "compare-and-set: a second station takes the controller from the first)",
    "claim_never_expires": "the watchdog does not free the claim: a dead station's claim stays until someone "
                           "clears it by hand",
}


@dataclass
class ModbusFault:
    """Reply with Modbus exception ``code`` to the next ``times`` requests touching ``address``
    (with function code ``function_code``, or any if None)."""

    address: int
    function_code: int | None
    code: int
    times: int


class FaultInjection:
    """Fault injection at run time, thread-safe (mixed into the simulated controller, which
    supplies the attributes declared here)."""

    _lock: threading.Lock
    _faults: list[ModbusFault]
    _latency: float
    _lose_ack: bool
    _estop_next: bool
    _drive_fault_next: int
    _hb_frozen: bool
    _corrupt_next_page: bool
    _switch_faults: dict[str, tuple[int, bool]]
    _server: Any
    _loop: Any
    _tables: Any
    word_order: Any

    def inject_modbus_exception(self, address: int, function_code: int | None = None, code: int = 2,
                                times: int = 1) -> None:
        with self._lock:
            self._faults.append(ModbusFault(int(address), function_code, int(code), int(times)))

    def set_latency(self, seconds: float) -> None:
        self._latency = float(seconds)

    def lose_next_ack(self) -> None:
        self._lose_ack = True

    def estop_during_next_move(self) -> None:
        self._estop_next = True

    def drive_fault_during_next_move(self, axis: int = 1) -> None:
        self._drive_fault_next = int(axis)

    def fail_next_table_switch(self, command: str, code: int, takes_effect: bool = False) -> None:
        """The next ``command`` (``"TABLE_ACTIVATE"`` or ``"TABLE_ROLLBACK"``) is answered with
        error ``code``. ``takes_effect``: the program switched its slots before it failed (a
        program that dies between the switch and its acknowledgement); else the slots are as
        they were (a refused switch). Each is a case the station's roll-back policy must tell
        apart from the CRC registers alone (docs/correction.md)."""
        with self._lock:
            self._switch_faults[command] = (int(code), bool(takes_effect))

    def freeze_heartbeat(self, frozen: bool = True) -> None:
        self._hb_frozen = bool(frozen)

    def drop_connections(self, timeout: float = 5.0) -> None:
        """Close every client connection (the listener stays open)."""
        done = threading.Event()

        def _drop() -> None:
            assert self._server is not None
            for conn in list(self._server.active_connections.values()):
                conn.close()
            done.set()

        assert self._loop is not None
        self._loop.call_soon_threadsafe(_drop)
        if not done.wait(timeout):
            raise RuntimeError("could not drop connections")

    def corrupt_staging_value(self, index: int, delta: float = 1e-3) -> None:
        """Change value ``index`` of the stored table pages (as a flaky store would): the page
        keeps its old CRC, so its read-back fails."""
        with self._lock:
            self._tables.corrupt_value(int(index), delta, self.word_order)

    def corrupt_next_page(self) -> None:
        """The next page written through the transfer block arrives with one bit flipped (its
        page CRC no longer matches): the program refuses it with PAGE_CRC_MISMATCH."""
        with self._lock:
            self._corrupt_next_page = True
