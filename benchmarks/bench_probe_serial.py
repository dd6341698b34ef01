"""All-channel snapshots per second over a paced pseudo-terminal, against the wire limit.

    .venv/bin/python benchmarks/bench_probe_serial.py [--baud 38400] [--runs 5] [--n 60]

The simulated unit paces its replies (and the request's own transfer) at the baud rate with
10 bits per byte (start + 8 data + stop), so the wire limit is
``baud / 10 / (request bytes + reply bytes)`` transactions per second. The figure printed is
the median over the runs; nothing is asserted (timings depend on the machine).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from drivers.probe_head import ProbeHead  # noqa: E402
from drivers.probe_protocol import format_request  # noqa: E402
from simulators.probe_head_sim import ProbeHeadPhysics, ProbeHeadServer  # noqa: E402


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baud", type=int, default=38400)
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--n", type=int, default=60, help="snapshots per run")
    args = ap.parse_args(argv)

    physics = ProbeHeadPhysics(seed=0)
    M = physics.geometry.nominal_contact_pose()
    rates = []
    with ProbeHeadServer(lambda: physics.readings(M), baudrate=args.baud, pace=True) as srv:
        with ProbeHead(srv.port, baudrate=args.baud) as ph:
            reply_bytes = len(ph.read_all().raw)  # also warms up
            request_bytes = len(format_request("M0"))
            for _ in range(args.runs):
                t0 = time.perf_counter()
                for _ in range(args.n):
                    ph.read_all()
                rates.append(args.n / (time.perf_counter() - t0))
    frame = request_bytes + reply_bytes
    wire = args.baud / 10.0 / frame
    median = statistics.median(rates)
    print(f"probe head, {physics.geometry.n_probes} channels, {args.baud} baud, 10 bits/byte")
    print(f"bytes per snapshot: {request_bytes} request + {reply_bytes} reply = {frame}")
    print(f"wire limit        : {wire:7.2f} snapshots/s")
    print(f"measured (median) : {median:7.2f} snapshots/s over {args.runs} runs of {args.n} "
          f"(min {min(rates):.2f}, max {max(rates):.2f})")
    print(f"ratio             : {median / wire * 100:6.1f} % of the wire limit (target >= 80 %)")


if __name__ == "__main__":
    main()
