"""Simulated calibration cell: robot controller (Modbus TCP) + probe head (serial, pty).

``start_simulated_cell()`` starts both in-process and returns once both endpoints accept
traffic; ``python -m simulators`` does the same as a process and prints the endpoints as one
JSON line.
"""

from __future__ import annotations

import socket
import time
from dataclasses import dataclass, field
from typing import Any

from drivers.controller_map import MAP_VERSION, WordOrder

__all__ = ["SimulatedCellServers", "start_simulated_cell"]


def _wait_tcp(host: str, port: int, timeout: float) -> None:
    deadline = time.monotonic() + timeout
    while True:
        try:
            with socket.create_connection((host, port), timeout=0.5):
                return
        except OSError as exc:
            if time.monotonic() >= deadline:
                raise RuntimeError(f"controller simulator at {host}:{port} not accepting: {exc}") from exc
            time.sleep(0.01)


@dataclass
class SimulatedCellServers:
    """Running simulators. ``cell.truth`` is the oracle (true robot, set-up, body)."""

    cell: Any
    controller_server: Any
    probe_server: Any
    seed: int = 0
    _stopped: bool = field(default=False, repr=False)

    @property
    def controller_host(self) -> str:
        return self.controller_server.host

    @property
    def controller_port(self) -> int:
        return self.controller_server.port

    @property
    def probe_port(self) -> str:
        return self.probe_server.port

    def endpoints(self) -> dict:
        return {"controller": f"{self.controller_host}:{self.controller_port}",
                "probe_head": self.probe_port, "seed": self.seed}

    def stop(self) -> None:
        """Stop both servers; re-raises a failure of either (after stopping both)."""
        if self._stopped:
            return
        self._stopped = True
        errors = []
        for server in (self.probe_server, self.controller_server):
            try:
                server.stop()
            except RuntimeError as exc:
                errors.append(exc)
        if errors:
            raise errors[0]

    def __enter__(self) -> "SimulatedCellServers":
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


def start_simulated_cell(seed: int = 0, time_scale: float = 0.0, pace: bool = False,
                         baudrate: int = 38400, host: str = "127.0.0.1", port: int = 0,
                         word_order: WordOrder = WordOrder.BIG, watchdog: float = 1.0,
                         cell: Any = None, ready_timeout: float = 10.0,
                         map_version: int | None = None) -> SimulatedCellServers:
    """Start the controller and probe-head simulators on one :class:`SimulatedCell`.
    ``map_version``: publish another register-map version (the driver must refuse it)."""
    from simulators.cell import SimulatedCell
    from simulators.controller_server import SimulatedController
    from simulators.probe_head_sim import ProbeHeadServer

    cell = cell if cell is not None else SimulatedCell(seed=seed)
    ctrl = SimulatedController(cell=cell, host=host, port=port, word_order=word_order,
                               time_scale=time_scale, watchdog=watchdog,
                               map_version=MAP_VERSION if map_version is None else map_version
                               ).start(ready_timeout)
    try:
        _wait_tcp(ctrl.host, ctrl.port, ready_timeout)
        probe = ProbeHeadServer(snapshot_source=cell.probe_values, baudrate=baudrate, pace=pace).start()
    except BaseException:
        ctrl.stop()
        raise
    return SimulatedCellServers(cell, ctrl, probe, seed)
