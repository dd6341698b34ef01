"""``python -m simulators``: run the simulated cell until SIGINT/SIGTERM.

Prints one JSON line ``{"controller": "127.0.0.1:PORT", "probe_head": "/dev/pts/N", "seed": N}``
once both endpoints accept traffic.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import threading

from simulators import start_simulated_cell


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m simulators", description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0, help="seed of the cell's true errors and noise")
    ap.add_argument("--time-scale", type=float, default=0.0,
                    help="motion-time scale of the controller (0 = instant moves, 1 = real time)")
    ap.add_argument("--baud", type=int, default=38400, help="probe-head baud rate (pacing)")
    ap.add_argument("--pace", action="store_true", help="hold probe replies for their serial transfer time")
    ap.add_argument("--host", default="127.0.0.1")
    ap.add_argument("--port", type=int, default=0, help="controller TCP port (0 = ephemeral)")
    args = ap.parse_args(argv)
    stop = threading.Event()

    def _on_signal(signum, _frame) -> None:
        stop.set()

    signal.signal(signal.SIGINT, _on_signal)
    signal.signal(signal.SIGTERM, _on_signal)
    servers = start_simulated_cell(seed=args.seed, time_scale=args.time_scale, pace=args.pace,
                                   baudrate=args.baud, host=args.host, port=args.port)
    try:
        print(json.dumps(servers.endpoints()), flush=True)
        while not stop.wait(0.5):
            pass
    finally:
        servers.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
