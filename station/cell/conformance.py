"""The conformance kit: does a robot program implement the register map and the handshake?

``station conformance CONFIG`` connects to the controller the configuration names and checks,
requirement by requirement, what ``docs/robot-program.md`` asks of the robot program:
identification registers, word order, heartbeats, acknowledgement and completion with the
command's sequence number, the sequence rule, the soft-limit refusal, error codes, and the
correction-table commands. Each requirement is reported passed, failed (with what to fix) or not
checked (with why).

Safety: the robot must be parked at ``[conformance].park_joints``. The kit commands joint moves
only (never Cartesian), every target checked by a :class:`~station.cell.safety.MotionGuard` whose
limits are the park zone (``park_joints ± test_move``) intersected with the configured and the
controller's soft limits. The one exception is the soft-limit probe: its target lies beyond a
soft limit by design, so it is checked by a guard on the park zone alone; it is only sent when
that limit lies inside the park zone (a joint parked within ``test_move`` of its limit), so even a
program that wrongly accepted it would stay in the park zone, and it is sent at the lowest speed
and stopped at once if the controller starts moving. Tables: the kit's test tables are removed
again and the controller's active table restored (checked by CRC).

The driver (:class:`drivers.controller.ModbusController`) does every register transfer; the
kit uses a subclass that can also send what a conforming station never sends (a wrong sequence
number, an unknown command code, a zero speed).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from drivers.controller import ControllerConnectionError, ModbusController
from drivers.controller_map import (
    MAX_JOINTS,
    REG,
    SUPPORTED_MAP_VERSIONS,
    Command,
    ControllerError,
    ErrorCode,
    WordOrder,
    decode,
    encode,
    implausible_limits,
    register_span,
)
from drivers.controller_status import ControllerStatus
from drivers.correction_table import CorrectionTableData, TableAxis
from station.cell.config import CellConfig, ConformanceConfig
from station.cell.safety import MotionGuard
from station.errors import ConfigError, Outcome, UnreachableError

__all__ = ["REQUIREMENTS", "Requirement", "ConformanceReport", "run_conformance", "PASSED", "FAILED", "NOT_CHECKED"]

PASSED, FAILED, NOT_CHECKED = "passed", "failed", "not checked"

#: The requirements, in report order: (id, what the robot program must do).
REQUIREMENTS: tuple[tuple[str, str], ...] = (
    ("identification", "map_version, n_joints, watchdog_ms and soft_limits are published"),
    ("word_order", "32-bit values use the link's word order"),
    ("heartbeat", "heartbeat both ways: hb_robot advances every period, hb_pc is taken from the PC"),
    ("ack", "every command is acknowledged with its sequence number in ack_seq"),
    ("done", "done_seq is set to the command's number only after the motion has arrived"),
    ("sequence", "a wrong sequence number is refused with SEQUENCE_ERROR, the next right one accepted"),
    ("soft_limit", "an out-of-limits target is refused with SOFT_LIMIT, error_joint and error_bound; "
                   "the robot does not move"),
    ("error_codes", "the documented error codes: BAD_COMMAND for an unknown command and a bad speed, "
                    "TABLE_NOT_STAGED; rejections do not latch"),
    ("table", "correction table: write, read-back, CRC-32, stage, activate, roll back; the original "
              "active table restored"),
)

_HDR_FIRST, _HDR_COUNT = register_span("table_format", "table_crc")
_CMD_FIRST = REG["cmd_code"].address
_ANSWER_TIMEOUT = 3.0  # seconds for a non-motion command to be answered
_HEARTBEAT_WINDOW = 1.5  # seconds to watch the heartbeats


def _next(seq: int) -> int:
    return seq % 0xFFFF + 1


@dataclass
class Requirement:
    """One requirement's result: ``status`` passed / failed / not checked, what was seen
    (``detail``) and, when it failed or could not be checked, what to do (``fix``)."""

    id: str
    title: str
    status: str = NOT_CHECKED
    detail: list[str] = field(default_factory=list)
    fix: list[str] = field(default_factory=list)

    def failed(self, detail: str, fix: str) -> None:
        self.status = FAILED
        self.detail.append(detail)
        if fix not in self.fix:
            self.fix.append(fix)

    def passed(self, detail: str = "") -> None:
        if self.status != FAILED:
            self.status = PASSED
        if detail:
            self.detail.append(detail)

    def not_checked(self, why: str, fix: str = "") -> None:
        if self.status != FAILED:
            self.status = NOT_CHECKED
        self.detail.append(f"not checked: {why}")
        if fix and fix not in self.fix:
            self.fix.append(fix)

    def to_json(self) -> dict[str, Any]:
        return {"id": self.id, "requirement": self.title, "status": self.status, "detail": list(self.detail),
                "fix": list(self.fix)}


@dataclass(frozen=True)
class ConformanceReport:
    controller: str
    configured_word_order: str
    detected_word_order: str | None
    requirements: tuple[Requirement, ...]
    notes: tuple[str, ...] = ()

    @property
    def passed(self) -> bool:
        return all(r.status == PASSED for r in self.requirements)

    @property
    def outcome(self) -> Outcome:
        """SUCCESS when every requirement passed; DEVICE_FAULT otherwise (the controller's
        program does not conform, or a requirement could not be checked)."""
        return Outcome.SUCCESS if self.passed else Outcome.DEVICE_FAULT

    def requirement(self, rid: str) -> Requirement:
        return next(r for r in self.requirements if r.id == rid)

    def to_json(self) -> dict[str, Any]:
        return {"outcome": self.outcome.name, "exit_code": int(self.outcome), "controller": self.controller,
                "word_order": {"configured": self.configured_word_order, "detected": self.detected_word_order},
                "passed": self.passed,
                "requirements": [r.to_json() for r in self.requirements], "notes": list(self.notes)}

    def describe(self) -> list[str]:
        lines = [f"conformance of the robot program at {self.controller}:"]
        for r in self.requirements:
            mark = {PASSED: "passed", FAILED: "FAILED", NOT_CHECKED: "NOT CHECKED"}[r.status]
            lines.append(f"  [{mark}] {r.id}: {r.title}")
            lines += [f"      {d}" for d in r.detail]
            if r.status != PASSED:
                lines += [f"      what to fix: {f}" for f in r.fix]
        lines += [f"  note: {n}" for n in self.notes]
        n_ok = sum(r.status == PASSED for r in self.requirements)
        lines.append(f"{n_ok} of {len(self.requirements)} requirements passed"
                     + ("" if self.passed else "; see docs/robot-program.md"))
        return lines


class _Link(ModbusController):
    """The driver, with the register-level access the kit needs."""

    def open_socket(self) -> None:
        """Connect the socket only (no checks): the kit reads the identification itself first."""
        with self._io_lock:
            ok = self._client.connect()
        if not ok:
            raise ControllerConnectionError(
                f"cannot connect to the controller at {self.host}:{self.port}: check that it is powered, the IP "
                f"address and port, and that the robot program is running")

    def read_registers(self, address: int, count: int) -> list[int]:
        return self._read(address, count)

    def write_registers(self, address: int, values: Sequence[int]) -> None:
        self._write(address, values)

    def read_entry(self, name: str) -> Any:
        return self._read_entry(name)

    @property
    def last_seq(self) -> int:
        return self._seq

    def send_block(self, code: int, seq: int, joints: np.ndarray | None = None, speed: float = 0.0) -> None:
        """Write the whole command block in one request, as the handshake prescribes (any code,
        any sequence number, any speed: the kit tests the refusals)."""
        o = self.word_order
        jj = np.zeros(MAX_JOINTS)
        if joints is not None:
            jj[:len(joints)] = joints
        regs = (encode("cmd_code", int(code), o) + encode("cmd_seq", int(seq), o) + encode("cmd_elbow", 0, o)
                + encode("cmd_speed", speed, o) + encode("cmd_joints", jj, o) + encode("cmd_pose", np.zeros(6), o))
        self._seq = int(seq)  # consumed: the next command continues from here
        self._write(_CMD_FIRST, regs)


@dataclass
class _Answer:
    """What the controller did with one command of the kit."""

    code: int
    seq: int
    motion: bool
    target: np.ndarray | None = None
    ack_seen: bool = False
    last_ack: int = -1
    result: str = "none"  # "done", "error" or "none" (no answer in time)
    status: ControllerStatus | None = None  # the snapshot that carried the result
    moving_seen: bool = False
    stopped: bool = False

    @property
    def name(self) -> str:
        try:
            return Command(self.code).name
        except ValueError:
            return f"code {self.code}"

    def describe(self) -> str:
        if self.result == "error" and self.status is not None:
            try:
                code = ErrorCode(self.status.error_code).name
            except ValueError:
                code = f"unknown error code {self.status.error_code}"
            return f"{self.name} seq {self.seq}: error {code} (error_joint {self.status.error_joint}, " \
                   f"error_bound {self.status.error_bound})"
        if self.result == "done":
            return f"{self.name} seq {self.seq}: done"
        return f"{self.name} seq {self.seq}: no done_seq or error_seq within the timeout"

    def error_is(self, code: ErrorCode) -> bool:
        return self.result == "error" and self.status is not None and self.status.error_code == int(code)


class _Kit:
    def __init__(self, cfg: CellConfig, conf: ConformanceConfig, link: _Link,
                 emit: Callable[[str], None]) -> None:
        self.cfg, self.conf, self.link, self.emit = cfg, conf, link, emit
        self.req = {rid: Requirement(rid, title) for rid, title in REQUIREMENTS}
        self.notes: list[str] = []
        self.answers: list[_Answer] = []
        self.detected: WordOrder | None = None
        self.g = cfg.model.n_joints
        self.zone_guard: MotionGuard | None = None
        self.motion_guard: MotionGuard | None = None
        self.ctrl_limits: np.ndarray | None = None
        self.may_move = False
        self.why_not_move = ""

    # -- plumbing --------------------------------------------------------------------------
    def _guarded(self, target: np.ndarray, what: str, probe: bool = False) -> np.ndarray:
        """Every motion target passes the park-zone guard; every one but the soft-limit probe
        also the guard of the zone intersected with the soft limits."""
        assert self.zone_guard is not None and self.motion_guard is not None
        q = self.zone_guard.check_joints(target, f"conformance {what} (park zone)")
        if not probe:
            q = self.motion_guard.check_joints(q, f"conformance {what}")
        return q

    def _command(self, code: int, *, seq: int | None = None, target: np.ndarray | None = None,
                 speed: float = 0.0, what: str = "", probe: bool = False) -> _Answer:
        motion = code in (Command.MOVE_JOINTS, Command.MOVE_CARTESIAN)
        if motion:
            if target is None:
                raise ValueError("a motion needs a target")
            target = self._guarded(np.asarray(target, dtype=float), what or "motion", probe)
        seq = _next(self.link.last_seq) if seq is None else seq
        ans = _Answer(int(code), int(seq), motion, target)
        self.answers.append(ans)
        self.link.send_block(code, seq, target, speed)
        timeout = self.cfg.devices.motion_timeout_s if motion else _ANSWER_TIMEOUT
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            st = self.link.status()
            ans.last_ack = st.ack_seq
            ans.ack_seen |= st.ack_seq == seq
            ans.moving_seen |= st.moving
            if probe and st.moving and not ans.stopped:  # a refused target must never move
                ans.stopped = True
                self.link.send_block(Command.STOP, _next(self.link.last_seq))
                self.notes.append(f"the controller started moving towards the out-of-limits target of seq {seq}: "
                                  f"STOP sent")
            if st.done_seq == seq or st.error_seq == seq:
                ans.result = "done" if st.done_seq == seq else "error"
                ans.status = st
                break
            time.sleep(0.003)
        if motion:
            self._settle()
        return ans

    def _settle(self) -> None:
        """Wait until the controller reports no motion (a program that reports done early must
        not make the next command a refused 'busy' one)."""
        deadline = time.monotonic() + self.cfg.devices.motion_timeout_s
        while self.link.status().moving and time.monotonic() < deadline:
            time.sleep(0.005)

    def _joints(self) -> np.ndarray:
        return self.link.read_joints()

    # -- the checks --------------------------------------------------------------------------
    def identification(self) -> bool:
        """Map version, joints, watchdog and soft limits; the word order from the soft limits.
        False when nothing else can be checked."""
        r, w = self.req["identification"], self.req["word_order"]
        link = self.link
        link.open_socket()
        version = int(decode("map_version", link.read_registers(REG["map_version"].address, 1)))
        if version not in SUPPORTED_MAP_VERSIONS:
            r.failed(f"map_version reads {version}", f"publish map_version = {SUPPORTED_MAP_VERSIONS[0]} (the "
                     f"register map this station speaks) and implement that map")
            return False
        g = int(decode("n_joints", link.read_registers(REG["n_joints"].address, 1)))
        if g != self.g:
            r.failed(f"n_joints reads {g}; the configured robot {self.cfg.model.name!r} has {self.g}",
                     "publish the robot's number of joints in n_joints (or configure the right robot file)")
            return False
        wd = int(decode("watchdog_ms", link.read_registers(REG["watchdog_ms"].address, 1)))
        if wd == 0:
            r.failed("watchdog_ms reads 0", "publish the watchdog time in ms (e.g. 1000) and stop a motion when "
                     "hb_pc has not changed for that long")
        lim_reg = REG["soft_limits"]
        raw = link.read_registers(lim_reg.address, lim_reg.n_registers)
        configured = link.word_order
        other = WordOrder.LITTLE if configured is WordOrder.BIG else WordOrder.BIG
        problem = implausible_limits(decode(lim_reg, raw, configured), g)
        if problem is None:
            self.detected = configured
        elif implausible_limits(decode(lim_reg, raw, other), g) is None:
            self.detected = other
            w.failed(f"soft_limits decode implausibly in the configured word order {configured.name} ({problem}) and "
                     f"plausibly in {other.name}; the rest of the checks use {other.name}",
                     f"write every 32-bit value with the word order of the link: {configured.name} = "
                     f"{'high word first (ABCD)' if configured is WordOrder.BIG else 'low word first (CDAB)'}; "
                     f"or, if {other.name} is what the controller must use, set [devices].word_order = "
                     f"\"{other.value}\"")
            link.word_order = other
        else:
            r.failed(f"soft_limits are implausible in either word order ({problem})",
                     "publish the soft limits as f32 pairs lower_1, upper_1, ... (finite, lower < upper) at "
                     f"registers {lim_reg.address}..{lim_reg.end - 1}")
            return False
        lim = np.asarray(decode(lim_reg, raw, link.word_order), dtype=float)[:2 * g].reshape(g, 2)
        self.ctrl_limits = lim
        r.passed(f"map_version {version}, n_joints {g}, watchdog_ms {wd}, soft limits "
                 f"{np.round(lim, 4).tolist()}")
        link.connect()  # the driver's own checks (map version, word order) now pass
        q = self._joints()
        span = lim[:, 1] - lim[:, 0]
        if not (np.all(np.isfinite(q)) and np.all(q >= lim[:, 0] - span) and np.all(q <= lim[:, 1] + span)):
            w.failed(f"act_joints read {q.tolist()} in {link.word_order.name}: not plausible joint values",
                     "write act_joints as f32 in the link's word order, the same as soft_limits")
        else:
            w.passed(f"soft_limits and act_joints {np.round(q, 5).tolist()} decode plausibly in "
                     f"{link.word_order.name}")
        wide = (self.cfg.soft_limits[:, 0] < lim[:, 0] - 1e-6) | (self.cfg.soft_limits[:, 1] > lim[:, 1] + 1e-6)
        if np.any(wide):
            self.notes.append(f"[limits] are wider than the controller's soft limits for joints "
                              f"{(np.nonzero(wide)[0] + 1).tolist()}")
        return True

    def heartbeat(self) -> None:
        r = self.req["heartbeat"]
        link = self.link
        t0 = time.monotonic()
        hb0 = last = int(link.read_entry("hb_robot"))
        pc0 = int(link.read_entry("hb_pc"))
        changes, pc_changed = 0, False
        while time.monotonic() - t0 < _HEARTBEAT_WINDOW and (changes < 2 or not pc_changed):
            time.sleep(0.02)
            hb = int(link.read_entry("hb_robot"))
            if hb != last:
                changes += 1
                last = hb
            pc_changed |= int(link.read_entry("hb_pc")) != pc0
        dt = time.monotonic() - t0
        if changes < 2:
            r.failed(f"hb_robot advanced {changes} time(s) in {dt:.2f} s (from {hb0})",
                     "increment hb_robot every 0.1 s (wrapping 65535 -> 0) in a cyclic task that runs also while "
                     "the robot moves; the station declares the link lost after 1 s without a change")
        else:
            r.passed(f"hb_robot advanced {changes} times in {dt:.2f} s")
        if not pc_changed:
            r.failed(f"hb_pc did not change in {dt:.2f} s while the station wrote it every 0.2 s",
                     "keep hb_pc a read-write register that holds what the PC writes, and watch it for the watchdog")
        else:
            r.passed("hb_pc follows the station's heartbeat")

    def prepare_motion(self) -> None:
        """The park zone, its guards, and whether the robot may be moved at all."""
        conf, lim = self.conf, self.ctrl_limits
        assert lim is not None
        zone = conf.zone()
        box = zone.copy()
        box[:, 0] = np.maximum.reduce([zone[:, 0], self.cfg.soft_limits[:, 0], lim[:, 0]])
        box[:, 1] = np.minimum.reduce([zone[:, 1], self.cfg.soft_limits[:, 1], lim[:, 1]])
        if not np.all(box[:, 0] < box[:, 1]):
            self.why_not_move = ("the park zone does not overlap the controller's soft limits: move park_joints "
                                 "inside them")
            return
        self.zone_guard = MotionGuard(zone)
        self.motion_guard = MotionGuard(box)
        st = self.link.status()
        if st.error or st.estop or not st.ready:
            self.why_not_move = (f"the controller is not ready ({st.error_message if st.error else 'READY bit clear'}): "
                                 f"release the e-stop, clear the fault, 'station reset CONFIG', then run again")
            return
        q = self._joints()
        try:
            self.motion_guard.check_joints(q, "the robot's position")
        except UnreachableError:
            self.why_not_move = (f"the robot is at {np.round(q, 5).tolist()}, outside the park zone "
                                 f"{np.round(box, 5).tolist()} (rad | mm): jog it to [conformance].park_joints")
            return
        self.may_move = True

    def sequence(self) -> None:
        r = self.req["sequence"]
        q = self._joints()
        wrong = _next(_next(self.link.last_seq))
        a = self._command(Command.MOVE_JOINTS, seq=wrong, target=q, speed=self.conf.move_speed,
                          what="sequence check (no motion)")
        fix = ("when cmd_seq changes, acknowledge it, then refuse it with SEQUENCE_ERROR unless it is the "
               "previous number + 1 (65535 wraps to 1); take the refused number as the previous one")
        if a.error_is(ErrorCode.SEQUENCE_ERROR):
            r.passed(f"seq {wrong} after {wrong - 1 if wrong > 1 else 65534} skipped: refused with SEQUENCE_ERROR")
        else:
            r.failed(f"a command with a skipped sequence number: {a.describe()}", fix)
        right = _next(wrong)
        b = self._command(Command.MOVE_JOINTS, seq=right, target=q, speed=self.conf.move_speed,
                          what="sequence check (no motion)")
        if b.result == "done":
            r.passed(f"seq {right} (the next one) accepted")
        else:
            r.failed(f"the next right number after the refusal: {b.describe()}", fix)

    def test_move(self) -> None:
        r = self.req["done"]
        assert self.motion_guard is not None
        q0 = self._joints()
        box = self.motion_guard.limits
        centre = box.mean(axis=1)
        step = 0.5 * self.conf.test_move_joint * np.where(q0 <= centre, 1.0, -1.0)
        target = np.clip(q0 + step, box[:, 0], box[:, 1])
        ok = True
        for tgt, what in ((target, "test move out"), (q0, "test move back")):
            a = self._command(Command.MOVE_JOINTS, target=tgt, speed=self.conf.move_speed, what=what)
            if a.result != "done":
                ok = False
                r.failed(f"{what}: {a.describe()}", "complete a MOVE_JOINTS inside the soft limits and report "
                         "done_seq := cmd_seq")
        if ok:
            r.passed(f"test move of {np.round(target - q0, 5).tolist()} (rad | mm) and back")

    def judge_done(self) -> None:
        r = self.req["done"]
        tol = self.conf.position_tolerance_joint
        for a in self.answers:
            if not a.motion or a.result != "done" or a.target is None or a.status is None:
                continue
            st = a.status
            if st.moving or not st.in_position:
                r.failed(f"{a.name} seq {a.seq}: done_seq was set while status read moving={int(st.moving)}, "
                         f"in_position={int(st.in_position)}",
                         "set done_seq := cmd_seq only after the motion has arrived: first MOVING = 0, IN_POSITION = 1 "
                         "and act_joints final, then done_seq (docs/protocols.md, rule 2)")
        # arrival: checked on the last motion (the robot is now where it ended)
        last = next((a for a in reversed(self.answers) if a.motion and a.result == "done" and a.target is not None), None)
        if last is not None and last.target is not None:
            q = self._joints()
            err = np.abs(q - last.target)
            if np.any(err > tol):
                r.failed(f"after {last.name} seq {last.seq} act_joints {np.round(q, 6).tolist()} differ from the target "
                         f"{np.round(last.target, 6).tolist()} by up to {float(err.max()):.3g}",
                         "report done only in position (within [conformance].position_tolerance), with act_joints "
                         "from the encoders")

    def soft_limit(self) -> None:
        r = self.req["soft_limit"]
        assert self.ctrl_limits is not None
        conf, lim = self.conf, self.ctrl_limits
        park, a = conf.park_joints, conf.test_move_joint
        best: tuple[float, int, int] | None = None  # (overshoot, joint, side)
        for j in range(self.g):
            for side, bound in ((-1, lim[j, 0]), (1, lim[j, 1])):
                dist = abs(bound - park[j])
                overshoot = min(0.25 * a[j], a[j] - dist)
                if overshoot > 1e-4 and (best is None or overshoot > best[0]):
                    best = (overshoot, j, side)
        if best is None:
            r.not_checked("no soft limit of the controller lies inside the park zone, so no out-of-limits target "
                          "can be sent that would keep a faulty program inside it",
                          "park one joint within test_move of its soft limit (e.g. a SCARA's quill just below its "
                          "upper limit) and run again")
            return
        overshoot, j, side = best
        q0 = self._joints()
        target = q0.copy()
        target[j] = lim[j, 0 if side < 0 else 1] + side * overshoot
        ans = self._command(Command.MOVE_JOINTS, target=target, speed=0.001, probe=True,
                            what=f"soft-limit probe (joint {j + 1} beyond its {'lower' if side < 0 else 'upper'} limit)")
        q1 = self._joints()
        fix = ("check every target joint against the soft limits before moving, letting only values with lower <= q "
               "<= upper through; refuse with error_code SOFT_LIMIT, error_joint = the joint (1-based), error_bound = "
               "-1 lower / +1 upper")
        st = ans.status
        if ans.result == "done" or ans.moving_seen:
            r.failed(f"joint {j + 1} = {target[j]:.6g} beyond the limit {lim[j, 0 if side < 0 else 1]:.6g}: the "
                     f"controller {'moved' if ans.moving_seen else 'reported done'}"
                     + (" (STOP sent)" if ans.stopped else ""), fix)
        elif not ans.error_is(ErrorCode.SOFT_LIMIT) or st is None:
            r.failed(f"joint {j + 1} beyond its limit: {ans.describe()}", fix)
        elif st.error_joint != j + 1 or st.error_bound != side:
            r.failed(f"SOFT_LIMIT reported with error_joint {st.error_joint}, error_bound {st.error_bound}; expected "
                     f"{j + 1}, {side:+d}", fix)
        else:
            r.passed(f"joint {j + 1} = {target[j]:.6g} (beyond {lim[j, 0 if side < 0 else 1]:.6g}): SOFT_LIMIT, "
                     f"error_joint {st.error_joint}, error_bound {st.error_bound:+d}")
        if np.any(np.abs(q1 - q0) > self.conf.position_tolerance_joint):
            r.failed(f"the robot moved from {np.round(q0, 6).tolist()} to {np.round(q1, 6).tolist()}", fix)
        if st is not None and not self.link.status().ready:
            r.failed("the refusal cleared READY (it latched)", "a rejection must not latch: keep READY set")

    def error_codes(self) -> None:
        r = self.req["error_codes"]

        def expect(ans: _Answer, code: ErrorCode, what: str, fix: str) -> None:
            if ans.error_is(code):
                st = self.link.status()
                if not st.ready or st.error:
                    r.failed(f"{what}: {code.name}, but READY was cleared / ERROR set",
                             "rejections do not latch: keep READY, leave the ERROR bit for e-stop, drive fault and "
                             "watchdog")
                else:
                    r.passed(f"{what}: {code.name}")
            else:
                r.failed(f"{what}: {ans.describe()}, expected {code.name}", fix)

        a = self._command(99)
        expect(a, ErrorCode.BAD_COMMAND, "unknown command code 99",
               "refuse an unknown cmd_code with error_code BAD_COMMAND (5)")
        if self.may_move:
            b = self._command(Command.MOVE_JOINTS, target=self._joints(), speed=0.0, what="zero-speed check (no motion)")
            expect(b, ErrorCode.BAD_COMMAND, "MOVE_JOINTS with cmd_speed 0",
                   "refuse cmd_speed outside 1..1000 (raw) with BAD_COMMAND (5)")
        else:
            r.detail.append(f"zero-speed refusal not checked: {self.why_not_move}")
        crcs = self.link.table_crcs()
        if crcs["staged"] == 0 and not self.link.status().table_staged:
            c = self._command(Command.TABLE_ACTIVATE)
            expect(c, ErrorCode.TABLE_NOT_STAGED, "TABLE_ACTIVATE with nothing staged",
                   "refuse TABLE_ACTIVATE without a staged table with TABLE_NOT_STAGED (8)")
            if c.result == "done":  # undo what a faulty program did (activated 'nothing')
                self.notes.append("the controller accepted TABLE_ACTIVATE with nothing staged; check its active table")
        else:
            r.detail.append("TABLE_NOT_STAGED not checked: the controller has a staged table")

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

    def judge_ack(self) -> None:
        r = self.req["ack"]
        bad = [a for a in self.answers if not a.ack_seen]
        if not self.answers:
            r.not_checked("no command was sent")
        elif bad:
            shown = ", ".join(f"seq {a.seq} (ack_seq read {a.last_ack})" for a in bad[:5])
            r.failed(f"{len(bad)} of {len(self.answers)} commands never showed ack_seq = their number: {shown}",
                     "when cmd_seq changes, write ack_seq := cmd_seq (the number itself, not a flag) before "
                     "validating or executing the command")
        else:
            r.passed(f"all {len(self.answers)} commands acknowledged with their sequence number")

    # -- the run -----------------------------------------------------------------------------
    def _step(self, rid: str, fn: Callable[[], None]) -> None:
        """Run one check; a controller error that is not a lost connection (a Modbus exception
        for a register the program does not serve, a malformed answer) fails its requirement."""
        try:
            fn()
        except ControllerConnectionError:
            raise
        except ControllerError as exc:
            self.req[rid].failed(f"{type(exc).__name__}: {exc}",
                                 "serve every register of the map (docs/robot-program.md) as documented")

    def run(self) -> None:
        self.emit("identification and word order")
        if not self.identification():
            for rq in self.req.values():
                if rq.status == NOT_CHECKED and not rq.detail:
                    rq.not_checked("identification failed", "fix the identification registers first")
            return
        self.emit("heartbeats")
        self._step("heartbeat", self.heartbeat)
        self.prepare_motion()
        if self.may_move:
            self.emit("sequence numbers")
            self._step("sequence", self.sequence)
            self.emit("test move (ack and done)")
            self._step("done", self.test_move)
            self._step("done", self.judge_done)
            self.emit("soft-limit refusal")
            self._step("soft_limit", self.soft_limit)
        else:
            for rid in ("sequence", "done", "soft_limit"):
                self.req[rid].not_checked(self.why_not_move, self.why_not_move.rpartition(": ")[2])
        self.emit("error codes")
        self._step("error_codes", self.error_codes)
        self.emit("correction table")
        self._step("table", self.table)
        self.judge_ack()


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
                 timeout=d.controller_timeout_s, heartbeat_period=0.2, link_timeout=3600.0)
    kit = _Kit(cfg, conf, link, emit or (lambda _m: None))
    try:
        kit.run()
    finally:
        link.close()
    return ConformanceReport(f"{d.controller_host}:{d.controller_port}", order.name,
                             None if kit.detected is None else kit.detected.name,
                             tuple(kit.req[rid] for rid, _ in REQUIREMENTS), tuple(kit.notes))
