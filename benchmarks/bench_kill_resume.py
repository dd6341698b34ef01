"""SIGKILL a simulated calibration at many random points and resume it each time (the sweep
tests/cell/test_resume.py keeps three points of, issue 42).

A simulator process (``python -m simulators --seed SEED``) outlives the station processes. First
one uninterrupted ``station calibrate CONFIG`` gives the reference; then one run is started and
killed ``--kills`` times, each once a random number of its plan's steps is committed (synced on
the run database, never on a clock), resumed after each kill, and finished. Prints each kill's
committed steps and seconds, whether every committed step stayed committed, whether the finished
run holds each step exactly once, and the largest difference of its identified parameters from
the reference's. Exit 1 unless all hold and the difference is ≤ 1e-12.

    .venv/bin/python benchmarks/bench_kill_resume.py [--kills 20] [--seed 3] [--rng 20261121]
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from simulators.cell import SimulatedCell
from simulators.reference_cell import cell_config_text
from station.cell.records.reading.run_list import committed_steps
from station.cell.records.rundb import RunDB

ROOT = Path(__file__).resolve().parents[1]
ENV = dict(os.environ, PYTHONPATH=str(ROOT))


def _station(*args: object) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "station.ui.cli.main", *map(str, args)], cwd=ROOT, env=ENV,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)


def _finish(cfg: Path, db: Path, *extra: object) -> tuple[np.ndarray, int, bool]:
    p = _station("calibrate", cfg, "--db", db, *extra)
    _, err = p.communicate()
    if p.returncode != 0:
        raise SystemExit(f"calibrate ended {p.returncode}: {err[-2000:]}")
    with RunDB(db) as d:
        idx = [r.step_index for r in d.measurements(1)]
        once = len(idx) == len(set(idx)) == d.run(1).n_steps
        return np.array(d.load_result(1, "identification")["params"]), d.run(1).n_steps, once


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kills", type=int, default=20)
    ap.add_argument("--seed", type=int, default=3, help="the simulated cell's seed")
    ap.add_argument("--rng", type=int, default=20261121, help="seed of the kill points")
    a = ap.parse_args(argv)
    sim = subprocess.Popen([sys.executable, "-m", "simulators", "--seed", str(a.seed)], cwd=ROOT, env=ENV,
                           stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        ep = json.loads(sim.stdout.readline())  # type: ignore[union-attr]
        host, port = ep["controller"].rsplit(":", 1)
        servers = SimpleNamespace(cell=SimulatedCell(seed=a.seed), probe_port=ep["probe_head"],
                                  controller_host=host, controller_port=int(port))
        with tempfile.TemporaryDirectory() as tmp:
            cfg = Path(tmp) / "cell.toml"
            cfg.write_text(cell_config_text(servers, a.seed))  # type: ignore[arg-type]
            ref, n_steps, _ = _finish(cfg, Path(tmp) / "ref.sqlite")
            points = np.sort(np.random.default_rng(a.rng).integers(1, n_steps - 1, a.kills))
            db, seen, kept = Path(tmp) / "crash.sqlite", [], True
            print(f"{n_steps} steps; kill  committed  seconds")
            for k, point in enumerate(points, 1):
                t0 = time.perf_counter()
                p = _station("calibrate", cfg, "--db", db, *(["--resume", 1] if committed_steps(db) else []))
                target = max(len(seen) + 1, int(point))
                while p.poll() is None and len(committed_steps(db)) < target:
                    time.sleep(0.02)
                p.send_signal(signal.SIGKILL)
                p.wait()
                done = committed_steps(db)
                kept &= set(seen) <= set(done)
                seen = done
                print(f"{k:14d}  {len(done):9d}  {time.perf_counter() - t0:7.1f}")
            params, _, once = _finish(cfg, db, "--resume", 1)
            diff = float(np.max(np.abs(params - ref)))
            print(f"{a.kills} kills: committed steps kept {'yes' if kept else 'NO'}; each step once "
                  f"{'yes' if once else 'NO'}; largest parameter difference from the uninterrupted run {diff:.1e}")
            return 0 if kept and once and diff <= 1e-12 else 1
    finally:
        sim.send_signal(signal.SIGTERM)
        sim.wait(10)


if __name__ == "__main__":
    raise SystemExit(main())
