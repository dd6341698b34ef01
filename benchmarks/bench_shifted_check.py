"""Cost of the shifted verification path's collision check (issue 40) on a SCARA example cell: the
verification-after steps as the controller moves them with a uniform table of ``--dq-deg`` in every
revolute joint (station/cell/plan/shifted_check.py), beside the pre-motion check of the whole plan:
poses, least clearance [mm] and seconds, each the median of ``--repeat`` runs (a fresh configuration
each: nothing cached from the run before).
Usage: python benchmarks/bench_shifted_check.py examples/scara600/cell.toml [--dq-deg 0.3] [--repeat 5]"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from station.cell.config.cell_config import load_config
from station.cell.plan.measurement_plan import build_plan
from station.cell.plan.run_path import check_plan
from station.cell.plan.shifted_check import check_shifted
from station.cell.plan.steps import StepKind
from station.core.table.values import CorrectionTableData, TableAxis


def _table(dq: np.ndarray) -> CorrectionTableData:
    """``dq`` (g,) everywhere in reach (one configuration)."""
    axes = (TableAxis(-1000.0, 500.0, 5),) * 3 + (TableAxis(-np.pi, np.pi / 4, 8, periodic=True),)
    return CorrectionTableData(axes, np.broadcast_to(dq, (1, 5, 5, 5, 8, dq.size)).copy())


def _least(report) -> str:
    c = report.closest
    return f"over {2 * report.margin_mm:g} mm" if c is None else f"{c.clearance_mm:.2f} mm ({c.a} / {c.b})"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("config")
    ap.add_argument("--dq-deg", type=float, default=0.3)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    pre_s, shifted_s = [], []
    for _ in range(args.repeat):
        cfg = load_config(args.config)
        plan = build_plan(cfg)
        t0 = time.perf_counter()
        pre = check_plan(cfg, plan)
        pre_s.append(time.perf_counter() - t0)
        steps = plan.run_steps(cfg.plan.verification_cycles, False)
        dq = np.array([np.radians(args.dq_deg) if k == "revolute" else 0.0 for k in cfg.model.joint_types])
        t0 = time.perf_counter()
        shifted = check_shifted(cfg, steps, cfg.model.nominal[:6], _table(dq), {StepKind.VERIFY_AFTER})
        shifted_s.append(time.perf_counter() - t0)
    assert shifted is not None
    n_after = sum(1 for st in steps if st.kind is StepKind.VERIFY_AFTER)
    print(f"{args.config}: median of {args.repeat}")
    print(f"  pre-motion check of the plan: {pre.poses} poses, least clearance {_least(pre)}, "
          f"{statistics.median(pre_s):.3f} s")
    print(f"  shifted verification path ({n_after} steps, {args.dq_deg:g} deg in every revolute joint): "
          f"{shifted.poses} poses, least clearance {_least(shifted)}, {statistics.median(shifted_s):.3f} s "
          f"(the last check_path {shifted.seconds:.3f} s; with vias: {shifted.vias} of the poses are vias)")


if __name__ == "__main__":
    main()
