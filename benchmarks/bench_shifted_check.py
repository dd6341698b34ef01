"""Cost of the collision check of the verification path as the controller moves it with a correction
(issue 40), beside the pre-motion check of the whole plan: poses, least clearance [mm] and seconds, each
the median of ``--repeat`` runs (a fresh configuration each: nothing cached from the run before).

A SCARA (station/cell/plan/moved_path/shifted_check.py): the verification-after steps with a uniform table of
``--dq-deg`` in every revolute joint, as last stop checked them (the steps alone: no transition, no
re-measure) and as now (from the retract of the last step before correction, with a redundant head's
re-measures); the difference is the added cost. An articulated arm
(station/cell/plan/moved_path/compensated_check.py): the compensated targets of a robot whose joint 1 zero is off by
``--dq-deg``, from the last verification step before correction.
Usage: python benchmarks/bench_shifted_check.py examples/scara600/cell.toml [--dq-deg 0.3] [--repeat 5]"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import time

import numpy as np

from station.cell.config.cell_config import load_config
from station.cell.plan.measurement_plan import build_plan
from station.cell.plan.moved_path.shifted_check import check_shifted, preceding, remeasures, shifted_path
from station.cell.plan.run_path import check_plan
from station.cell.plan.steps import StepKind
from station.core.table.values import CorrectionTableData, TableAxis


def _table(dq: np.ndarray) -> CorrectionTableData:
    """``dq`` (g,) everywhere in reach (one configuration)."""
    axes = (TableAxis(-1000.0, 500.0, 5),) * 3 + (TableAxis(-np.pi, np.pi / 4, 8, periodic=True),)
    return CorrectionTableData(axes, np.broadcast_to(dq, (1, 5, 5, 5, 8, dq.size)).copy())


def _least(report) -> str:
    c = report.closest
    return f"over {2 * report.margin_mm:g} mm" if c is None else f"{c.clearance_mm:.2f} mm ({c.a} / {c.b})"


def _timed(fn, *args):
    t0 = time.perf_counter()
    out = fn(*args)
    return out, time.perf_counter() - t0


def _scara(cfg, steps, dq_deg: float):
    """(last stop's check, this one's): the reports and their seconds."""
    R = cfg.model.nominal[:6]
    dq = np.array([np.radians(dq_deg) if k == "revolute" else 0.0 for k in cfg.model.joint_types])
    bare = dataclasses.replace(cfg, plan=dataclasses.replace(cfg.plan, remeasure_attempts=0))
    old = _timed(lambda: check_shifted(bare, steps, R, _table(dq), {StepKind.VERIFY_AFTER}))
    prev = preceding(steps, {StepKind.VERIFY_AFTER})

    def now():
        start = None if prev is None else shifted_path(cfg, [prev], R, None, vias=False)[3]
        return check_shifted(cfg, steps, R, _table(dq), {StepKind.VERIFY_AFTER}, start=start)

    return old, _timed(now)


def _arm(cfg, steps, dq_deg: float):
    """The compensated targets' check, the targets' computation included."""
    from station.cell.pipeline.articulated import articulated_targets
    from station.cell.plan.moved_path.compensated_check import check_compensated, standing_at

    R = cfg.model.nominal[:6]
    p = np.array(cfg.model.nominal, dtype=float)
    p[cfg.model.param_names.index("A1.yaw")] += np.radians(dq_deg)

    def now():
        start = standing_at(cfg, preceding(steps, {StepKind.VERIFY_AFTER}), articulated_targets(cfg, steps, None, R))
        return check_compensated(cfg, steps, articulated_targets(cfg, steps, p, R), {StepKind.VERIFY_AFTER},
                                 start=start)

    return None, _timed(now)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("config")
    ap.add_argument("--dq-deg", type=float, default=0.3)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    pre_s, old_s, now_s = [], [], []
    for _ in range(args.repeat):
        cfg = load_config(args.config)
        plan = build_plan(cfg)
        pre, t = _timed(check_plan, cfg, plan)
        pre_s.append(t)
        steps = plan.run_steps(cfg.plan.verification_cycles, False)
        old, (now, t_now) = (_scara if cfg.model.is_scara else _arm)(cfg, steps, args.dq_deg)
        now_s.append(t_now)
        if old is not None:
            old_s.append(old[1])
    assert now is not None
    n_after = sum(1 for st in steps if st.kind is StepKind.VERIFY_AFTER)
    print(f"{args.config}: median of {args.repeat}")
    print(f"  pre-motion check of the plan: {pre.poses} poses, least clearance {_least(pre)}, "
          f"{statistics.median(pre_s):.3f} s")
    if old is not None:
        print(f"  shifted verification path, the steps alone ({n_after} steps, {args.dq_deg:g} deg in every revolute "
              f"joint): {old[0].poses} poses, least clearance {_least(old[0])}, {statistics.median(old_s):.3f} s")
    what = ("with the transition and the re-measures" + f" ({remeasures(cfg)} a touch)" if cfg.model.is_scara else
            f"compensated targets, joint 1's zero off by {args.dq_deg:g} deg, with the transition")
    added = "" if not old_s else f", added {statistics.median(now_s) - statistics.median(old_s):+.3f} s"
    print(f"  verification path {what}: {now.poses} poses ({now.vias} vias), least clearance {_least(now)}, "
          f"{statistics.median(now_s):.3f} s{added}")


if __name__ == "__main__":
    main()
