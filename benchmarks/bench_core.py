"""Timing of the numerical core on this machine: medians of repeated runs after a warm-up.

    .venv/bin/python benchmarks/bench_core.py [--repeat 7]

Prints each figure, its target, and target/figure (> 1: faster than the target). No asserts.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from benchmarks._timing import median_time  # noqa: E402
from station.core.identification import identify  # noqa: E402
from station.core.kinematics import forward_with_jacobian  # noqa: E402
from station.core.measurements import synthetic_set  # noqa: E402
from station.core.poses import spread_joints  # noqa: E402
from station.core.study import StudyInputs, perturbed  # noqa: E402
from station.core.uncertainty import monte_carlo  # noqa: E402
from station.io.robot_files import load_robot  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=7, help="timed runs per figure (>= 5)")
    args = ap.parse_args(argv)
    repeat = max(5, args.repeat)

    model = load_robot("sr800")
    rng = np.random.default_rng(0)
    inputs = StudyInputs()
    true = perturbed(model, rng, inputs)
    sig = np.array([inputs.sigma_position_mm] * 3 + [inputs.sigma_angle_rad] * 3)
    q25 = spread_joints(model, 25, rng)
    q1000 = spread_joints(model, 1000, rng)
    q10k = spread_joints(model, 10_000, rng)
    d25 = synthetic_set(model, "pose", q25, true, sigma=sig, rng=rng)
    d1000 = synthetic_set(model, "pose", q1000, true, sigma=sig, rng=rng)
    res25 = identify(model, d25)
    exact25 = synthetic_set(model, "pose", q25, true, sigma=sig)

    cases = [
        ("identify 20 params, 25 full poses", lambda: identify(model, d25), 0.010),
        ("identify 20 params, 1000 full poses", lambda: identify(model, d1000), 0.100),
        ("Monte Carlo 1000 sets x 25 poses",
         lambda: monte_carlo(model, exact25, true, res25.chosen_index, 1000, np.random.default_rng(1)), 2.0),
        ("forward_with_jacobian, 10 000 poses", lambda: forward_with_jacobian(model, q10k, true), 0.050),
    ]
    print(f"station core benchmark: median of {repeat} runs after a warm-up; "
          f"python {sys.version.split()[0]}, numpy {np.__version__}, {os.cpu_count()} CPUs")
    print(f"{'case':40s} {'median':>10s} {'target':>10s} {'target/median':>14s}")
    for name, fn, target in cases:
        t = median_time(fn, repeat)
        print(f"{name:40s} {t * 1e3:8.2f}ms {target * 1e3:8.0f}ms {target / t:14.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
