"""Timing of the general inverse kinematics (station.core.kinematics.ik) and of compensated targets on the
six-axis robot: medians of repeated runs after a warm-up.

    .venv/bin/python benchmarks/bench_ik.py [--repeat 7] [--robot irb2600] [--steps 300]

Figures: IK of a 300-step plan (all eight branches refined on the identified model, one chosen
per step; target < 1 s), the same with a requested configuration, compensated targets for
the 300 steps, and a joint-offset fit over 500 poses. Prints each figure, its target where it
has one, and target/figure (> 1: faster than the target). No asserts.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from benchmarks._timing import median_time  # noqa: E402
from station.core.kinematics.compensation import compensated_targets  # noqa: E402
from station.core.kinematics.forward import forward  # noqa: E402
from station.core.kinematics.ik import ArmConfig, solve_ik  # noqa: E402
from station.core.kinematics.joint_offsets import fit_joint_offsets  # noqa: E402
from station.core.kinematics.poses import spread_joints  # noqa: E402
from station.io.robot.files import load_robot  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=7, help="timed runs per figure (>= 5)")
    ap.add_argument("--robot", default="irb2600", help="six-axis robot (built-in name or file)")
    ap.add_argument("--steps", type=int, default=300, help="plan steps (default 300)")
    args = ap.parse_args(argv)
    repeat = max(5, args.repeat)
    model = load_robot(args.robot)
    rng = np.random.default_rng(0)
    identified = model.nominal + rng.standard_normal(model.n_params) * np.where(model.is_angle(), 5e-4, 0.3)
    q = spread_joints(model, args.steps, rng)
    T = forward(model, q, identified, setup=False)
    res = solve_ik(model, T, identified)
    print(f"robot {model.name}, {args.steps} targets; solved {int(res.has_joints.sum())}, "
          f"median {float(np.median(res.n_solutions)):.0f} valid solutions per target")
    rows = [
        (f"IK, {args.steps}-step plan, identified model", lambda: solve_ik(model, T, identified), 1.0),
        (f"IK, {args.steps} steps, configuration elbow +1", lambda: solve_ik(model, T, identified,
                                                                           configuration=ArmConfig(elbow=1)), 1.0),
        (f"compensated targets, {args.steps} steps", lambda: compensated_targets(model, identified, T), None),
        ("joint-offset fit, 500 poses", lambda: fit_joint_offsets(model, identified,
                                                                   spread_joints(model, 500, rng)), None),
    ]
    for name, fn, target in rows:
        t = median_time(fn, repeat)
        extra = f"  target {target:.2f} s  ×{target / t:.1f}" if target else ""
        print(f"{name:48s} {t * 1000:9.1f} ms{extra}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
