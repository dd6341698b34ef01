"""Time of drawing the cell's picture (issue 40, station/ui/report/render/cell_picture.py) for an example
cell's plan: the SVG alone, the SVG and the PNG (what ``station plan --out`` writes), each the median
of 5, besides the poses' sequence (the vias: plan_path) and the collision check the report makes for
a stored plan, which come before the drawing. The target: the drawing under 1 s for a 300-step plan
(examples/puma560_obstacles: 306 steps, 1502 poses with the vias).
Usage: python benchmarks/bench_cell_picture.py [examples/puma560_obstacles/cell.toml]"""

from __future__ import annotations

import os
import statistics
import sys
import time

from station.cell.config.cell_config import load_config
from station.cell.plan.collision import check_path
from station.cell.plan.measurement_plan import build_plan
from station.ui.report.render.cell_picture import cell_picture, picture_poses

RUNS = 5


def _median(f) -> tuple[float, list[float], float]:
    """The median wall time [s], every run's, and the median CPU time of this process [s] (on a
    machine shared by several sessions the wall time is the CPU time and the wait for a core)."""
    times, cpu = [], []
    for _ in range(RUNS):
        t0, c0 = time.perf_counter(), time.process_time()
        f()
        times.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return statistics.median(times), times, statistics.median(cpu)


def main(path: str) -> None:
    cfg = load_config(path)
    steps = build_plan(cfg).run_steps(cfg.plan.verification_cycles, with_oracle=False)
    t0 = time.perf_counter()
    poses = picture_poses(cfg, steps)
    t_poses = time.perf_counter() - t0
    report = check_path(cfg, poses)
    pic = cell_picture(cfg, steps, poses, report)
    print(f"{path}: {len(steps)} steps, {len(poses)} poses ({pic.vias} vias), families {pic.families}; "
          f"SVG {len(pic.svg) / 1e3:.0f} kB, PNG {len(pic.png or b'') / 1e3:.0f} kB")
    print(f"  poses with the vias (plan_path) {t_poses:.2f} s, the collision check {report.seconds:.2f} s (before the drawing)")
    for what, png in (("SVG", False), ("SVG and PNG", True)):
        med, times, cpu = _median(lambda png=png: cell_picture(cfg, steps, poses, report, png=png))
        print(f"  draw {what}: median {med:.2f} s of {', '.join(f'{t:.2f}' for t in times)} s (CPU {cpu:.2f} s); "
              f"load average {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "examples/puma560_obstacles/cell.toml")
