"""Cost of the redundant-head checks per touch: the pose solve with the residual test (every
touch of a head with more than six probes), and the diagnosis of a touch that failed it
(leave-one-out and the frozen-reading test), for the seven-probe example head and a ten-probe head.

    .venv/bin/python benchmarks/bench_probe_check.py [--runs 7] [--n 50]

Prints the median over the runs of the mean time per touch [ms]; nothing is asserted (timings
depend on the machine). A touch takes seconds of motion and settling, so these are overheads.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from station.core.kinematics.transforms import pose_to_matrix  # noqa: E402
from station.core.probe.check import diagnose, residual_test  # noqa: E402
from station.core.probe.geometry import FACE_NORMALS, ProbeHeadGeometry, readings_from_pose, solve_pose  # noqa: E402
from station.io.head_file import load_head  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def ten_probe_head() -> ProbeHeadGeometry:
    contacts = [(0, (5, 5, 0)), (0, (35, 5, 0)), (0, (20, 35, 0)), (0, (35, 30, 0)), (1, (0, 6, -8)),
                (1, (0, 34, -12)), (1, (0, 20, -30)), (2, (6, 0, -10)), (2, (34, 0, -8)), (2, (20, 0, -30))]
    M0 = pose_to_matrix(np.array([0.0, 0.0, -60.0, 0.0, 0.0, 0.0]))
    pts = np.array([M0[:3, :3] @ (np.array(p, float) + FACE_NORMALS[f]) + M0[:3, 3] for f, p in contacts])
    dirs = np.array([-FACE_NORMALS[f] for f, _ in contacts])
    return ProbeHeadGeometry(pts, dirs, np.array([f for f, _ in contacts]), 1.0, 10.0, 40.0, M0)


def touches(geom: ProbeHeadGeometry, n: int, seed: int = 0) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    Mn = geom.nominal_contact_pose()
    return [readings_from_pose(geom, Mn @ pose_to_matrix(np.r_[rng.uniform(-0.5, 0.5, 3), rng.uniform(-0.004, 0.004, 3)]))
            + rng.normal(0, 0.0005, geom.n_probes) for _ in range(n)]


def per_touch_ms(fn, items, runs: int) -> float:
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        for it in items:
            fn(it)
        times.append((time.perf_counter() - t0) / len(items) * 1e3)
    return statistics.median(times)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=7)
    ap.add_argument("--n", type=int, default=50)
    a = ap.parse_args(argv)
    for name, geom, bad in (("seven-probe (stuck P3)", load_head(ROOT / "examples/heads/seven-probe.toml").geometry, "stuck"),
                            ("ten-probe (20 µm on probe 6)", ten_probe_head(), "debris")):
        clean = touches(geom, a.n)

        def check(r, geom=geom):
            sol = solve_pose(geom, r, check_residuals=False)
            return residual_test(geom, r, sol.M)

        seen = []
        for r in clean:
            r = r.copy()
            if bad == "stuck":
                r[2] = clean[0][2]  # P3 frozen at the first touch's reading
            else:
                r[5] += 0.02
            seen.append(r)
        # each touch with the (faulty) touches before it, most recent first, as the runner keeps them
        faulty = [(seen[i], seen[max(i - 8, 0):i][::-1]) for i in range(1, len(seen))]

        def diag(item, geom=geom):
            r, prev = item
            return diagnose(geom, r, check(r), prev)

        named = sum(diag(it).suspect is not None for it in faulty)
        print(f"{name}: solve + residual test {per_touch_ms(check, clean, a.runs):.2f} ms/touch; "
              f"diagnosis of a failed touch {per_touch_ms(diag, faulty, a.runs):.1f} ms/touch "
              f"(named {named}/{len(faulty)}); median of {a.runs} runs")


if __name__ == "__main__":
    main()
