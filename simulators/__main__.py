"""``python -m simulators``: run the simulated cell until SIGINT/SIGTERM.

Prints one JSON line ``{"controller": "127.0.0.1:PORT", "probe_head": "/dev/pts/N", "seed": N}``
once both endpoints accept traffic. Log records (warnings and errors, e.g. pymodbus on malformed
frames) go to stderr without ever blocking: when nobody reads the pipe they are dropped and
counted (:mod:`simulators.stderr_log`), so the simulators keep serving.
"""

from __future__ import annotations

import argparse
import json
import logging
import signal
import sys
import threading

from drivers.controller_map import MAP_VERSION, WordOrder
from simulators import start_simulated_cell
from simulators.stderr_log import install as install_stderr_log


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m simulators", description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0, help="seed of the cell's true errors and noise")
    ap.add_argument("--time-scale", type=float, default=0.0,
                    help="motion-time scale of the controller (0 = instant moves, 1 = real time)")
    ap.add_argument("--baud", type=int, default=38400, help="probe-head baud rate (pacing)")
    ap.add_argument("--pace", action="store_true", help="hold probe replies for their serial transfer time")
    ap.add_argument("--host", default="127.0.0.1")
    ap.add_argument("--port", type=int, default=0, help="controller TCP port (0 = ephemeral)")
    ap.add_argument("--word-order", choices=[o.value for o in WordOrder], default="big",
                    help="word order of the controller's 32-bit values")
    ap.add_argument("--map-version", type=int, default=MAP_VERSION,
                    help="register-map version the controller reports (another one plays a "
                         "robot program the driver does not know)")
    args = ap.parse_args(argv)
    install_stderr_log(logging.WARNING)
    stop = threading.Event()

    def _on_signal(signum, _frame) -> None:
        stop.set()

    signal.signal(signal.SIGINT, _on_signal)
    signal.signal(signal.SIGTERM, _on_signal)
    servers = start_simulated_cell(seed=args.seed, time_scale=args.time_scale, pace=args.pace,
                                   baudrate=args.baud, host=args.host, port=args.port,
                                   word_order=WordOrder(args.word_order),
                                   map_version=args.map_version)
    try:
        print(json.dumps(servers.endpoints()), flush=True)
        while not stop.wait(0.5):
            pass
    finally:
        servers.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
