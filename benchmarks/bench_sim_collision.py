"""Time per move of the simulated controller's own collision check (issue 40,
simulators/collision_check.py) over an example cell's plan as the station builds it: every move
between consecutive commanded poses checked as the controller checks it (target and joint-space
path), in ms per move, median of the runs; the samples per move and the moves refused.

Usage: python benchmarks/bench_sim_collision.py [CELL.toml ...] [--runs N]
(default: examples/puma560_obstacles/cell.toml examples/scara600_column/cell.toml, 3 runs)
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from simulators.collision_check import CellCollision
from station.cell.config.cell_config import load_config
from station.cell.plan.measurement_plan import build_plan
from station.cell.plan.run_path import plan_path

DEFAULT = ("examples/puma560_obstacles/cell.toml", "examples/scara600_column/cell.toml")


def one_run(check: CellCollision, poses: list[np.ndarray]) -> tuple[list[float], int, float]:
    """Seconds per move, the moves refused, and the CPU seconds of the whole plan (process time:
    what the check costs a run whatever the machine's load; the wall times grow with it)."""
    times, refused = [], 0
    cpu = time.process_time()
    for a, b in zip(poses, poses[1:]):
        t0 = time.perf_counter()
        refused += check.check_move(a, b) is not None
        times.append(time.perf_counter() - t0)
    return times, refused, time.process_time() - cpu


def bench(path: str, runs: int) -> None:
    cfg = load_config(path)
    poses = [q for q, _, _ in plan_path(cfg, build_plan(cfg))]
    check = CellCollision.from_config(cfg)
    samples = [len(check.samples(a, b)[0]) for a, b in zip(poses, poses[1:])]
    results = [one_run(check, poses) for _ in range(runs)]
    per_move = [1e3 * statistics.mean(t) for t, _, _ in results]
    p95 = [1e3 * float(np.percentile(t, 95)) for t, _, _ in results]
    print(f"{path}: {len(poses) - 1} moves, {int(np.median(samples))} samples per move (median; max {max(samples)}), "
          f"{len(check.moving)} moving and {len(check.fixed)} fixed shapes; check {statistics.median(per_move):.1f} ms "
          f"per move (median of {runs} runs' means; p95 {statistics.median(p95):.1f} ms), "
          f"{statistics.median(sum(t) for t, _, _ in results):.1f} s for the plan (CPU "
          f"{statistics.median(c for _, _, c in results):.1f} s); {results[0][1]} moves refused")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("cells", nargs="*", default=list(DEFAULT))
    ap.add_argument("--runs", type=int, default=3)
    args = ap.parse_args()
    for path in args.cells:
        bench(path, args.runs)


if __name__ == "__main__":
    main()
