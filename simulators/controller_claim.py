"""The robot program's claim rules (map 3, "one station per controller"), on a register image.

Used by the simulated controller (:class:`simulators.controller_server.SimulatedController`) and by
the driver's transcript tests, as :func:`simulators.controller_tables.serve_transfer` is. The
rules are those of ``docs/protocols.md`` and of the shipped robot programs:

* a request (a token in ``claim_request``) is granted - copied to ``claim_owner`` - only while
  ``claim_owner`` is 0 and the PC heartbeat is live; a request while another station holds the
  controller is left unanswered (``claim_owner`` keeps the holder's token);
* the holder's :func:`~drivers.controller_map.release_code` in ``claim_request`` frees it;
* the watchdog (``hb_pc`` unchanged for ``watchdog_ms``) frees it;
* freeing clears the request and the holder's host, PID and since as well, so that neither a
  stale request is granted later nor a stale holder named.

The quirks play programs that get a rule wrong (``station conformance`` must catch them).
"""

from __future__ import annotations

from collections.abc import Iterable

from drivers.controller_map import REG, WordOrder
from simulators.program_words import get_value, put_value

__all__ = ["ClaimRules", "CLAIM_QUIRKS"]

#: deviations from the claim rules (names shared with :data:`simulators.controller_faults.QUIRKS`)
CLAIM_QUIRKS = ("claim_always_granted", "claim_never_expires")


class ClaimRules:
    """The claim rules on ``regs`` (the window image by offset) in the program's word order."""

    def __init__(self, order: WordOrder, quirks: Iterable[str] = ()):
        self.order = order
        self.quirks = frozenset(quirks)

    def u32(self, regs: list[int], name: str) -> int:
        return int(get_value(regs, REG[name], self.order))

    def _put(self, regs: list[int], name: str, value: int) -> None:
        put_value(regs, REG[name], value, self.order)

    def owner(self, regs: list[int]) -> int:
        return self.u32(regs, "claim_owner")

    def free(self, regs: list[int]) -> None:
        for name in ("claim_owner", "claim_request", "claim_host", "claim_pid", "claim_since"):
            self._put(regs, name, 0)

    def serve(self, regs: list[int], heartbeat_live: bool) -> None:
        """One pass of the program over the claim block (level-triggered: a pending request is
        granted on the first pass that finds the controller free and the heartbeat live)."""
        owner, req = self.owner(regs), self.u32(regs, "claim_request")
        # docs/protocols.md, "One station per controller": the holder gives the controller back
        # by writing 0xFFFFFFFF - token to claim_request
        if owner and req == 0xFFFFFFFF - owner:
            self.free(regs)
        elif req and req != owner and heartbeat_live and (not owner or "claim_always_granted" in self.quirks):
            self._put(regs, "claim_owner", req)

    def expire(self, regs: list[int]) -> None:
        """The watchdog fired (``hb_pc`` silent for ``watchdog_ms``): the claim is freed."""
        if self.owner(regs) and "claim_never_expires" not in self.quirks:
            self.free(regs)

    def allows(self, regs: list[int], token: int) -> bool:
        """Whether a command carrying ``token`` comes from the holder."""
        owner = self.owner(regs)
        return owner != 0 and int(token) == owner
