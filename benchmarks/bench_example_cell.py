"""Rehearse a cell from its own files on several seeds (issue 8: the example cell gains ≥ 20×
and ends with after/oracle ≤ 1.2 on three seeds).

Runs ``station calibrate --simulated CONFIG`` in-process for each seed (a fresh run database
each) and prints the RMS before/after, the gain, after/oracle and the wall time per seed, then
the median and the worst; per ``[[tool]]`` its own correction's error, its oracle's and what the
head's table would leave it. Asserts nothing about time.

    .venv/bin/python benchmarks/bench_example_cell.py [--config examples/scara600/cell.toml] [--seeds 1 2 3]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from station.cell.session.calibrate import CellRequest, run_calibration_session
from station.ui.simulated_cell import load_cell

ROOT = Path(__file__).resolve().parents[1]


def one(config: str, seed: int) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        s = run_calibration_session(CellRequest(config=config, simulated=True, seed=seed,
                                                db=str(Path(tmp) / "runs.sqlite")), lambda e: None, load=load_cell)
        wall = time.perf_counter() - t0
    return {"seed": seed, "outcome": s.outcome.name, "before_um": s.before.rms_um if s.before else None,
            "after_um": s.after.rms_um if s.after else None, "gain": s.gain, "after_vs_oracle": s.after_vs_oracle,
            "wall_s": wall, "failure": s.failure.message if s.failure else None,
            "tools": [(t.name, t.after_rms_um, t.oracle_rms_um, t.head_rms_um) for t in s.tools]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default=str(ROOT / "examples" / "scara600" / "cell.toml"))
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    args = ap.parse_args()
    rows = [one(args.config, seed) for seed in args.seeds]
    print(f"cell {args.config}")
    print(f"{'seed':>4}  {'outcome':10}  {'before µm':>10}  {'after µm':>9}  {'gain ×':>7}  {'after/oracle':>12}  {'wall s':>6}")
    for r in rows:
        def f(v, fmt):
            return format(v, fmt) if v is not None else "–"
        print(f"{r['seed']:>4}  {r['outcome']:10}  {f(r['before_um'], '10.1f')}  {f(r['after_um'], '9.1f')}  "
              f"{f(r['gain'], '7.1f')}  {f(r['after_vs_oracle'], '12.2f')}  {r['wall_s']:6.1f}")
        if r["failure"]:
            print(f"      {r['failure']}")
        for name, own, oracle, head in r["tools"]:
            ratio = own / oracle if own is not None and oracle else None
            print(f"      tool {name}: own correction {f(own, '.1f')} µm, oracle {f(oracle, '.1f')} µm "
                  f"(after/oracle {f(ratio, '.2f')}); the head's table would leave {f(head, '.1f')} µm")
    gains = [r["gain"] for r in rows if r["gain"] is not None]
    ratios = [r["after_vs_oracle"] for r in rows if r["after_vs_oracle"] is not None]
    if gains and ratios:
        print(f"median gain ×{statistics.median(gains):.1f} (worst ×{min(gains):.1f}); median after/oracle "
              f"{statistics.median(ratios):.2f} (worst {max(ratios):.2f}); wall median "
              f"{statistics.median(r['wall_s'] for r in rows):.1f} s")


if __name__ == "__main__":
    main()
