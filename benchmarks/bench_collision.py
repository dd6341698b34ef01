"""Time of the collision check (issue 40) on an example cell's plan: poses (vias among them), path
samples at the margin's step and those evaluated, the first clash, the check's seconds and the whole
planning's (the plan with its collision-free pose design, the vias, the check), each the median of 3.
Usage: python benchmarks/bench_collision.py examples/puma560/cell.toml"""

from __future__ import annotations

import statistics
import sys
import time

from station.cell.config.cell_config import load_config
from station.cell.plan.collision import check_path
from station.cell.plan.measurement_plan import build_plan
from station.cell.plan.run_path import check_plan, plan_path
from station.errors import ConfigError, UnreachableError


def _planning(path: str) -> float:
    """Seconds from a fresh configuration to the checked plan (nothing cached from a run before)."""
    cfg = load_config(path)
    t0 = time.perf_counter()
    try:
        check_plan(cfg, build_plan(cfg))
    except (ConfigError, UnreachableError) as exc:  # a refused plan is a figure too: say so, time it all the same
        print(f"  refused: {exc}")
    return time.perf_counter() - t0


def main(path: str) -> None:
    cfg = load_config(path)
    poses = plan_path(cfg, build_plan(cfg))
    runs = [check_path(cfg, poses) for _ in range(3)]
    r = runs[0]
    vias = sum(1 for p in poses if p[1].rsplit(": ", 1)[-1] in ("depart", "arrive", "arm upright", "turned upright")
               or p[1].endswith(" first"))
    print(f"{path}: {r.poses} poses ({vias} vias), {r.samples} samples at {r.margin_mm:g} mm ({r.evaluated} evaluated), "
          f"check median {statistics.median(x.seconds for x in runs):.2f} s; first clash: "
          f"{'none' if r.clash is None else r.clash.describe()}")
    plans = [_planning(path) for _ in range(3)]
    print(f"  planning with the collision checks (plan, vias, check): median {statistics.median(plans):.2f} s "
          f"of {', '.join(f'{s:.2f}' for s in plans)} s")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "examples/puma560/cell.toml")
