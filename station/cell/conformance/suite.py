"""The conformance kit: does a robot program implement the register map and the handshake?

``station conformance CONFIG`` connects to the controller the configuration names and checks,
requirement by requirement, what ``docs/robot-program.md`` asks of the robot program:
identification registers, word order, heartbeats, acknowledgement and completion with the
command's sequence number, the sequence rule, the soft-limit refusal, error codes, and the
correction-table commands. Each requirement is reported passed, failed (with what to fix) or not
checked (with why).

Safety: the robot must be parked at ``[conformance].park_joints``. The kit commands joint moves
only (never Cartesian), every target checked by a :class:`~station.cell.limits.motion_guard.MotionGuard` whose
limits are the park zone (``park_joints ± test_move``) intersected with the configured and the
controller's soft limits. The one exception is the soft-limit probe: its target lies beyond a
soft limit by design, so it is checked by a guard on the park zone alone; it is only sent when
that limit lies inside the park zone (a joint parked within ``test_move`` of its limit), so even a
program that wrongly accepted it would stay in the park zone, and it is sent at the lowest speed
and stopped at once if the controller starts moving. Tables: before its first command the kit
reads the three table slots (CRC-32 and data, through the slot reads); afterwards it rebuilds them
exactly as found and compares the CRCs (:mod:`station.cell.conformance.slots`). A table it cannot
read back makes it change no slot at all.

The driver (:class:`drivers.controller.ModbusController`) does every register transfer; the
kit uses a subclass that can also send what a conforming station never sends (a wrong sequence
number, an unknown command code, a zero speed).
"""

from __future__ import annotations

from collections.abc import Callable

from drivers.controller_errors import ControllerClaimed, ControllerConnectionError
from drivers.controller_map import ControllerError, WordOrder
from station.cell.config.cell_config import CellConfig
from station.cell.conformance.checks import _HandshakeChecks
from station.cell.conformance.kit import _Link
from station.cell.conformance.report import (
    FAILED,
    NOT_APPLICABLE,
    NOT_CHECKED,
    PARTLY_CHECKED,
    PASSED,
    REQUIREMENTS,
    ConformanceReport,
    Requirement,
)
from station.cell.conformance.slots import _SlotKeeper
from station.cell.conformance.table import _TableChecks
from station.errors import ConfigError, UnreachableError

# The requirements and the report live in conformance_report, the link in conformance_kit; they
# stay importable from here.

#: the requirements that only a controller holding the station's correction table must meet
_TABLE_REQUIREMENTS = ("table", "pages", "slot_reads", "activation", "discard_previous", "keep_previous",
                       "slots_restored")

__all__ = ["REQUIREMENTS", "Requirement", "ConformanceReport", "run_conformance", "PASSED", "FAILED", "NOT_CHECKED",
           "NOT_APPLICABLE", "PARTLY_CHECKED"]

#: what to do when the kit's own motion guard refuses a target (the robot left the park zone)
_GUARD_FIX = ("the robot is not where the kit sent it: a program that decodes the command registers wrongly "
              "(signed 16-bit words read as unsigned, the word order) moves where it was not sent - decode cmd_target "
              "as the map's scaled signed i32 (docs/robot-program.md); jog the robot back to [conformance].park_joints "
              "and run the kit again")


class _Kit(_HandshakeChecks, _TableChecks, _SlotKeeper):
    """The kit: every check of the requirements, run in report order."""

    # -- the run -----------------------------------------------------------------------------
    def _step(self, rid: str, fn: Callable[[], None]) -> None:
        """Run one check; a controller error that is not a lost connection (a Modbus exception
        for a register the program does not serve, a malformed answer) fails its requirement."""
        try:
            fn()
        except ControllerConnectionError:
            raise
        except UnreachableError as exc:  # the kit's own safety refusal: a failed requirement, no abort
            self.stop_moving(f"the kit's motion guard refused a target ({exc})")
            self.req[rid].failed(f"the kit refused to command a motion: {exc}", _GUARD_FIX)
        except ControllerError as exc:
            self.req[rid].failed(f"{type(exc).__name__}: {exc}",
                                 "serve every register of the map (docs/robot-program.md) as documented")

    def _checks(self) -> None:
        self.prepare_motion()
        steps = (("sequence", "sequence numbers", self.sequence), ("done", "test move (ack and done)", self.test_move),
                 ("done", "", self.judge_done), ("soft_limit", "soft-limit refusal", self.soft_limit))
        for rid, title, fn in steps:
            if not self.may_move:  # never moved, or stopped moving: the robot went where it was not sent
                if self.req[rid].status == NOT_CHECKED and not any(d.startswith("not checked") for d in self.req[rid].detail):
                    self.req[rid].not_checked(self.why_not_move, self.why_not_move.rpartition(": ")[2])
                continue
            if title:
                self.emit(title)
            self._step(rid, fn)
        self.emit("error codes")
        self._step("error_codes", self.error_codes)
        if not self.uses_table:
            return
        self.emit("table pages")
        self._step("pages", self.pages)
        self.emit("correction table")
        self._step("table", self.table)
        self.emit("table slot rules")
        self._step("activation", self.switching)
        if self.not_staged_pending:  # the operator's staged table was in the way of error_codes
            self.emit("error codes: TABLE_NOT_STAGED")
            self._step("error_codes", self.table_not_staged)

    def run(self) -> None:
        self.emit("identification and word order")
        try:
            identified = self.identification()
        except (ControllerConnectionError, ControllerClaimed):  # no controller to check, or another station's
            raise
        except ControllerError as exc:  # a window too small for the map, a refused info page
            self.req["identification"].failed(f"{type(exc).__name__}: {exc}", "serve the map's 128-register window "
                                              "at [devices].controller_register_base (docs/robot-program.md)")
            identified = False
        if not identified:
            for rq in self.req.values():
                if rq.status == NOT_CHECKED and not rq.detail:
                    rq.not_checked("identification failed", "fix the identification registers first")
            return
        self.emit("heartbeats")
        self._step("heartbeat", self.heartbeat)
        self.emit("one station per controller")
        self._step("claim", self.claim_rules)
        if not self.uses_table:  # compensated targets: the program holds no table (robot-programs/ur)
            for rid in _TABLE_REQUIREMENTS:
                self.req[rid].not_applicable("this cell's robot is not a SCARA: the station sends compensated "
                                             "targets and uploads no correction table, so the program need hold none")
            self._checks()
        else:
            self.emit("table slots as found")  # before the first command: nothing has changed them yet
            self._step("slot_reads", self.read_slots)
            try:
                self._checks()
            finally:
                self.emit("table slots put back")
                self._step("slots_restored", self.restore_slots)
        self.judge_ack()
        if self.not_staged_pending:  # a step before it stopped the kit
            self.req["error_codes"].partly("TABLE_NOT_STAGED for TABLE_ACTIVATE with nothing staged",
                                           "the slot steps it waits for did not run (see the requirements before it)")
        for rq in self.req.values():  # never a bare "not checked"
            if rq.status == NOT_CHECKED and not rq.detail:
                rq.not_checked("the steps it needs did not run (see the requirements before it)")


def run_conformance(cfg: CellConfig, emit: Callable[[str], None] | None = None) -> ConformanceReport:
    """Check the robot program of the controller ``cfg`` names; see the module docstring.
    Raises :class:`ConfigError` without ``[conformance].park_joints``, and the driver's errors
    when the controller cannot be reached at all."""
    conf = cfg.conformance
    if conf is None:
        raise ConfigError("conformance.park_joints is missing: add a [conformance] table with park_joints (the joints "
                          "the robot is parked at, deg | mm) and test_move (the half-width of the park zone); "
                          "'station init' shows the template")
    d = cfg.devices
    order = WordOrder.BIG if d.word_order == "big" else WordOrder.LITTLE
    link = _Link(d.controller_host, d.controller_port, device_id=d.device_id, word_order=order,
                 timeout=d.controller_timeout_s, register_base=d.controller_register_base, heartbeat_period=0.2,
                 link_timeout=3600.0)
    kit = _Kit(cfg, conf, link, emit or (lambda _m: None))
    try:
        kit.run()
    finally:
        link.close()
    return ConformanceReport(f"{d.controller_host}:{d.controller_port}", order.name,
                             None if kit.detected is None else kit.detected.name,
                             tuple(kit.req[rid] for rid, _ in REQUIREMENTS), tuple(kit.notes))
