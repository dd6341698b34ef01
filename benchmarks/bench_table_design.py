"""A new cell right the first time (issue 27): over many seeds, how runs end, and how well the
correction's bound predicted before motion matches the identified robot's table.

Runs ``station calibrate --simulated [CONFIG] --seed N`` in-process (a fresh run database each)
for seeds 0–19 of the built-in cell and 1–10 of ``examples/scara_arc``, and prints per run: the
outcome, the bound predicted before motion (median of the sampled robots), the identified
robot's table bound over the same cells, their ratio, the grid and the wall time; then per cell
the count of SUCCESS / refused before motion / failed after measuring, and the ratio's median,
range and how many runs lie within ×1.5. The prediction never sees the simulator's true robot.

    .venv/bin/python benchmarks/bench_table_design.py                       # both cells (~20–30 min)
    .venv/bin/python benchmarks/bench_table_design.py --builtin 0 1 --arc   # a quick look
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

from station.cell.session.calibrate import CellRequest, run_calibration_session
from station.ui.simulated_cell import load_cell

ROOT = Path(__file__).resolve().parents[1]
ARC = str(ROOT / "examples" / "scara_arc" / "cell.toml")


def one(config: str | None, seed: int) -> dict[str, Any]:
    """One rehearsal: its outcome, whether it measured, and the correction's figures."""
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        s = run_calibration_session(CellRequest(config=config, simulated=True, seed=seed,
                                                db=str(Path(tmp) / "runs.sqlite")), lambda e: None, load=load_cell)
        wall = time.perf_counter() - t0
    corr = s.to_json().get("correction") or {}
    measured = s.run_id is not None and s.identification is not None
    return {"seed": seed, "outcome": s.outcome.name, "measured": measured, "run": s.run_id is not None,
            "predicted": corr.get("predicted_bound_um"), "identified": corr.get("interpolation_bound_um"),
            "grid": corr.get("grid_shape"), "n_values": corr.get("n_values"), "refined": corr.get("refined"),
            "reason": s.to_json().get("not_uploaded_reason"), "wall_s": wall,
            "failure": s.failure.message if s.failure else None, "gain": s.gain, "after_vs_oracle": s.after_vs_oracle}


def _f(v: Any, fmt: str) -> str:
    return "–" if v is None else format(v, fmt)


def report(name: str, rows: list[dict[str, Any]]) -> None:
    print(f"\n{name}")
    print(f"{'seed':>4}  {'outcome':22}  {'pred µm':>7}  {'ident µm':>8}  {'ratio':>5}  {'grid':16}  {'values':>6}  "
          f"{'gain':>6}  {'a/o':>5}  {'wall s':>6}")
    for r in rows:
        ratio = r["identified"] / r["predicted"] if r["identified"] and r["predicted"] else None
        grid = "×".join(map(str, r["grid"])) if r["grid"] else "–"
        print(f"{r['seed']:>4}  {r['outcome']:22}  {_f(r['predicted'], '7.1f')}  {_f(r['identified'], '8.1f')}  "
              f"{_f(ratio, '5.2f')}  {grid:16}  {_f(r['n_values'], '6d')}  {_f(r['gain'], '6.1f')}  "
              f"{_f(r['after_vs_oracle'], '5.2f')}  {r['wall_s']:6.1f}" + ("  refined" if r["refined"] else ""))
        if r["failure"] or r["reason"]:
            print(f"      {r['reason'] or ''} {(r['failure'] or '')[:400]}")
    ok = sum(r["outcome"] == "SUCCESS" for r in rows)
    before = sum(r["outcome"] != "SUCCESS" and not r["run"] for r in rows)
    after = sum(r["outcome"] != "SUCCESS" and r["run"] for r in rows)
    print(f"{name}: {len(rows)} runs: {ok} SUCCESS, {before} refused before motion, {after} failed after measuring")
    ratios = [r["identified"] / r["predicted"] for r in rows if r["identified"] and r["predicted"]]
    if ratios:
        within = sum(1 / 1.5 <= x <= 1.5 for x in ratios)
        print(f"identified / predicted bound: median {statistics.median(ratios):.2f}, range {min(ratios):.2f}–"
              f"{max(ratios):.2f}, within ×1.5 in {within} of {len(ratios)}; identified above predicted × 1.5 in "
              f"{sum(x > 1.5 for x in ratios)}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--builtin", type=int, nargs="*", default=list(range(20)), help="seeds of the built-in cell")
    ap.add_argument("--arc", type=int, nargs="*", default=list(range(1, 11)), help="seeds of examples/scara_arc")
    ap.add_argument("--config", default=ARC, help="the second cell (default examples/scara_arc/cell.toml)")
    args = ap.parse_args()
    if args.builtin:
        report("built-in simulated cell", [one(None, s) for s in args.builtin])
    if args.arc:
        report(args.config, [one(args.config, s) for s in args.arc])


if __name__ == "__main__":
    main()
