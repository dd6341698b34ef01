"""The driver's session with the controller: the heartbeat and the claim (map 3: one station per
controller).

:class:`SessionKeeper` is mixed into :class:`drivers.controller.ModbusController`, as
:class:`drivers.controller_transfer.TablePager` is; it uses only what the host declares below.

The claim (``docs/protocols.md``): connect() asks for the controller with a random 32-bit session
token in ``claim_request`` - after one heartbeat, because the program grants a claim only while
``hb_pc`` is live - and reads ``claim_owner`` back. Granted, it writes who it is (the IPv4 address
of its socket, its PID, the UTC second of the grant) so that a refused station can name it; every
command carries the token (``cmd_token``); close() gives the controller back with the token's
:func:`~drivers.controller_map.release_code` and waits until the program has freed it. A controller
that another station holds raises :class:`ControllerClaimed` naming the holder, before this driver
has written anything - not even a heartbeat - so the holder's run goes on undisturbed. The
heartbeat keeps the claim: a station that stops it (dies, hangs) loses the controller after
``watchdog_ms`` by the robot program's watchdog.
"""

from __future__ import annotations

import ipaddress
import logging
import os
import secrets
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

from .controller_errors import (
    ClaimIdentity,
    ClaimNotGranted,
    ControllerClaimed,
    ControllerLinkLost,
    HandshakeTimeout,
)
from .controller_map import REG, ControllerError, WordOrder, decode, encode, register_span, release_code

__all__ = ["SessionKeeper", "new_token"]

log = logging.getLogger(__name__)

_HOLDER_FIRST, _HOLDER_COUNT = register_span("claim_host", "claim_since")


def new_token() -> int:
    """A random session token, 1..0xFFFFFFFE (0 means "free"; neither it nor a release code of a
    live token can be confused with one)."""
    return 1 + secrets.randbelow(0xFFFFFFFE)


class SessionKeeper:
    """Heartbeat and claim (mixin; the host supplies the attributes below)."""

    word_order: WordOrder
    ack_timeout: float
    poll_interval: float
    heartbeat_period: float | None
    link_timeout: float
    timeout: float
    _client: Any
    _hb_thread: threading.Thread | None
    _hb_stop: threading.Event
    _hb_counter: int
    _hb_last_error: BaseException | None
    _hb_robot_seen: float | None
    _link_lost: str | None
    #: the session token (random unless given), and whether the program granted it
    claim_token: int
    _claim_identity: ClaimIdentity | None
    _claimed: bool
    _watchdog_ms: int

    _read: Callable[[int, int], list[int]]
    _write: Callable[[int, Sequence[int]], None]

    # -- the claim ---------------------------------------------------------------------------
    def _u32(self, name: str) -> int:
        r = REG[name]
        return int(decode(r, self._read(r.address, r.n_registers), self.word_order))

    def holder(self) -> ClaimIdentity:
        """Who holds the controller, as the holder wrote it (all zero while nobody does)."""
        regs = self._read(_HOLDER_FIRST, _HOLDER_COUNT)

        def field(name: str) -> int:
            r = REG[name]
            a = r.address - _HOLDER_FIRST
            return int(decode(r, regs[a:a + r.n_registers], self.word_order))

        return ClaimIdentity(str(ipaddress.IPv4Address(field("claim_host"))), field("claim_pid"),
                             float(field("claim_since")))

    def _refuse(self, owner: int, asked: bool = False) -> ControllerError:
        """The error naming the holder of ``owner``; a holder granted a moment ago names itself
        within a request or two, so the refusal waits for that (at most ack_timeout). An owner
        that appeared right after this station ``asked`` and never names itself is this
        station's own token as a wrong program read it (:class:`ClaimNotGranted`)."""
        deadline = time.monotonic() + self.ack_timeout
        who = self.holder()
        while not who.since and time.monotonic() < deadline and self._u32("claim_owner") == owner:
            time.sleep(self.poll_interval)
            who = self.holder()
        if asked and not who.since:
            return ClaimNotGranted(owner, self.claim_token, self.ack_timeout)
        return ControllerClaimed(who, owner, self._watchdog_ms)

    def _left_behind(self, holder: ClaimIdentity) -> bool:
        """Whether ``holder`` is provably gone: named, on this machine (the IPv4 address of this
        link), not this process, and its PID runs no process (a reused PID only makes the station
        refuse, the safe side)."""
        if not holder.since or holder.host == "0.0.0.0" or holder.pid == os.getpid():
            return False
        if holder.host != self._own_identity().host:
            return False
        try:
            os.kill(holder.pid, 0)
        except ProcessLookupError:
            return True
        except OSError:  # it runs as another user, or cannot tell: the safe side
            return False
        return False

    def _own_identity(self) -> ClaimIdentity:
        if self._claim_identity is not None:
            return self._claim_identity
        host = "0.0.0.0"
        sock = getattr(self._client, "socket", None)  # pymodbus' ModbusTcpClient keeps its socket here
        try:
            name = sock.getsockname()[0] if sock is not None else ""
            host = str(ipaddress.IPv4Address(name))
        except (OSError, ValueError, TypeError, IndexError):
            pass  # not an IPv4 socket: the holder is named by PID and since only
        return ClaimIdentity(host, os.getpid(), float(int(time.time())))

    def claim(self, owner: int | None = None) -> None:
        """Hold the controller for this session (``owner``: ``claim_owner`` as just read, else
        read here). Raises :class:`ControllerClaimed` when another station holds it - before
        anything was written - and :class:`HandshakeTimeout` when the program does not answer."""
        owner = self._u32("claim_owner") if owner is None else int(owner)
        if owner and owner != self.claim_token:
            refusal = self._refuse(owner)
            if not (isinstance(refusal, ControllerClaimed) and self._left_behind(refusal.holder)):
                raise refusal
            # a process of this machine that is gone (killed, crashed) holds it: its heartbeat has
            # stopped, so the robot program's watchdog frees the claim; wait for that, nothing more
            log.warning("the controller is held by %s, a process of this machine that is gone: waiting for the "
                        "robot program's watchdog (%d ms) to free it", refusal.holder.describe(), self._watchdog_ms)
            deadline = time.monotonic() + self._watchdog_ms / 1000.0 + 2.0
            while (owner := self._u32("claim_owner")) == refusal.owner_token and time.monotonic() < deadline:
                time.sleep(0.02)
            if owner:
                raise refusal if owner == refusal.owner_token else self._refuse(owner)
        if not owner:
            if self._claimed:
                log.warning("the claim on the controller lapsed (no heartbeat reached it for %d ms): asking again",
                            self._watchdog_ms)
            self._heartbeat_once()  # the program grants a claim only while hb_pc is live (changing)
            self._write(REG["claim_request"].address, encode("claim_request", self.claim_token, self.word_order))
            deadline = time.monotonic() + self.ack_timeout
            while (owner := self._u32("claim_owner")) != self.claim_token:
                if owner:  # another station asked in the same moment and was granted
                    raise self._refuse(owner, asked=True)
                if time.monotonic() >= deadline:
                    raise HandshakeTimeout(
                        f"the robot program did not grant the claim within {self.ack_timeout:.3g} s (claim_owner "
                        f"stays 0): check that it runs the map version the station speaks (robot-programs/)")
                time.sleep(self.poll_interval)
        elif self._claimed:
            return  # held and named already
        who = self._own_identity()
        self._claim_identity = who
        self._write(_HOLDER_FIRST, [*encode("claim_host", int(ipaddress.IPv4Address(who.host)), self.word_order),
                                    *encode("claim_pid", who.pid, self.word_order),
                                    *encode("claim_since", int(who.since), self.word_order)])
        self._claimed = True

    @property
    def claimed(self) -> bool:
        """Whether this session holds the controller (as far as the driver knows)."""
        return self._claimed

    def release(self) -> None:
        """Give the controller back (orderly end) and wait until the program has freed it, so that
        the next station finds it free; a program that does not answer frees it by its watchdog."""
        if not self._claimed:
            return
        self._claimed = False
        try:
            self._write(REG["claim_request"].address,
                        encode("claim_request", release_code(self.claim_token), self.word_order))
            deadline = time.monotonic() + self.ack_timeout
            while self._u32("claim_owner") == self.claim_token:
                if time.monotonic() >= deadline:
                    log.warning("the robot program did not free the claim within %.3g s; its watchdog will",
                                self.ack_timeout)
                    return
                time.sleep(self.poll_interval)
        except ControllerError as exc:  # the link is gone: the watchdog frees the claim
            log.warning("could not give the controller back (%s); the robot program's watchdog frees it", exc)

    # -- heartbeat -------------------------------------------------------------------------
    def _start_heartbeat(self) -> None:
        self._hb_stop.clear()
        self._hb_thread = threading.Thread(target=self._heartbeat_loop, name="controller-heartbeat",
                                           daemon=True)
        self._hb_thread.start()

    def _stop_heartbeat(self) -> None:
        self._hb_stop.set()
        t = self._hb_thread
        if t is not None and t is not threading.current_thread():
            t.join(timeout=max(2.0, 2 * self.timeout))
        self._hb_thread = None

    def _heartbeat_loop(self) -> None:
        last_robot: int | None = None
        last_change = time.monotonic()
        period = float(self.heartbeat_period or 0.2)
        while not self._hb_stop.wait(period):
            try:
                hb = self._heartbeat_once()
                if hb != last_robot:
                    last_robot = hb
                    last_change = time.monotonic()
                    self._hb_robot_seen = last_change
            except ControllerError as exc:
                # Recorded, reported as the cause if the link is declared lost.
                self._hb_last_error = exc
                log.warning("heartbeat exchange failed: %s", exc)
            silent = time.monotonic() - last_change
            if silent > self.link_timeout:
                cause = f" (last error: {self._hb_last_error})" if self._hb_last_error else ""
                self._link_lost = (
                    f"controller heartbeat did not advance for {silent:.2f} s (limit "
                    f"{self.link_timeout:.2f} s){cause}: the robot program or the link is down; check "
                    f"the robot program and the link, then start the run again")
                log.error(self._link_lost)
                return

    @property
    def heartbeat_age_s(self) -> float | None:
        """Seconds since the robot's heartbeat last advanced (None before the first one)."""
        seen = self._hb_robot_seen
        return None if seen is None else time.monotonic() - seen

    def _heartbeat_once(self) -> int:
        """Advance and write the PC heartbeat; return the robot heartbeat."""
        self._hb_counter = (self._hb_counter + 1) & 0xFFFF
        self._write(REG["hb_pc"].address, [self._hb_counter])
        return int(self._read(REG["hb_robot"].address, 1)[0])

    @property
    def link_lost(self) -> str | None:
        """Reason the link was declared lost, or None."""
        return self._link_lost

    def _check_link(self) -> None:
        if self._link_lost is not None:
            raise ControllerLinkLost(self._link_lost)

