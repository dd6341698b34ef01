"""Timing of ``station identify … --model auto`` (issue 30): the geometric fit and the model chosen by
cross-validation, medians of repeated runs after a warm-up.

    .venv/bin/python benchmarks/bench_model_auto.py [--repeat 9] [--poses 100]

Two data sets of the six-axis arm (irb2600), position measurements with 15 µm noise: one with no
effect beyond geometry (the selection tries every family once and keeps none), one with compliance
and first-harmonic errors of joints 2 and 3 (it keeps them, four steps of candidates). Each figure
is the whole of what ``identify --model auto`` computes beyond reading the file: the geometric fit
(:func:`station.core.identification.identify`) and :func:`station.core.terms.selection.select_model`.
Target: well under a second (0.5 s). Then the whole command in a fresh process, ``station identify
FILE --robot irb2600 --model auto`` and the same without ``--model`` (interpreter start, imports, reading
the file and printing included). No asserts.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from benchmarks._timing import median_time  # noqa: E402
from station.core.accuracy.studies import StudyInputs, perturbed  # noqa: E402
from station.core.identification.identify import identify  # noqa: E402
from station.core.kinematics.poses import spread_joints  # noqa: E402
from station.core.measurement.measurements import MeasurementSet, add_noise  # noqa: E402
from station.core.terms.error_model import TermSpec, apply_terms, term_basis  # noqa: E402
from station.core.terms.selection import select_model  # noqa: E402
from station.io.datafile import write_csv  # noqa: E402
from station.io.robot.files import load_robot  # noqa: E402

TARGET_S = 0.5


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=9)
    ap.add_argument("--poses", type=int, default=100)
    args = ap.parse_args(argv)
    model = load_robot("irb2600")
    rng = np.random.default_rng(0)
    true = perturbed(model, rng, StudyInputs())
    q = spread_joints(model, args.poses, rng)
    spec = TermSpec(("compliance", "cyclic.q2", "cyclic.q3"))
    basis = term_basis(model, q, spec)
    print(f"identify --model auto, {args.poses} positions of {model.name}: median of {args.repeat} runs after a warm-up")
    for label, x in (("no effect beyond geometry", np.zeros(6)),
                     ("compliance + harmonics of joints 2, 3", np.array([2e-6, 3e-6, 1e-4, -5e-5, 8e-5, 6e-5]))):
        pts = apply_terms(model, q, true, basis, x)[:, :3, 3]
        d = MeasurementSet("position", q, pts, np.array([0.015] * 3))
        d = d.with_measured(add_noise(d, pts, rng))

        def run(d=d):
            return select_model(model, d, geometric=identify(model, d))

        sel = run()
        t = median_time(run, max(3, args.repeat))
        print(f"{label:40s} {t * 1e3:8.1f} ms  (target {TARGET_S * 1e3:.0f} ms, target/median {TARGET_S / t:.1f}); "
              f"kept: {', '.join(sel.chosen) or 'none'}; {len(sel.table)} candidates scored")
    with tempfile.TemporaryDirectory() as tmp:
        f = Path(tmp) / "arm.csv"
        write_csv(f, [f"q{i} [deg]" for i in range(1, 7)] + ["x [mm]", "y [mm]", "z [mm]"],
                  np.column_stack([np.degrees(q), d.measured]))
        root = Path(__file__).resolve().parents[1]
        for label, extra in (("whole command, --model auto", ["--model", "auto"]), ("whole command, geometric", [])):
            cmd = [sys.executable, "-m", "station.ui.cli.main", "identify", str(f), "--robot", "irb2600", *extra]
            times = []
            for _ in range(max(3, args.repeat // 2)):
                t0 = time.perf_counter()
                subprocess.run(cmd, cwd=root, capture_output=True, check=True)
                times.append(time.perf_counter() - t0)
            print(f"{label:40s} {statistics.median(times) * 1e3:8.1f} ms  (fresh process, median of {len(times)})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
