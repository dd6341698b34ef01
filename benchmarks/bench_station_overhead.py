"""Station's own time in a real-time simulated run, against motion, settling and sampling.

Target (issue 4): the station's own time ≤ 3 % of the run beyond motion, settling and sampling.
Runs the measurement phase of a real-time simulated cell (time scale 1, probe bytes paced at
38 400 baud) for a number of identification steps and splits the wall time with the runner's
own accounting. Prints the median of several runs. Asserts nothing about time.

    .venv/bin/python benchmarks/bench_station_overhead.py [--steps 6] [--runs 5]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from contextlib import ExitStack
from pathlib import Path

from simulators import start_simulated_cell
from simulators.reference_cell import cell_config_text
from station.cell.config.cell_config import parse_text
from station.cell.pipeline.calibration import _proc_for
from station.cell.plan.measurement_plan import build_plan
from station.cell.plan.steps import StepKind
from station.cell.records.rundb import RunDB
from station.cell.run.runner import Runner
from station.cell.session.calibrate import open_cell


def one_run(n_steps: int, settle: float) -> dict:
    with ExitStack() as st, tempfile.TemporaryDirectory() as d:
        srv = start_simulated_cell(seed=1, time_scale=1.0, pace=True)
        st.callback(srv.stop)
        text = cell_config_text(srv, 1).replace("settle_s = 0.0", f"settle_s = {settle}")
        cfg = parse_text(text)
        plan = [s for s in build_plan(cfg).identification if s.kind is StepKind.IDENTIFICATION][:n_steps]
        db = st.enter_context(RunDB(Path(d) / "b.sqlite"))
        run = db.create_run(cfg.source_text, [s.to_record() for s in plan])
        cell = open_cell(cfg, st)
        runner = Runner(cfg, cell.probe, cell.controller, lambda e: None)
        t0 = time.perf_counter()
        runner.measure_steps(db, run, plan, {StepKind.IDENTIFICATION}, len(plan), _proc_for(cfg, None))
        total = time.perf_counter() - t0
        busy = sum(runner.timing.values())
        return {"total": total, **runner.timing, "own": total - busy}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--steps", type=int, default=6)
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--settle", type=float, default=0.2)
    a = ap.parse_args(argv)
    rows = [one_run(a.steps, a.settle) for _ in range(a.runs)]
    med = {k: statistics.median(r[k] for r in rows) for k in rows[0]}
    ratio = statistics.median(r["own"] / r["total"] for r in rows)
    print(f"real-time simulated measurement, {a.steps} steps, median of {a.runs} runs "
          f"(time scale 1, paced 38 400 baud, settle {a.settle} s)")
    for k in ("total", "motion", "settle", "sampling", "own"):
        print(f"  {k:9s} {med[k]:8.3f} s")
    print(f"  station's own time / run: {100 * ratio:.2f} %   (target ≤ 3 %)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
