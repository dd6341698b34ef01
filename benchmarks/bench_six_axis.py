"""A simulated six-axis cell end to end (issues 9, 22): per seed, the verification figures after
correction by compensated targets, the oracle's, gain and after/oracle, the orientation errors in
arc seconds and the joint-zero-offset-only figure beside the full model's; then the median and the
worst over the seeds, and the plan's size and robot-time estimate.

``--robot irb2600`` (the default) runs the built-in cell (``station calibrate --simulated --robot
irb2600 --seed N``); ``--robot CELL.toml`` rehearses a cell configuration of a six-axis arm
(``station calibrate --simulated CELL.toml --seed N``: its robot file, e.g. a modified-DH table,
its head, body and ``[simulation]``). Each seed runs in-process on a fresh database in a temporary
folder. The issues' checks: gain ≥ 10× on every seed, after/oracle ≤ 1.2 on every seed, median
≤ 1.05.

Robot time: the number of measurements a run makes (identification × repeats + held-out targets
× cycles × before/after) and the preview's motion estimate: at the robot file's joint speeds, or,
where the file gives none, at :data:`ASSUMED_SPEED_DEG_S` per joint (a yardstick to compare plans
by, not a duration), plus ``[plan] settle_s`` per measurement.

    .venv/bin/python benchmarks/bench_six_axis.py [--robot irb2600 | CELL.toml] [--seeds N | --seed-list 1 2 3]
    .venv/bin/python benchmarks/bench_six_axis.py --terms [--seeds N] [--poses 200: random poses, not the design]
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

#: joint speed [deg/s] of the motion estimate when the robot file gives none
ASSUMED_SPEED_DEG_S = 90.0


def _request(robot: str, seed: int, db: str):
    from station.cell.session.calibrate import CellRequest

    if robot.endswith(".toml"):
        return CellRequest(config=robot, simulated=True, seed=seed, db=db)
    return CellRequest(simulated=True, robot=robot, seed=seed, db=db)


def run_seed(robot: str, seed: int, folder: Path) -> dict:
    from station.cell.records.rundb import RunDB
    from station.cell.session.calibrate import run_calibration_session
    from station.ui.simulated_cell import load_cell

    db = str(folder / f"six-{seed}.sqlite")
    t0 = time.perf_counter()
    s = run_calibration_session(_request(robot, seed, db), lambda e: None, load=load_cell)
    wall = time.perf_counter() - t0
    if s.failure is not None:
        return {"seed": seed, "outcome": s.outcome.name, "failure": s.failure.message}
    assert s.run_id is not None
    with RunDB(db) as rdb:
        extra = rdb.load_result(s.run_id, "articulated")
    o = extra.get("orientation", {})
    acc = extra.get("joint_offsets_only", {}).get("accuracy", {})
    return {
        "seed": seed, "outcome": s.outcome.name, "wall_s": wall,
        "before_um": s.before.rms_um if s.before else None, "after_um": s.after.rms_um if s.after else None,
        "oracle_um": s.oracle.rms_um if s.oracle else None, "gain": s.gain, "after_vs_oracle": s.after_vs_oracle,
        "ap_after_um": s.after.ap_max_um if s.after else None, "rp_after_um": s.after.rp_max_um if s.after else None,
        "before_arcsec": o.get("verification_before", {}).get("rms_arcsec"),
        "after_arcsec": o.get("verification_after", {}).get("rms_arcsec"),
        "oracle_arcsec": o.get("oracle", {}).get("rms_arcsec"),
        "offsets_only_um": acc.get("joint_offsets", {}).get("rms_position_um"),
        "full_model_um": acc.get("full_model", {}).get("rms_position_um"),
        "n_parameters": s.identification.n_parameters if s.identification else None,
    }


def plan_config(robot: str):
    """The cell configuration the runs plan with (seed 1)."""
    from station.cell.config.cell_config import load_config, parse_text

    if robot.endswith(".toml"):
        return load_config(robot)
    if robot != "irb2600":
        raise SystemExit(f"--robot {robot}: give irb2600 or a cell configuration (.toml) of a six-axis arm "
                         f"(its [robot] model may be any robot file: .toml, .mdh.csv, .dh.csv, .urdf)")
    from simulators.six_axis_cell import six_axis_cell, six_axis_config_text

    class _Servers:
        def __init__(self) -> None:
            self.cell = six_axis_cell(1)
            self.probe_port = "socket://127.0.0.1:1"
            self.controller_host = "127.0.0.1"
            self.controller_port = 1502

    return parse_text(six_axis_config_text(_Servers(), 1), "<bench>")


def plan_figures(robot: str) -> dict:
    from station.cell.pipeline.preview import motion_seconds, preview

    cfg = plan_config(robot)
    t0 = time.perf_counter()
    p = preview(cfg)
    t_plan = time.perf_counter() - t0
    steps = tuple(s.step for s in p.steps)
    basis = "the robot file's joint speeds"
    motion = p.motion_s_estimate
    if motion is None:
        v = np.full(cfg.model.n_joints, np.deg2rad(ASSUMED_SPEED_DEG_S))
        cfg = dataclasses.replace(cfg, model=dataclasses.replace(cfg.model, max_speed=v))
        motion = motion_seconds(cfg, steps)
        basis = f"{ASSUMED_SPEED_DEG_S:g}°/s per joint (the robot file gives no speeds)"
    return {"preview_s": t_plan, "n_ident": p.n_identification, "n_ver": p.n_verification_targets,
            "n_steps": len(p.steps), "motion_s": motion, "settle_s": p.settle_s_total, "basis": basis,
            "sigma_um": p.sigma_position_um, "n_params": len(p.identifiable), "condition": p.condition,
            "design": None if p.design is None else p.design.describe()}


def terms_main(seeds: list[int], poses: int | None) -> int:
    """``--terms``: per seed, geometric and auto after/oracle on the arm with joint errors (issues 30,
    38), on the identification poses the station's design takes (or ``poses`` random ones)."""
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from benchmarks._six_axis_terms import N_CANDIDATES, design_poses, rehearse
    from simulators.six_axis_cell import six_axis_truth

    how = (f"{poses} random poses" if poses else f"the station's I-optimal design from {N_CANDIDATES} random "
           f"candidates (until the predicted σ is ¼ of the measurement σ)")
    print(f"six-axis arm with compliance and cyclic joint errors (simulators/joint_errors.py), pose measurements "
          f"(15 µm, 15″) at {how}, 200 held-out poses; model-level rehearsal")
    print(f"{'seed':>4}  {'poses':>5}  {'design σ':>8}  {'geometric µm':>12}  {'auto µm':>8}  {'oracle µm':>9}  "
          f"{'geo/orc':>7}  {'auto/orc':>8}  {'struct/orc':>10}  {'est µm':>6}  {'pred σ':>6}  kept")
    ratios, floors, est, pred, designs, n_poses = [], [], [], [], {}, []
    for seed in seeds:
        if not poses:
            designs[seed] = design_poses(six_axis_truth(seed).model,
                                         np.random.default_rng(np.random.SeedSequence([seed, 3031])))
        r = rehearse(seed, n_ident=poses or None, design=designs.get(seed))
        ratios.append(r["auto_vs_oracle"])
        floors.append(r["structure_vs_oracle"])
        est.append(r["estimation_um"])
        pred.append(r["predicted_um"])
        n_poses.append(r["design"]["poses"])
        sig = r["design"].get("sigma_um")
        print(f"{seed:>4}  {r['design']['poses']:>5}  {'-' if sig is None else format(sig, '8.2f'):>8}  "
              f"{r['geometric_um']:12.1f}  {r['auto_um']:8.1f}  {r['oracle_um']:9.1f}  "
              f"{r['geometric_vs_oracle']:7.2f}  {r['auto_vs_oracle']:8.3f}  {r['structure_vs_oracle']:10.3f}  "
              f"{r['estimation_um']:6.1f}  {r['predicted_um']:6.1f}  {', '.join(r['chosen']) or 'none'}"
              f"{'; missed ' + ', '.join(r['missed']) if r['missed'] else ''}", flush=True)
    print(f"auto after/oracle: median {statistics.median(ratios):.3f}, worst {max(ratios):.3f} (target ≤ 1.1, "
          f"issue 38); oracle: the truth's own model (geometry and joint errors), leaving the 10 µm repeatability; "
          f"identification poses: median {statistics.median(n_poses):g}")
    print("kept: the families auto kept; missed: the truth's (compliance, the first harmonic of every joint) it did not")
    print(f"struct: the truth's own structure (its masses, compliance, every first harmonic) fitted to the same "
          f"measurements: median {statistics.median(floors):.3f}, worst {max(floors):.3f}, the estimation floor")
    print(f"est: auto's prediction against the truth's own at the held-out poses, median {statistics.median(est):.1f} µm; "
          f"pred σ: its linear σ there (measurement σ only, no repeatability), median {statistics.median(pred):.1f} µm "
          f"(with the a-posteriori factor and the robot file's RP: benchmarks/bench_sigma_honesty.py)")
    print("the same arm rigid (no joint errors: scale 0), the same poses and noise: auto should keep nothing")
    rigid = [rehearse(seed, n_ident=poses or None, scale=0.0, design=designs.get(seed)) for seed in seeds]
    for r in rigid:
        print(f"{r['seed']:>4}  {r['design']['poses']:>5}  {'':>8}  {r['geometric_um']:12.1f}  {r['auto_um']:8.1f}  "
              f"{r['oracle_um']:9.1f}  {r['geometric_vs_oracle']:7.2f}  {r['auto_vs_oracle']:8.3f}  {'':>10}  "
              f"{r['estimation_um']:6.1f}  {r['predicted_um']:6.1f}  {', '.join(r['chosen']) or 'none'}", flush=True)
    print(f"rigid: {sum(1 for r in rigid if not r['chosen'])} of {len(rigid)} seeds keep nothing")
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robot", default="irb2600", help="irb2600 (built-in cell) or a cell configuration .toml")
    ap.add_argument("--seeds", type=int, default=3, help="seeds 1 … N")
    ap.add_argument("--seed-list", type=int, nargs="+", help="these seeds instead of 1 … N")
    ap.add_argument("--terms", action="store_true",
                    help="the arm with compliance and cyclic joint errors: geometric and --model auto after/oracle "
                         "(a model-level rehearsal, benchmarks/_six_axis_terms.py; issue 30)")
    ap.add_argument("--poses", type=int, default=None,
                    help="--terms: this many random identification poses instead of the station's design")
    args = ap.parse_args(argv)
    seeds = args.seed_list or list(range(1, args.seeds + 1))
    if args.terms:
        return terms_main(seeds, args.poses)
    pf = plan_figures(args.robot)
    robot_s = (pf["motion_s"] or 0.0) + pf["settle_s"]
    print(f"plan ({args.robot}, seed 1): {pf['n_ident']} identification steps, {pf['n_ver']} held-out targets, "
          f"{pf['n_steps']} measurements in a run; {pf['n_params']} parameters, condition {pf['condition']:.1f}, "
          f"predicted σ at the held-out targets {pf['sigma_um'][0]:.1f}–{pf['sigma_um'][2]:.1f} µm; "
          f"preview {pf['preview_s']:.1f} s")
    if pf["design"]:
        print(f"design: {pf['design']}")
    print(f"robot time estimate: {robot_s:.0f} s ({pf['motion_s'] or 0.0:.0f} s motion at {pf['basis']}, "
          f"no acceleration; {pf['settle_s']:.0f} s settling)")

    def f(v, fmt: str) -> str:
        return "-" if v is None else format(v, fmt)

    print(f"{'seed':>4}  {'outcome':8}  {'before µm':>9}  {'after µm':>8}  {'oracle µm':>9}  {'gain':>6}  "
          f"{'aft/orc':>7}  {'AP µm':>6}  {'RP µm':>6}  {'before″':>7}  {'after″':>6}  {'oracle″':>7}  "
          f"{'offs µm':>7}  {'full µm':>7}  {'wall s':>6}")
    gains, ratios = [], []
    with tempfile.TemporaryDirectory() as d:
        for seed in seeds:
            r = run_seed(args.robot, seed, Path(d))
            if "failure" in r:
                print(f"{seed:>4}  {r['outcome']:8}  {r['failure']}")
                continue
            if r["gain"] is not None:
                gains.append(r["gain"])
            if r["after_vs_oracle"] is not None:
                ratios.append(r["after_vs_oracle"])
            print(f"{seed:>4}  {r['outcome'][:8]:8}  {f(r['before_um'], '9.1f')}  {f(r['after_um'], '8.1f')}  "
                  f"{f(r['oracle_um'], '9.1f')}  {f(r['gain'], '6.1f')}  {f(r['after_vs_oracle'], '7.2f')}  "
                  f"{f(r['ap_after_um'], '6.1f')}  {f(r['rp_after_um'], '6.1f')}  {f(r['before_arcsec'], '7.1f')}  "
                  f"{f(r['after_arcsec'], '6.1f')}  {f(r['oracle_arcsec'], '7.1f')}  {f(r['offsets_only_um'], '7.1f')}  "
                  f"{f(r['full_model_um'], '7.1f')}  {f(r['wall_s'], '6.1f')}", flush=True)
    if ratios and gains:
        print(f"after/oracle: median {statistics.median(ratios):.3f}, worst {max(ratios):.3f}; gain: median "
              f"{statistics.median(gains):.1f}, worst {min(gains):.1f} ({len(ratios)} of {len(seeds)} seeds)")
    print("columns: RMS position error of the held-out poses before / after correction by compensated "
          "targets / with the oracle's (true parameters); gain = before/after; AP, RP: ISO 9283 maxima after; "
          "″: RMS orientation error; offs: joint-zero offsets only, full: the full model, both on the same "
          "targets against the simulator's truth (no measurement noise)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
