"""The corrected robot in its true base frame (issue 36): simulated sessions of the example cells
with a set-up at least 1 mm off in z, judged where the user commands the robot.

Per seed, runs ``station calibrate --simulated CONFIG`` in-process (a fresh run database each),
then commands the simulator's true robot to targets over the table's region (a SCARA: its
correction grid; an arm: the body's region, 150 mm around the head's targets) through three
models, as a perfect table would, and prints the RMS position error of the head frame in the
true base frame [µm]: the robot file's model (nominal), the identified one (with table) and the
reference (the truth with what a body calibration cannot see handed to the set-up, by the
identification's own choice; what it leaves is the truth's unobservable part), and with-table /
reference. The set-up's error is the seed's own draw at the configured σ with its z planted at
±1.5 mm where the draw is smaller (``[simulation] setup_error``, exact: the seed's robot and
its x, y and angles stay the draws), so every seed stands at least 1 mm off in z; the line says
so. Median over the seeds. Asserts nothing about time.

    .venv/bin/python benchmarks/bench_base_frame.py [--config examples/scara600/cell.toml] [--seeds 1 2 3]
"""

from __future__ import annotations

import argparse
import re
import statistics
import tempfile
from pathlib import Path

import numpy as np

from simulators.base_frame import base_frame_check, targets_in_box
from simulators.from_config import simulated_cell_for
from station.cell.config.cell_config import load_config
from station.cell.pipeline.results import grid_for, reference_params
from station.cell.plan.assembly import head_targets_world
from station.cell.session.calibrate import CellRequest, run_calibration_session
from station.core.kinematics.transforms import invert, pose_to_matrix
from station.ui.simulated_cell import load_cell

ROOT = Path(__file__).resolve().parents[1]
#: the set-up's z error every seed has at least [mm] (issue 36: at least 1 mm)
MIN_Z_MM = 1.5
N_TARGETS = 400


def _with_setup_error(text: str, error: np.ndarray) -> str:
    """The configuration text with ``[simulation] setup_error`` = ``error`` (6,) [mm, rad]."""
    keys = ("x_mm", "y_mm", "z_mm", "roll_deg", "pitch_deg", "yaw_deg")
    vals = np.r_[error[:3], np.degrees(error[3:])]
    table = "{ " + ", ".join(f"{k} = {float(v)!r}" for k, v in zip(keys, vals)) + " }"
    text = re.sub(r"(?m)^setup_error\s*=.*$", "", text)
    if not re.search(r"(?m)^\[simulation\]\s*$", text):
        text += "\n[simulation]\n"
    return re.sub(r"(?m)^\[simulation\]\s*$", f"[simulation]\nsetup_error = {table}", text, count=1)


def _region(cfg) -> tuple[np.ndarray, np.ndarray]:
    """The box targets are drawn in [mm, base frame]: the SCARA's correction grid, else the body's."""
    if cfg.model.is_scara:
        g = grid_for(cfg)
        return np.array([g.x_range[0], g.y_range[0], g.z_range[0]]), np.array([g.x_range[1], g.y_range[1], g.z_range[1]])
    heads = invert(pose_to_matrix(cfg.model.nominal[:6])) @ head_targets_world(cfg)
    return heads[:, :3, 3].min(axis=0) - 150.0, heads[:, :3, 3].max(axis=0) + 150.0


def one(config: Path, seed: int) -> dict:
    text = config.read_text(encoding="utf-8")
    drawn = np.array(simulated_cell_for(load_config(str(config)), seed).truth.errors[:6], dtype=float)
    planted = drawn.copy()
    if abs(drawn[2]) < MIN_Z_MM:
        planted[2] = MIN_Z_MM if drawn[2] >= 0 else -MIN_Z_MM
    # beside the original: the robot, head and body files are named relative to it
    tmp_cfg = config.with_name(f".bench_base_frame_{seed}.toml")
    tmp_cfg.write_text(_with_setup_error(text, planted), encoding="utf-8")
    try:
        cfg = load_config(str(tmp_cfg))
        truth = simulated_cell_for(cfg, seed).truth
        with tempfile.TemporaryDirectory() as tmp:
            s = run_calibration_session(CellRequest(config=str(tmp_cfg), simulated=True, seed=seed,
                                                    db=str(Path(tmp) / "runs.sqlite")), lambda e: None, load=load_cell)
    finally:
        tmp_cfg.unlink()
    row = {"seed": seed, "outcome": s.outcome.name, "setup_z_mm": float(truth.errors[2]),
           "setup_yaw_deg": float(np.degrees(truth.errors[5])), "drawn_z_mm": float(drawn[2]),
           "planted": bool(planted[2] != drawn[2])}
    if s.identification is None:
        return {**row, "failure": s.failure.message if s.failure else "not identified"}
    model = cfg.model
    p = np.array(model.nominal, dtype=float)
    chosen = tuple(e.name for e in s.identification.parameters)
    p[[model.param_index(n) for n in chosen]] = [e.value for e in s.identification.parameters]
    lo, hi = _region(cfg)
    targets = targets_in_box(model, lo, hi, N_TARGETS, np.random.default_rng(1000 + seed))
    c = base_frame_check(model, reference_params(cfg, truth), p, chosen, s.identification.objective, targets)
    return {**row, "nominal": c.nominal_um, "table": c.corrected_um, "reference": c.reference_um, "ratio": c.ratio,
            "after_vs_oracle": s.after_vs_oracle}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", type=Path, nargs="+",
                    default=[ROOT / "examples" / "scara600" / "cell.toml", ROOT / "examples" / "puma560" / "cell.toml"])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    args = ap.parse_args()
    for config in args.config:
        rows = [one(config.resolve(), seed) for seed in args.seeds]
        print(f"cell {config}: true base frame, RMS of the head frame over {N_TARGETS} targets [µm]")
        print(f"{'seed':>4}  {'outcome':8}  {'set-up z mm':>11}  {'yaw °':>6}  {'nominal':>8}  {'with table':>10}  "
              f"{'reference':>9}  {'ratio':>5}  {'after/oracle':>12}")
        for r in rows:
            if "failure" in r:
                print(f"{r['seed']:>4}  {r['outcome']:8}  {r['failure']}")
                continue
            raised = f"  (z planted; drawn {r['drawn_z_mm']:+.2f})" if r["planted"] else ""
            aor = f"{r['after_vs_oracle']:.2f}" if r["after_vs_oracle"] is not None else "–"
            print(f"{r['seed']:>4}  {r['outcome']:8}  {r['setup_z_mm']:+11.2f}  {r['setup_yaw_deg']:+6.2f}  "
                  f"{r['nominal']:8.1f}  {r['table']:10.1f}  {r['reference']:9.1f}  {r['ratio']:5.2f}  {aor:>12}{raised}")
        ok = [r for r in rows if "failure" not in r]
        if ok:
            med = {k: statistics.median(r[k] for r in ok) for k in ("nominal", "table", "reference", "ratio")}
            print(f"median  nominal {med['nominal']:.1f}  with table {med['table']:.1f}  reference "
                  f"{med['reference']:.1f}  ratio {med['ratio']:.2f} (worst {max(r['ratio'] for r in ok):.2f}); "
                  f"with table below nominal on {sum(r['table'] < r['nominal'] for r in ok)} of {len(ok)}")


if __name__ == "__main__":
    main()
