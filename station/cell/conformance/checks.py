"""The conformance checks of the handshake: identification and word order, heartbeats, the
sequence rule, acknowledgement and completion, the soft-limit refusal and the error codes (the
requirements of :mod:`station.cell.conformance.report`; the safety rules are in
:mod:`station.cell.conformance.suite`'s docstring).
"""

from __future__ import annotations

import time

import numpy as np

from drivers.controller_errors import ClaimNotGranted
from drivers.controller_map import (
    INFO_PAGES,
    ORDER_CHECK_VALUE,
    REG,
    SUPPORTED_MAP_VERSIONS,
    Command,
    ControllerError,
    CorrectionState,
    ErrorCode,
    WordOrder,
    decode,
    encode,
    implausible_limits,
    release_code,
)
from drivers.controller_session import new_token
from station.cell.conformance.kit import _ANSWER_TIMEOUT, _Answer, _KitBase, _next
from station.cell.conformance.report import FAILED
from station.cell.limits.motion_guard import MotionGuard
from station.errors import UnreachableError

_HEARTBEAT_WINDOW = 1.5  # seconds to watch the heartbeats
#: a refused claim changes nothing, so its answer is the program having run on: this many advances
#: of hb_robot (0.1 s each) after the request, or _CLAIM_WAIT_MAX seconds where hb_robot stands
_CLAIM_PASSES = 5
_CLAIM_WAIT_MAX = 2.0


class _HandshakeChecks(_KitBase):
    # -- the checks --------------------------------------------------------------------------
    def identification(self) -> bool:
        """Map version, joints, watchdog, the word order from ``order_check``, and the soft limits
        from info page 0. False when nothing else can be checked."""
        r, w = self.req["identification"], self.req["word_order"]
        link = self.link
        link.open_socket()
        ident = link.read_registers(0, REG["order_check"].end)

        def field(name: str, order: WordOrder = link.word_order) -> int:
            reg = REG[name]
            return int(decode(reg, ident[reg.address:reg.end], order))

        version = field("map_version")
        if version not in SUPPORTED_MAP_VERSIONS:
            r.failed(f"map_version reads {version} at register {link.register_base + REG['map_version'].address}",
                     f"publish map_version = {SUPPORTED_MAP_VERSIONS[0]} (the register map this station speaks) and "
                     f"implement that map, or set [devices].controller_register_base to where its window starts")
            return False
        g = field("n_joints")
        if g != self.g:
            r.failed(f"n_joints reads {g}; the configured robot {self.cfg.model.name!r} has {self.g}",
                     "publish the robot's number of joints in n_joints (or configure the right robot file)")
            return False
        wd = field("watchdog_ms")
        if wd == 0:
            r.failed("watchdog_ms reads 0", "publish the watchdog time in ms (e.g. 1000) and stop a motion when "
                     "hb_pc has not changed for that long")
        configured = link.word_order
        other = WordOrder.LITTLE if configured is WordOrder.BIG else WordOrder.BIG
        if field("order_check") == ORDER_CHECK_VALUE:
            self.detected = configured
        elif field("order_check", other) == ORDER_CHECK_VALUE:
            self.detected = other
            w.failed(f"order_check reads {field('order_check')} in the configured word order {configured.name} and "
                     f"{ORDER_CHECK_VALUE} in {other.name}; the rest of the checks use {other.name}",
                     f"write every 32-bit value with the word order of the link: {configured.name} = "
                     f"{'high word first (ABCD)' if configured is WordOrder.BIG else 'low word first (CDAB)'}; "
                     f"or, if {other.name} is what the controller must use, set [devices].word_order = "
                     f"\"{other.value}\"")
            link.word_order = other
        else:
            r.failed(f"order_check reads {field('order_check')} ({configured.name}), expected {ORDER_CHECK_VALUE}",
                     f"publish order_check = {ORDER_CHECK_VALUE} as a u32 at offsets {REG['order_check'].address}.."
                     f"{REG['order_check'].end - 1} of the window, in the link's word order")
            return False
        try:  # before any transfer request: a station that another holds is refused here (ControllerClaimed)
            link.claim()
        except ClaimNotGranted as exc:
            self.req["claim"].failed(str(exc), "take claim_request as the map's u32 (signed 16-bit words, the "
                                     "link's word order) and copy it to claim_owner unchanged")
            link.claim_failed = True
        link.sync_transfer()
        lim_reg = INFO_PAGES["soft_limits"][1]
        try:
            raw = link.read_info_raw("soft_limits")
        except ControllerError as exc:
            r.failed(f"info page 0 (the soft limits) could not be read: {exc}",
                     "serve READ_INFO page 0: the soft limits as 12 scaled i32 (1e-6 rad or mm per count)")
            return False
        decoded = np.asarray(decode(lim_reg, raw, link.word_order), dtype=float)
        problem = implausible_limits(decoded, g)
        if problem is not None:
            r.failed(f"the soft limits of info page 0 are implausible ({problem})",
                     "publish the soft limits on info page 0 as scaled i32 pairs lower_1, upper_1, ... "
                     "(1e-6 rad or mm per count; finite, lower < upper), in the link's word order")
            return False
        lim = decoded[:2 * g].reshape(g, 2)
        self.ctrl_limits = lim
        state = field("correction_state")
        r.passed(f"map_version {version}, n_joints {g}, watchdog_ms {wd}, correction_state {state}, soft limits "
                 f"{np.round(lim, 4).tolist()}")
        if state != CorrectionState.NONE:
            self.notes.append(f"correction_state reads {state}: the controller applies (or may apply) a correction "
                              f"of its own; a station table would correct on top of it")
        link.connect()  # the driver's own checks (map version, word order) now pass
        q = self._joints()
        span = lim[:, 1] - lim[:, 0]
        if not (np.all(np.isfinite(q)) and np.all(q >= lim[:, 0] - span) and np.all(q <= lim[:, 1] + span)):
            w.failed(f"act_joints read {q.tolist()} in {link.word_order.name}: not plausible joint values",
                     "write act_joints as scaled i32 (1e-6 rad or mm per count) in the link's word order, as the "
                     "soft limits")
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

    def _program_passes(self, n: int) -> None:
        """Until hb_robot has advanced ``n`` times (the program's cyclic task has run on), at most
        ``_CLAIM_WAIT_MAX`` seconds (a program without a heartbeat fails its own check)."""
        link = self.link
        start = int(link.read_entry("hb_robot"))
        end = time.monotonic() + _CLAIM_WAIT_MAX
        while (int(link.read_entry("hb_robot")) - start) % 65536 < n and time.monotonic() < end:
            time.sleep(0.02)

    def claim_rules(self) -> None:
        """One station per controller: a second claim is refused, a command with another token is
        refused with NOT_CLAIMED, the holder's release frees the controller, and a holder that stops
        its heartbeat loses it by the program's watchdog. The kit holds the controller afterwards."""
        r, link = self.req["claim"], self.link
        if link.claim_failed:  # failed at identification: the kit holds no claim to test the rules with
            return
        other = new_token()
        while other in (link.claim_token, release_code(link.claim_token)):
            other = new_token()
        link.write_registers(REG["claim_request"].address, encode("claim_request", other, link.word_order))
        self._program_passes(_CLAIM_PASSES)  # a refusal changes nothing: the program must have run on
        owner = int(link.read_entry("claim_owner"))
        if owner != link.claim_token:
            r.failed(f"a second station's claim was granted while the kit held the controller (claim_owner reads "
                     f"{owner:#010x}, the kit's token is {link.claim_token:#010x})",
                     "grant a claim_request only while claim_owner is 0 (compare and set in the program)")
            link.write_registers(REG["claim_request"].address,
                                 encode("claim_request", release_code(owner), link.word_order))
            self._await_owner(0)
            link.claim()
        ans = self._command(Command.RESET, token=other)  # harmless if obeyed: nothing is latched at this point
        if not ans.error_is(ErrorCode.NOT_CLAIMED):
            r.failed(f"a command with another station's token: {ans.describe()}",
                     "refuse every command but STOP whose cmd_token is not claim_owner with NOT_CLAIMED (17)")
        link.release()
        if not self._await_owner(0):
            r.failed("writing the holder's release code (0xFFFFFFFF - token) to claim_request did not free the "
                     "controller", "free the claim when claim_request holds 0xFFFFFFFF - claim_owner")
            link.claim()  # still the kit's: it goes on holding it
            return
        link.claim()
        link._stop_heartbeat()  # the kit plays a station that died
        wd = int(link.read_entry("watchdog_ms")) / 1000.0
        t0 = time.monotonic()
        freed = self._await_owner(0, wd + 2.0)
        dt = time.monotonic() - t0
        link._heartbeat_once()  # hb_pc live again before anything else: no watchdog fires on the next move
        link.claim_after_lapse()
        link._start_heartbeat()
        if freed:
            self.emit(f"one station per controller: the watchdog freed the kit's silent claim after {dt:.2f} s, as "
                      f"this check expects; claimed again")
        if not freed:
            r.failed(f"the claim was not freed {dt:.2f} s after the holder's heartbeat stopped (watchdog_ms "
                     f"{wd * 1000:.0f})", "clear claim_owner (and the holder's request, host, PID and since) when "
                     "hb_pc has not changed for watchdog_ms: a dead station's claim must expire by itself")
            return
        if r.status != FAILED:
            r.passed(f"a second claim was refused, a command with its token refused NOT_CLAIMED, the release freed "
                     f"the controller, and the watchdog freed a silent holder's claim after {dt:.2f} s")

    def _await_owner(self, owner: int, timeout: float = _ANSWER_TIMEOUT) -> bool:
        deadline = time.monotonic() + timeout
        while int(self.link.read_entry("claim_owner")) != owner:
            if time.monotonic() >= deadline:
                return False
            time.sleep(0.01)
        return True

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

    def moved(self, r, q0: np.ndarray, what: str) -> bool:
        """Fail ``r`` if the robot moved from ``q0`` (beyond the position tolerance), naming the
        joint and the distance, and stop commanding motions: the program moves where it was not
        sent. True when it moved."""
        q1 = self._joints()
        d = np.abs(q1 - q0)
        if not np.any(d > self.conf.position_tolerance_joint):
            return False
        j = int(np.argmax(d))
        r.failed(f"{what} moved the robot: joint {j + 1} by {d[j]:.6g} (rad | mm), from {q0[j]:.6g} to {q1[j]:.6g}",
                 "a refused command, and a move to the joints the robot stands at, must not move it: decode cmd_target "
                 "as the map's scaled signed i32 in the link's word order (a UR's read_port_register returns the "
                 "signed value -32768 .. 32767, docs/robot-program.md); jog the robot back to "
                 "[conformance].park_joints before the next run")
        self.stop_moving(f"joint {j + 1} moved by {d[j]:.6g} on a command that must not move it")
        return True

    def stop_moving(self, why: str) -> None:
        """Command no further motion (the robot is not where the program reported it)."""
        if self.may_move:
            self.notes.append(f"the kit commanded no further motion: {why}; the robot may have left the park zone")
        self.may_move = False
        self.why_not_move = f"{why}: the kit commanded no further motion: jog the robot back to [conformance].park_joints"

    def sequence(self) -> None:
        r = self.req["sequence"]
        q = self._joints()
        wrong = _next(_next(self.link.last_seq))
        a = self._command(Command.MOVE_JOINTS, seq=wrong, target=q, speed=self.conf.move_speed,
                          what="sequence check (no motion)")
        if self.moved(r, q, f"MOVE_JOINTS seq {wrong} with a skipped number (refused: nothing may move)"):
            return
        fix = ("when cmd_seq changes, acknowledge it, then refuse it with SEQUENCE_ERROR unless it is the "
               "previous number + 1 (65535 wraps to 1); take the refused number as the previous one")
        if a.error_is(ErrorCode.SEQUENCE_ERROR):
            r.passed(f"seq {wrong} after {wrong - 1 if wrong > 1 else 65534} skipped: refused with SEQUENCE_ERROR")
        else:
            r.failed(f"a command with a skipped sequence number: {a.describe()}", fix)
        right = _next(wrong)
        b = self._command(Command.MOVE_JOINTS, seq=right, target=q, speed=self.conf.move_speed,
                          what="sequence check (no motion)")
        if self.moved(r, q, f"MOVE_JOINTS seq {right} to the joints the robot stands at"):
            return
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

    def _expect(self, ans: _Answer, code: ErrorCode, what: str, fix: str) -> None:
        """``error_codes``: ``ans`` must be the refusal ``code``, and the refusal must not latch."""
        r = self.req["error_codes"]
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

    def error_codes(self) -> None:
        r = self.req["error_codes"]
        a = self._command(99)
        self._expect(a, ErrorCode.BAD_COMMAND, "unknown command code 99",
                     "refuse an unknown cmd_code with error_code BAD_COMMAND (5)")
        if self.may_move:
            b = self._command(Command.MOVE_JOINTS, target=self._joints(), speed=0.0, what="zero-speed check (no motion)")
            self._expect(b, ErrorCode.BAD_COMMAND, "MOVE_JOINTS with cmd_speed 0",
                         "refuse cmd_speed outside 1..1000 (raw) with BAD_COMMAND (5)")
        else:
            r.partly("BAD_COMMAND for cmd_speed 0", self.why_not_move, self.why_not_move.rpartition(": ")[2])
        staged = self.link.table_crcs()["staged"] != 0 or self.link.status().table_staged
        if staged and self.uses_table and not self.why_not_tables:
            # the operator's staged table: TABLE_ACTIVATE would activate it. The slot rules end
            # with nothing staged (and the kit puts the slots back afterwards): checked then
            self.not_staged_pending = True
            return
        self.table_not_staged()

    def table_not_staged(self) -> None:
        """``error_codes``: TABLE_ACTIVATE with nothing staged is refused with TABLE_NOT_STAGED.
        Sent only where it cannot activate a table the kit could not put back."""
        r = self.req["error_codes"]
        self.not_staged_pending = False
        part = "TABLE_NOT_STAGED for TABLE_ACTIVATE with nothing staged"
        if self.uses_table and self.why_not_tables:  # a faulty program might activate 'nothing' over a table
            r.partly(part, self.why_not_tables, "serve the slot reads, then run the kit again")
        elif self.link.table_crcs()["staged"] != 0 or self.link.status().table_staged:
            r.partly(part, "the controller still has a staged table (TABLE_ACTIVATE would activate it)",
                     "fix the table slot rules first (see activation)" if self.uses_table else
                     "clear the staged table on the controller (TABLE_STAGE is for SCARA cells), then run again")
        else:
            c = self._command(Command.TABLE_ACTIVATE)
            self._expect(c, ErrorCode.TABLE_NOT_STAGED, "TABLE_ACTIVATE with nothing staged",
                         "refuse TABLE_ACTIVATE without a staged table with TABLE_NOT_STAGED (8)")
            if c.result == "done":  # the slots are put back at the end; say what the program did
                self.notes.append("the controller accepted TABLE_ACTIVATE with nothing staged")

    def judge_ack(self) -> None:
        r = self.req["ack"]
        bad = [a for a in self.answers if not a.ack_seen]
        torn = [a for a in self.answers if a.torn]
        if not self.answers:
            r.not_checked("no command was sent")
        elif torn:
            shown = ", ".join(f"seq {a.seq} ({a.result}_seq {a.seq} beside ack_seq {a.last_ack})" for a in torn[:5])
            r.failed(f"{len(torn)} of {len(self.answers)} commands: one status read showed the answer but not the "
                     f"acknowledgement: {shown}",
                     "one Modbus read must see one state of the registers: write ack_seq before the answer, and "
                     "copy a read's registers and publish the status under one lock (Epson SPEL+: SyncLock), "
                     "so that no read sees half an update")
        elif bad:
            shown = ", ".join(f"seq {a.seq} (ack_seq read {a.last_ack})" for a in bad[:5])
            r.failed(f"{len(bad)} of {len(self.answers)} commands never showed ack_seq = their number: {shown}",
                     "when cmd_seq changes, write ack_seq := cmd_seq (the number itself, not a flag) before "
                     "validating or executing the command")
        else:
            r.passed(f"all {len(self.answers)} commands acknowledged with their sequence number")
