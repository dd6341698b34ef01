"""Distance objective at scale: time and peak memory of identify from 1000 measured points.

    .venv/bin/python benchmarks/bench_distance.py [--poses 1000] [--repeat 5] [--strategy cap]

Targets (issue 10): < 2 s and < 300 MB with the default pair strategy. Each figure is the median
of ``--repeat`` runs after a warm-up; memory is the peak of Python allocations (tracemalloc,
numpy's buffers included) during one run, and the process's peak resident set for scale. The
work is the whole of what ``station identify --objective distance`` does after reading the file:
form the pairs, their distances, identify with the correlated-pair uncertainty. No asserts.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import sys
import time
import tracemalloc
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from station.core.identification.identify import identify  # noqa: E402
from station.core.kinematics.forward import forward  # noqa: E402
from station.core.kinematics.poses import spread_joints  # noqa: E402
from station.core.measurement.distance_pairs import DEFAULT_STRATEGY, STRATEGIES, distances, make_pairs  # noqa: E402
from station.core.measurement.measurements import MeasurementSet  # noqa: E402
from station.io.robot.files import load_robot  # noqa: E402

TIME_TARGET_S = 2.0
MEMORY_TARGET_MB = 300.0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--poses", type=int, default=1000)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--strategy", choices=STRATEGIES, default=DEFAULT_STRATEGY)
    ap.add_argument("--robot", default="sr800")
    args = ap.parse_args(argv)
    model = load_robot(args.robot)
    rng = np.random.default_rng(0)
    true = model.nominal + rng.standard_normal(model.n_params) * np.where(model.is_angle(), 5e-4, 0.1)
    q = spread_joints(model, args.poses, rng)
    pts = forward(model, q, true, setup=False)[:, :3, 3] + rng.standard_normal((args.poses, 3)) * 0.015

    def run():
        pairs = make_pairs(len(q), args.strategy)
        data = MeasurementSet("distance", q, distances(pts, pairs), np.sqrt(2) * 0.015, pairs)
        return identify(model, data)

    res = run()  # warm-up (and the design-rank cache, as in a long-lived process)
    times = []
    for _ in range(max(1, args.repeat)):
        t0 = time.perf_counter()
        run()
        times.append(time.perf_counter() - t0)
    tracemalloc.start()
    run()
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    t = statistics.median(times)
    print(f"distance objective, {args.poses} poses, strategy {args.strategy}: {res.residuals.shape[0]} pairs, "
          f"{len(res.chosen)} parameters; python {sys.version.split()[0]}, numpy {np.__version__}, "
          f"{os.cpu_count()} CPUs")
    print(f"time   median of {len(times)}: {t:.3f} s   (target < {TIME_TARGET_S} s, runs "
          f"{', '.join(f'{x:.3f}' for x in times)})")
    print(f"memory peak allocations: {peak / 2**20:.1f} MB (target < {MEMORY_TARGET_MB:.0f} MB); "
          f"process peak RSS {rss_mb:.0f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
