"""Cost of one configured tool in a calibration run ([[tool]], docs/correction.md "Tools after the
head"): the tool's own correction table and figures after the head's table, without a truth (a
real cell) and with one (simulation: the oracle's table too). Synthetic identified parameters on
the template cell; nothing moves. Prints the median of ``--runs`` timings. Asserts nothing.

    .venv/bin/python benchmarks/bench_tools.py [--runs 5]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from drivers.controller_map import MAX_TABLE_VALUES
from station.cell.config.cell_config import parse_text
from station.cell.config.template import TEMPLATE
from station.cell.correction.robot_tools import evaluate_tool
from station.cell.pipeline.calibration import grid_for
from station.cell.plan.measurement_plan import build_plan
from station.core.table.build import build_correction_table

GRIPPER = '\n[[tool]]\nname = "gripper"\ntcp = [50.0, 0.0, -200.0, 0.0, 0.0, 0.0]\nz_mm = [150.0, 350.0, 200.0]\n'


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=5)
    args = ap.parse_args()
    cfg = parse_text(TEMPLATE + GRIPPER)
    steps = build_plan(cfg).run_steps(cfg.plan.verification_cycles, True)
    rng = np.random.default_rng(1)
    scale = np.tile([0.04, 0.04, 0.04, 7e-4, 7e-4, 7e-4], cfg.model.n_params // 6)
    p_id = cfg.model.nominal + rng.normal(size=cfg.model.n_params) * scale
    p_true = p_id + rng.normal(size=cfg.model.n_params) * scale * 0.02
    head = build_correction_table(cfg.model, p_id, grid_for(cfg), capacity=MAX_TABLE_VALUES)
    real, sim = [], []
    for _ in range(args.runs):
        t0 = time.perf_counter()
        evaluate_tool(cfg, cfg.tools[0], p_id, steps, head)
        t1 = time.perf_counter()
        evaluate_tool(cfg, cfg.tools[0], p_id, steps, head, p_ref=p_true)
        t2 = time.perf_counter()
        real.append(t1 - t0)
        sim.append(t2 - t1)
    n = len({(st.point, st.elbow) for st in steps if st.kind.is_verification})
    print(f"one tool, {n} verification targets, {args.runs} runs (median):")
    print(f"  real cell (own table, head's figure predicted): {statistics.median(real):.2f} s")
    print(f"  simulation (+ oracle's table, three figures):   {statistics.median(sim):.2f} s")


if __name__ == "__main__":
    main()
