"""How long the UR program takes, in 2 ms frames of controller time, for each step the station
waits on - measured by running the shipped program in the executor at a given statement budget
(``python -m simulators.urscript.timing [BUDGET ...]`` prints the table of
``docs/robot-program.md``).

The station's deadlines (``drivers/controller.py`` defaults): a command acknowledged within
``ack_timeout`` = 1.0 s, a transfer request answered within ``ack_timeout`` = 1.0 s, ``hb_robot``
changing within ``link_timeout`` = 1.0 s; the conformance kit waits 3 s for an answer.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass

import numpy as np

from drivers.controller_map import MAP_VERSION, REG, Command, decode, encode
from simulators.urscript.controller import URController
from simulators.urscript.interp import FRAME_S

__all__ = ["Timing", "measure", "DEADLINES_S", "Bench"]

#: the station's deadlines per step [s]
DEADLINES_S = {"start": 10.0, "claim": 1.0, "ack": 1.0, "refusal": 1.0, "done_after_arrival": 1.0, "info_page_0": 1.0,
               "info_page_1": 1.0, "heartbeat": 1.0}
BASE = 128


class Bench:
    """The shipped program in simulated time, with the station's side written by hand."""

    def __init__(self, budget: int, q0=None, source: str | None = None):
        self.c = URController(source=source, budget=budget, q0=q0 if q0 is not None else [0, 0, 0, 0, 0.5, 0])
        self.seq = 0
        self.xfer = 0
        self.hb = 0
        #: the PC heartbeat: hb_pc changes every 0.1 s while True
        self.pc_heartbeat = True
        #: the station's session token (cmd_token of every command; claim() asks for it)
        self.token = 0x5EC0DE01

    def claim(self, token: int | None = None, max_frames: int = 2000) -> int:
        """Ask for the controller with ``token`` (default: the bench's) as the station does;
        return claim_owner once the program has answered (the owner, or 0 if nothing changed)."""
        token = self.token if token is None else token
        owner0 = self.read("claim_owner")
        self.write("claim_request", token)
        try:
            self.until(lambda: self.read("claim_owner") not in (0, owner0) or self.read("claim_owner") == token,
                       max_frames)
        except TimeoutError:
            pass  # a refused claim changes nothing: no change within max_frames is the program's answer
        return int(self.read("claim_owner"))

    def frames(self, n: int) -> None:
        for _ in range(n):
            self.c.run_frames(1)
            if self.pc_heartbeat and self.c.program.frames % 50 == 0:  # the PC heartbeat every 0.1 s
                self.hb = (self.hb + 1) & 0xFFFF
                self.write("hb_pc", self.hb)
            if self.c.program.error is not None:
                raise self.c.program.error

    def until(self, pred, max_frames: int = 20000) -> int:
        for i in range(max_frames):
            if pred():
                return i
            self.frames(1)
        raise TimeoutError(f"not within {max_frames} frames")

    def write(self, name: str, value) -> None:
        r = REG[name]
        self.c.ports.set_words(BASE + r.address, encode(r, value))

    def read(self, name: str):
        r = REG[name]
        return decode(r, self.c.ports.words(BASE + r.address, r.n_registers))

    def command(self, code: int, joints=None, speed: float = 0.5, seq: int | None = None, pose=None,
                elbow: int = 0, token: int | None = None) -> int:
        self.seq = self.seq % 0xFFFF + 1 if seq is None else seq
        target = joints if joints is not None else pose
        regs = (encode("cmd_code", int(code)) + encode("cmd_seq", self.seq) + encode("cmd_elbow", elbow)
                + encode("cmd_speed", speed) + encode("cmd_target", np.zeros(6) if target is None else target)
                + encode("cmd_token", self.token if token is None else token))
        self.c.ports.set_words(BASE + REG["cmd_code"].address, regs)
        return self.seq

    def transfer(self, op: int, index: int) -> int:
        self.xfer = self.xfer % 0xFFFF + 1
        self.c.ports.set_words(BASE + REG["xfer_seq"].address, [self.xfer, op, index])
        return self.xfer


@dataclass
class Timing:
    budget: int
    frames: dict[str, int]

    def seconds(self, step: str) -> float:
        return self.frames[step] * FRAME_S

    def met(self) -> bool:
        return all(self.seconds(k) <= DEADLINES_S[k] for k in self.frames)


def measure(budget: int) -> Timing:
    """Frames each step takes at ``budget`` statements per thread per frame."""
    b = Bench(budget)
    f: dict[str, int] = {}
    f["start"] = b.until(lambda: b.read("map_version") == MAP_VERSION)
    b.write("claim_request", b.token)
    f["claim"] = b.until(lambda: b.read("claim_owner") == b.token)
    hb0 = b.read("hb_robot")
    f["heartbeat"] = b.until(lambda: b.read("hb_robot") != hb0)
    hb1 = b.read("hb_robot")
    f["heartbeat"] = max(f["heartbeat"], b.until(lambda: b.read("hb_robot") != hb1))
    seq = b.command(Command.MOVE_JOINTS, [0.01, 0, 0, 0, 0.5, 0])
    f["ack"] = b.until(lambda: b.read("ack_seq") == seq)
    b.until(lambda: not b.c.arm.idle)
    b.until(lambda: b.c.arm.idle)
    f["done_after_arrival"] = b.until(lambda: b.read("done_seq") == seq)
    seq = b.command(Command.MOVE_JOINTS, [0, 0, 9.0, 0, 0.5, 0])  # beyond a soft limit
    f["refusal"] = b.until(lambda: b.read("error_seq") == seq)
    for page in (0, 1):
        x = b.transfer(5, page)
        f[f"info_page_{page}"] = b.until(lambda x=x: b.read("xfer_ack") == x)
    return Timing(budget, f)


def main(argv: list[str]) -> int:
    budgets = [int(a) for a in argv] or [5, 10, 20, 50, 100]
    steps = list(DEADLINES_S)
    print("budget  " + "  ".join(f"{s:>18}" for s in steps) + "  deadlines met")
    for budget in budgets:
        t = measure(budget)
        cells = [f"{t.frames[s]:>6} fr {t.seconds(s) * 1000:>6.0f} ms" for s in steps]
        print(f"{budget:>6}  " + "  ".join(cells) + f"  {'yes' if t.met() else 'NO'}")
    print("deadlines [s]: " + ", ".join(f"{k} {v:g}" for k, v in DEADLINES_S.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
