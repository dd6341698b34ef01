"""Robot time of a recheck against the full calibration (issue 13: a recheck of 10 poses takes
≤ 10 % of the full calibration's robot time).

Runs a full simulated calibration and then a recheck of ``--poses`` poses on a time-scaled
simulated cell, and compares the robot time of each from the runner's own accounting (motion,
settling, sampling). Prints the median of ``--runs`` pairs. Asserts nothing about time.

    .venv/bin/python benchmarks/bench_recheck.py [--poses 10] [--runs 3] [--time-scale 0.02]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
from pathlib import Path

import station.cell.pipeline.calibration as pipeline
import station.cell.recheck.measure as recheck
from station.cell.recheck.measure import RecheckOptions
from station.cell.recheck.session import run_recheck_session
from station.cell.run.runner import Runner
from station.cell.session.calibrate import CellRequest, run_calibration_session
from station.ui.simulated_cell import load_cell

_RUNNERS: list[Runner] = []


class _Counted(Runner):
    def __init__(self, *a, **kw):
        super().__init__(*a, **kw)
        _RUNNERS.append(self)


def robot_time() -> float:
    t = sum(sum(r.timing.values()) for r in _RUNNERS)
    _RUNNERS.clear()
    return t


def one_pair(poses: int, time_scale: float) -> tuple[float, float]:
    with tempfile.TemporaryDirectory() as d:
        req = CellRequest(simulated=True, seed=1, time_scale=time_scale, db=str(Path(d) / "b.sqlite"))
        s = run_calibration_session(req, lambda e: None, load=load_cell)
        assert s.outcome.name == "SUCCESS", s
        cal = robot_time()
        r = run_recheck_session(req, lambda e: None, options=RecheckOptions(poses=poses), load=load_cell)
        assert r.outcome.name == "SUCCESS", r
        return cal, robot_time()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--poses", type=int, default=10)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--time-scale", type=float, default=0.02)
    a = ap.parse_args(argv)
    pipeline.Runner = _Counted  # type: ignore[misc]
    recheck.Runner = _Counted  # type: ignore[misc]
    rows = [one_pair(a.poses, a.time_scale) for _ in range(a.runs)]
    cal = statistics.median(c for c, _ in rows)
    rec = statistics.median(r for _, r in rows)
    ratio = statistics.median(r / c for c, r in rows)
    print(f"simulated cell, time scale {a.time_scale}, median of {a.runs} runs (runner's motion + settle + sampling)")
    print(f"  full calibration robot time  {cal:8.2f} s")
    print(f"  recheck of {a.poses} poses (+1 repeat) {rec:8.2f} s")
    print(f"  recheck / calibration: {100 * ratio:.1f} %   (target ≤ 10 %)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
