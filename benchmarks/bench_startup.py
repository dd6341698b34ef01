"""Start-up of the ``station`` command, against bare ``import numpy, scipy.optimize``.

    .venv/bin/python benchmarks/bench_startup.py [--repeat 7] [--robot irb2600]

Each round runs every case once, in turn (interleaved, so a loaded machine slows them alike);
prints the median wall time of each case and its ratio to the bare import. The identify cases
fit a tracker's position file (10 µm noise) of 100 and of 1000 poses. Targets (issue 21):
``identify`` of 100 poses within 1.6x of the bare import, ``--help`` within 0.5x. No asserts.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from station.core.accuracy.studies import StudyInputs, perturbed  # noqa: E402
from station.core.kinematics.poses import spread_joints  # noqa: E402
from station.core.measurement.measurements import synthetic_set  # noqa: E402
from station.io.datafile import write_csv  # noqa: E402
from station.io.robot.files import load_robot  # noqa: E402

SIGMA_MM = 0.010


def _station() -> list[str]:
    """The console script beside this interpreter, as a user runs it; else the module."""
    script = Path(sys.executable).with_name("station")
    return [str(script)] if script.exists() else [sys.executable, "-m", "station.ui.cli.main"]


def write_position_file(path: Path, robot: str, n: int, seed: int) -> None:
    """``n`` measured positions of a perturbed ``robot`` (joints in deg / mm, as docs/data-files.md)."""
    model = load_robot(robot)
    rng = np.random.default_rng(seed)
    true = perturbed(model, rng, StudyInputs())
    q = spread_joints(model, n, rng)
    data = synthetic_set(model, "position", q, true, sigma=np.full(3, SIGMA_MM), rng=rng)
    revolute = np.array([k == "revolute" for k in model.joint_types])
    q_file = np.where(revolute, np.degrees(q), q)
    header = [f"q{i + 1} [{'deg' if r else 'mm'}]" for i, r in enumerate(revolute)] + ["x [mm]", "y [mm]", "z [mm]"]
    write_csv(path, header, np.column_stack([q_file, data.measured]))


def _run(cmd: list[str]) -> float:
    t0 = time.perf_counter()
    r = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, timeout=600)
    dt = time.perf_counter() - t0
    if r.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} exited {r.returncode}: {r.stderr.strip()}")
    return dt


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=7, help="interleaved rounds (>= 5)")
    ap.add_argument("--robot", default="irb2600", help="built-in robot of the data files (default irb2600, 6R)")
    args = ap.parse_args(argv)
    repeat = max(5, args.repeat)

    with tempfile.TemporaryDirectory() as tmp:
        files = {}
        for n in (100, 1000):
            files[n] = Path(tmp) / f"positions-{n}.csv"
            write_position_file(files[n], args.robot, n, seed=n)
        station = _station()
        cases = [
            ("bare: import numpy, scipy.optimize", [sys.executable, "-c", "import numpy, scipy.optimize"], None),
            ("station --help", [*station, "--help"], 0.5),
            (f"station identify, 100 poses ({args.robot})",
             [*station, "identify", str(files[100]), "--robot", args.robot], 1.6),
            (f"station identify, 1000 poses ({args.robot})",
             [*station, "identify", str(files[1000]), "--robot", args.robot], None),
        ]
        for _, cmd, _ in cases:  # warm-up: the file cache, the .pyc files
            _run(cmd)
        times: list[list[float]] = [[] for _ in cases]
        for _ in range(repeat):
            for k, (_, cmd, _) in enumerate(cases):
                times[k].append(_run(cmd))

    medians = [statistics.median(t) for t in times]
    bare = medians[0]
    print(f"station start-up benchmark: median of {repeat} interleaved rounds after a warm-up; "
          f"python {sys.version.split()[0]}, numpy {np.__version__}, {os.cpu_count()} CPUs")
    print(f"{'case':44s} {'median':>9s} {'/ bare':>8s} {'target':>8s}")
    for (name, _, target), t in zip(cases, medians):
        print(f"{name:44s} {t:8.3f}s {t / bare:7.2f}x {f'≤ {target}x' if target else '–':>8s}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
