"""Time of the collision check (issue 40) on an example cell's plan: poses, path samples, the first
clash and the seconds (median of 3). Usage: python benchmarks/bench_collision.py examples/puma560/cell.toml"""

from __future__ import annotations

import statistics
import sys

from station.cell.config.cell_config import load_config
from station.cell.plan.collision import check_path, plan_path
from station.cell.plan.measurement_plan import build_plan


def main(path: str) -> None:
    cfg = load_config(path)
    poses = plan_path(cfg, build_plan(cfg))
    runs = [check_path(cfg, poses) for _ in range(3)]
    r = runs[0]
    print(f"{path}: {r.poses} poses, {r.samples} samples at {r.margin_mm:g} mm, "
          f"median {statistics.median(x.seconds for x in runs):.2f} s; first clash: "
          f"{'none' if r.clash is None else r.clash.describe()}")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "examples/puma560/cell.toml")
