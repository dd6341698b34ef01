"""A stand-in for a UR e-Series controller: the URScript program (:mod:`.interp`), the arm
(:mod:`.arm`) and the Modbus server (:mod:`.modbus`) on one set of port registers.

:meth:`URController.run_frames` runs frames back to back (deterministic tests: simulated time
only). :meth:`URController.start` runs the program on a thread that paces the frames to the wall
clock, 500 frames a second (§10.2), so that the station - a separate process with wall-clock
timeouts - sees the program at its real rate; the arm still moves by simulated frames. When the
machine falls behind, frames run back to back until the program has caught up.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

from simulators.urscript import DEFAULT_BUDGET
from simulators.urscript.arm import Arm
from simulators.urscript.builtins import PortRegisters, make_builtins
from simulators.urscript.interp import FRAME_S, Program, mark_purity
from simulators.urscript.modbus import URModbusServer

__all__ = ["URController", "SHIPPED_SCRIPT"]

SHIPPED_SCRIPT = Path(__file__).resolve().parents[2] / "robot-programs" / "ur" / "station_link.script"


class URController:
    """``URController(source)`` with ``source`` the program's text (default: the shipped file)."""

    def __init__(self, source: str | None = None, budget: int = DEFAULT_BUDGET, q0=None,
                 model_name: str = "irb2600", host: str = "127.0.0.1", port: int = 0):
        self.source = SHIPPED_SCRIPT.read_text(encoding="utf-8") if source is None else source
        self.arm = Arm(q0, model_name)
        self.ports = PortRegisters()
        self.program = Program(self.source, make_builtins(self.arm, self.ports), budget, on_frame=self.arm.step)
        mark_purity(self.program)
        self.server = URModbusServer(self.ports, host, port)
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self.lag_resets = 0

    # ------------------------------------------------------------------ simulated time
    def run_frames(self, n: int) -> None:
        """Run ``n`` frames now (the Modbus side may be written between calls)."""
        with self.ports.lock:
            for _ in range(n):
                self.program.step_frame()
                if self.program.error is not None:
                    self.arm.halt()
                    return

    def run_until(self, predicate, max_frames: int) -> int:
        """Run frames until ``predicate()``; the frames it took. Raises if it never holds."""
        for i in range(max_frames):
            if predicate():
                return i
            self.run_frames(1)
            if self.program.error is not None:
                raise self.program.error
        raise TimeoutError(f"not within {max_frames} frames ({max_frames * FRAME_S:.3f} s of controller time)")

    # ------------------------------------------------------------------ real time
    def start(self) -> "URController":
        self.server.start()
        self._thread = threading.Thread(target=self._pace, name="urscript", daemon=True)
        self._thread.start()
        return self

    def _pace(self) -> None:
        t0 = time.monotonic()
        done = 0
        while not self._stop.is_set() and self.program.running:
            due = int((time.monotonic() - t0) / FRAME_S)
            if due - done > 250:  # more than 0.5 s behind: let the program's clock slip
                self.lag_resets += 1
                done = due - 1
            if due > done:
                self.run_frames(min(due - done, 25))
                done += min(due - done, 25)
            else:
                time.sleep(FRAME_S / 2)
        self.arm.halt()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(10.0)
        self.server.stop()

    def __enter__(self) -> "URController":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    @property
    def address(self) -> str:
        return f"{self.server.host}:{self.server.port}"
