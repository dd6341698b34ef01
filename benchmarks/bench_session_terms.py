"""The cell session with error terms beyond geometry (issue 30): the example PUMA 560 cell
(``examples/puma560/cell.toml``) rehearsed in simulation with ``[simulation] joint_errors =
"six-axis"`` (its joints bend under gravity and err once per turn), identified with
``[identification] model = "geometric"`` and ``"auto"``, and without joint errors with ``"auto"``.
The oracle knows the simulator's joint errors (``station/cell/pipeline/terms.py``).

Prints per seed and session: outcome, RMS before / after / oracle [µm], after/oracle, the terms
auto kept and the cross-validated RMS of the geometric and the chosen model [µm]; then the median
and worst after/oracle per session kind.

    .venv/bin/python benchmarks/bench_session_terms.py [--seeds N | --seed-list 1 2 3]
"""

from __future__ import annotations

import argparse
import shutil
import statistics
import tempfile
import time
from pathlib import Path

CELL = Path(__file__).resolve().parents[1] / "examples" / "puma560"
KINDS = (("six-axis", "geometric"), ("six-axis", "auto"), ("none", "auto"))


def session(folder: Path, seed: int, joint_errors: str, model: str) -> dict:
    """One simulated session of the example cell with ``joint_errors`` and ``model`` (time scale 0)."""
    from station.cell.session.calibrate import CellRequest, run_calibration_session
    from station.ui.simulated_cell import load_cell

    d = folder / f"{seed}-{joint_errors}-{model}"
    shutil.copytree(CELL, d)
    text = (d / "cell.toml").read_text(encoding="utf-8")
    text = text.replace("[identification]\n", f'[identification]\nmodel = "{model}"\n', 1)
    text = text.replace("[simulation]\n", f'[simulation]\njoint_errors = "{joint_errors}"\n', 1)
    (d / "cell.toml").write_text(text, encoding="utf-8")
    t0 = time.perf_counter()
    s = run_calibration_session(CellRequest(config=str(d / "cell.toml"), simulated=True, seed=seed,
                                            db=str(d / "runs.sqlite"), time_scale=0.0), lambda e: None, load=load_cell)
    out: dict = {"seed": seed, "joint_errors": joint_errors, "model": model, "outcome": s.outcome.name,
                 "wall_s": time.perf_counter() - t0}
    if s.before is not None and s.after is not None and s.oracle is not None:
        out.update(before_um=s.before.rms_um, after_um=s.after.rms_um, oracle_um=s.oracle.rms_um,
                   after_vs_oracle=s.after_vs_oracle)
    if s.error_model is not None:
        out.update(chosen=s.error_model.chosen, cv_geometric_um=s.error_model.cv_geometric_um,
                   cv_chosen_um=s.error_model.cv_chosen_um)
    if s.failure is not None:
        out["failure"] = s.failure.message
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=1, help="seeds 1 … N (default 1)")
    ap.add_argument("--seed-list", type=int, nargs="+", help="these seeds instead")
    args = ap.parse_args()
    seeds = args.seed_list or list(range(1, args.seeds + 1))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in seeds:
            for je, model in KINDS:
                r = session(Path(tmp), seed, je, model)
                rows.append(r)
                line = f"seed {seed} joint_errors={je:8s} model={model:9s} {r['outcome']}"
                if "after_um" in r:
                    line += (f"  before {r['before_um']:.1f} µm, after {r['after_um']:.1f} µm, oracle "
                             f"{r['oracle_um']:.1f} µm, after/oracle {r['after_vs_oracle']:.3f}")
                if "chosen" in r:
                    line += (f"; kept {' + '.join(r['chosen']) or 'nothing'} (CV {r['cv_geometric_um']:.1f} → "
                             f"{r['cv_chosen_um']:.1f} µm)")
                if "failure" in r:
                    line += f": {r['failure']}"
                print(line + f"  [{r['wall_s']:.1f} s]", flush=True)
    for je, model in KINDS:
        v = [r["after_vs_oracle"] for r in rows if r["joint_errors"] == je and r["model"] == model
             and r.get("after_vs_oracle") is not None]
        if v:
            print(f"joint_errors={je}, model={model}: after/oracle median {statistics.median(v):.3f}, worst "
                  f"{max(v):.3f} over {len(v)} seeds")
    return 0 if all(r["outcome"] == "SUCCESS" for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
