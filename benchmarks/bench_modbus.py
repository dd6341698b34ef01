"""Modbus loopback figures: round trip of one status read, and a 32 000-value correction table
upload + read-back through map 2's paged transfer (29 values a page, every page acknowledged and
read back), with the map at base 128 in a 128-register window.
``python benchmarks/bench_modbus.py [--runs 5] [--reads 500]``. Prints medians beside the figure
of map 1 (a flat 64 000-register area: 0.23 s for 20 000 values); asserts nothing about time."""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from drivers.controller import ModbusController
from simulators.controller_server import SimulatedController
from station.core.table.values import CorrectionTableData, TableAxis


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--reads", type=int, default=500)
    args = ap.parse_args()
    axes = (TableAxis(300.0, 20.0, 25), TableAxis(-400.0, 32.0, 20), TableAxis(250.0, 100.0, 1),
            TableAxis(-np.pi, np.pi / 4, 8, periodic=True))
    table = CorrectionTableData(axes, np.random.default_rng(0).normal(0, 1e-3, (2, 25, 20, 1, 8, 4)))
    with SimulatedController(register_base=128, register_count=128) as sim, \
            ModbusController("127.0.0.1", sim.port, register_base=128, heartbeat_period=None) as c:
        rt = []
        for _ in range(args.runs):
            t = time.perf_counter()
            for _ in range(args.reads):
                c.status()
            rt.append((time.perf_counter() - t) / args.reads)
        up, rb = [], []
        for _ in range(args.runs):
            t = time.perf_counter()
            c.upload_table(table)
            up.append(time.perf_counter() - t)
            t = time.perf_counter()
            back = c.read_table()
            rb.append(time.perf_counter() - t)
            if not back.same_as(table):
                raise RuntimeError("read-back differs from the upload")
    med_rt = statistics.median(rt)
    print(f"status read round trip (7 registers, loopback): median {med_rt * 1e3:.3f} ms "
          f"over {args.runs} runs x {args.reads} reads")
    print(f"table of {table.n_values} values: upload median {statistics.median(up):.3f} s, "
          f"read-back median {statistics.median(rb):.3f} s, total "
          f"{statistics.median(np.add(up, rb)):.3f} s over {args.runs} runs (map 1, 20 000 values: 0.23 s; "
          f"target <= 2 s)")


if __name__ == "__main__":
    main()
