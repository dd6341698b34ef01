"""What the robot controller reports: the status block, and the status of one command.

:class:`ControllerStatus` decodes the response block of the register map
(:mod:`drivers.controller_map`); :class:`CommandStatus` follows one acknowledged command of a
controller (:class:`drivers.controller.ModbusController`, seen here only as the structural
:class:`StatusSource`, so that this module does not import the driver) until the controller
reports it done or failed.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field
from typing import Any, Protocol, Sequence

from .controller_errors import MotionTimeout, error_message
from .controller_map import REG, Command, ControllerError, RegisterDecodeError, StatusBit, decode, register_span

__all__ = ["ControllerStatus", "CommandStatus", "MotionStatus", "StatusSource"]

# --------------------------------------------------------------------------------------------
# status
# --------------------------------------------------------------------------------------------

_STATUS_FIRST, _STATUS_COUNT = register_span("ack_seq", "error_bound")


@dataclass(frozen=True)
class ControllerStatus:
    """Snapshot of the response block."""

    ack_seq: int
    done_seq: int
    error_seq: int
    error_code: int
    bits: int
    error_joint: int
    error_bound: int

    ready: bool = field(init=False)
    moving: bool = field(init=False)
    in_position: bool = field(init=False)
    error: bool = field(init=False)
    estop: bool = field(init=False)
    table_active: bool = field(init=False)
    table_staged: bool = field(init=False)
    table_previous: bool = field(init=False)

    def __post_init__(self) -> None:
        b = StatusBit(self.bits & 0xFF)
        for name, bit in (("ready", StatusBit.READY), ("moving", StatusBit.MOVING),
                          ("in_position", StatusBit.IN_POSITION), ("error", StatusBit.ERROR),
                          ("estop", StatusBit.ESTOP), ("table_active", StatusBit.TABLE_ACTIVE),
                          ("table_staged", StatusBit.TABLE_STAGED),
                          ("table_previous", StatusBit.TABLE_PREVIOUS)):
            object.__setattr__(self, name, bool(b & bit))

    @property
    def error_message(self) -> str:
        return error_message(self.error_code)

    @classmethod
    def from_registers(cls, regs: Sequence[int]) -> "ControllerStatus":
        """Decode the registers ``ack_seq .. error_bound``; raises :class:`RegisterDecodeError`."""
        if len(regs) != _STATUS_COUNT:
            raise RegisterDecodeError(f"status block: expected {_STATUS_COUNT} registers, got {len(regs)}")
        base = REG["ack_seq"].address

        def field_(name: str) -> Any:
            r = REG[name]
            return decode(r, regs[r.address - base:r.end - base])

        return cls(field_("ack_seq"), field_("done_seq"), field_("error_seq"), field_("error_code"),
                   field_("status"), field_("error_joint"), field_("error_bound"))


# --------------------------------------------------------------------------------------------
# status objects for slow actions
# --------------------------------------------------------------------------------------------


class StatusSource(Protocol):
    """What a :class:`CommandStatus` needs of its controller."""

    poll_interval: float

    def _check_link(self) -> None: ...

    def status(self) -> "ControllerStatus": ...

    def _error_for(self, st: "ControllerStatus", seq: int, command: Command, target: Any) -> ControllerError: ...


class CommandStatus:
    """Status of one acknowledged command (ophyd ``StatusBase`` style).

    Resolves when ``done_seq`` equals its sequence number (success) or ``error_seq`` does
    (failure, typed error). Polling happens in :meth:`wait`, :attr:`done` and :meth:`exception`.
    """

    def __init__(self, controller: StatusSource, seq: int, command: Command, target: Any = None):
        self.controller = controller
        self.seq = int(seq)
        self.command = command
        self.target = target
        self._done = False
        self._exc: BaseException | None = None
        self._lock = threading.Lock()

    def _poll(self) -> None:
        with self._lock:
            if self._done:
                return
            self.controller._check_link()
            st = self.controller.status()
            if st.done_seq == self.seq:
                self._done = True
            elif st.error_seq == self.seq:
                self._exc = self.controller._error_for(st, self.seq, self.command, self.target)
                self._done = True

    @property
    def done(self) -> bool:
        """True once resolved (success or failure); polls the controller once if still pending."""
        self._poll()
        return self._done

    @property
    def success(self) -> bool:
        return self.done and self._exc is None

    def exception(self) -> BaseException | None:
        """The typed error if the command failed, else None (polls once if pending)."""
        self._poll()
        return self._exc

    def wait(self, timeout: float) -> None:
        """Block until resolved; raise the command's typed error, or :class:`MotionTimeout`."""
        if timeout is None or not timeout > 0:
            raise ValueError("wait() needs a positive timeout in seconds")
        deadline = time.monotonic() + timeout
        while True:
            self._poll()
            if self._done:
                if self._exc is not None:
                    raise self._exc
                return
            if time.monotonic() >= deadline:
                raise MotionTimeout(
                    f"{self.command.name} seq {self.seq} not finished within {timeout:.3g} s; the robot "
                    f"may still be moving: wait, or stop it and check the robot")
            time.sleep(self.controller.poll_interval)

    def __repr__(self) -> str:
        state = "pending" if not self._done else ("failed" if self._exc else "done")
        return f"<{type(self).__name__} {self.command.name} seq={self.seq} {state}>"


class MotionStatus(CommandStatus):
    """Status of a motion command."""

