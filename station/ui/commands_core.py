"""The numeric commands of ``station``: ``analyze``, ``identify``, ``predict``, ``study``.

They work on robot and data files only (no cell); the parser is in :mod:`station.ui.cli`.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from station.core.units import ARCSEC
from station.errors import ConfigError


def _names(s: str) -> tuple[str, ...]:
    return tuple(n.strip() for n in s.split(",") if n.strip())


def _fmt_param(name: str, value: float, unit_angle="deg") -> str:
    if name.split(".")[1] in ("roll", "pitch", "yaw"):
        return f"{np.degrees(value):.6f}°"
    return f"{value:.4f} mm"


def _fmt_sigma(name: str, sigma: float) -> str:
    if name.split(".")[1] in ("roll", "pitch", "yaw"):
        return f"{sigma / ARCSEC:.2f}″"
    return f"{sigma * 1e3:.2f} µm"


def _print_json(obj) -> None:
    print(json.dumps(obj, indent=2, default=lambda o: o.tolist() if isinstance(o, np.ndarray) else str(o)))


# --- analyze --------------------------------------------------------------------------------

def cmd_analyze(args) -> int:
    from station.core.identifiability import analyze
    from station.core.measurements import random_pairs, synthetic_set
    from station.core.poses import spread_joints
    from station.io.datafile import joints_from_table, read_table
    from station.io.robot_files import load_robot

    model = load_robot(args.robot)
    rng = np.random.default_rng(args.seed)
    if args.joints:
        q = joints_from_table(read_table(args.joints), model)
    else:
        q = spread_joints(model, args.poses, rng, planar=args.planar)
    pairs = random_pairs(len(q), args.distances, rng) if args.kind == "distance" else None
    data = synthetic_set(model, args.kind, q, model.nominal, pairs=pairs)
    prefer = _names(args.prefer) or model.prefer
    a = analyze(model, data, prefer=prefer, fix=_names(args.fix), exclude=_names(args.exclude))
    if args.json:
        _print_json({"robot": model.name, "kind": args.kind, "poses": len(q), **a.to_dict()})
        return 0
    print(f"robot {model.name}: {model.n_params} parameters, complete minimal model "
          f"4R+2P+6 = {model.minimal_param_count}")
    print(f"{args.kind} measurements at {len(q)} poses{' in one plane' if args.planar else ''}"
          f"{f', {len(pairs)} distances' if pairs is not None else ''}")
    print(f"identifiable parameters (rank): {a.rank}")
    print(f"condition (scaled columns):     {a.condition:.1f} (chosen set {a.chosen_condition:.1f})")
    print(f"minimal set: {', '.join(a.chosen)}")
    if a.held:
        print(f"held at their values: {', '.join(a.held)}")
    print("left out, and what they merge with:")
    for d in a.dependencies:
        print(f"  {d.describe()}")
    return 0


# --- identify -------------------------------------------------------------------------------

def cmd_identify(args) -> int:
    from station.core.identification import identify
    from station.core.measurements import MeasurementSet, random_pairs
    from station.core.model import robot_to_toml
    from station.io.datafile import read_measurements
    from station.io.robot_files import load_robot

    model = load_robot(args.robot)
    kind, q, measured = read_measurements(args.data, model)
    objective = args.objective or kind
    sp, sa = args.sigma_position * 1e-3, args.sigma_angle * ARCSEC
    if objective == "pose":
        if kind != "pose":
            raise ConfigError(f"{args.data} holds positions only; use --objective position or distance")
        data = MeasurementSet("pose", q, measured, np.array([sp, sp, sp, sa, sa, sa]))
    else:
        pos = measured[:, :3, 3] if kind == "pose" else measured
        if objective == "position":
            data = MeasurementSet("position", q, pos, np.array([sp, sp, sp]))
        elif objective == "distance":
            pairs = random_pairs(len(q), 10**9, np.random.default_rng(0))
            d = np.linalg.norm(pos[pairs[:, 0]] - pos[pairs[:, 1]], axis=1)
            data = MeasurementSet("distance", q, d, np.sqrt(2) * sp, pairs)
        else:
            raise ConfigError(f"unknown objective {objective!r}; use pose, position or distance")
    res = identify(model, data, prefer=_names(args.prefer) or None, fix=_names(args.fix),
                   exclude=_names(args.exclude))
    if args.output:
        Path(args.output).write_text(robot_to_toml(model, res.params))
    if args.json:
        _print_json({
            "robot": model.name, "objective": objective, "n_measurements": data.n_items,
            "converged": res.converged, "evaluations": res.iterations,
            "rms_normalized": res.rms_normalized, "outliers": list(res.outliers),
            "parameters": {n: {"value": float(v), "sigma": float(s)} for n, v, s in
                           zip(res.chosen, res.estimates, res.uncertainty.sigma)},
            "max_abs_correlation": res.uncertainty.max_abs_correlation(),
            "residuals": res.residuals.tolist(), "output": args.output,
        })
        return 0
    print(f"identified {len(res.chosen)} parameters of {model.name} from {data.n_items} "
          f"{objective} measurements ({res.iterations} evaluations, "
          f"{'converged' if res.converged else 'NOT converged: ' + res.message})")
    print(f"normalised RMS residual {res.rms_normalized:.3f}; RMS position residual "
          f"{res.rms_position_mm() * 1e3:.1f} µm")
    print(f"{'parameter':12s} {'nominal':>16s} {'identified':>16s} {'σ':>12s}")
    for n, i, v, s in zip(res.chosen, res.chosen_index, res.estimates, res.uncertainty.sigma):
        print(f"{n:12s} {_fmt_param(n, model.nominal[i]):>16s} {_fmt_param(n, v):>16s} {_fmt_sigma(n, s):>12s}")
    print(f"largest |correlation|: {res.uncertainty.max_abs_correlation():.2f}")
    if res.outliers:
        print(f"suspected outliers (rows): {', '.join(str(i + 1) for i in res.outliers)}")
    if args.output:
        print(f"identified model written to {args.output}")
    return 0


# --- predict --------------------------------------------------------------------------------

def cmd_predict(args) -> int:
    from station.core.kinematics import forward
    from station.core.transforms import matrix_to_pose
    from station.io.datafile import joints_from_table, read_table
    from station.io.robot_files import load_robot

    model = load_robot(args.model)
    q = joints_from_table(read_table(args.joints), model)
    poses = matrix_to_pose(forward(model, q, setup=not args.base))
    if args.json:
        _print_json({"robot": model.name, "frame": "base" if args.base else "measurement",
                     "poses_mm_rad": poses.tolist()})
        return 0
    print("x [mm],y [mm],z [mm],roll [deg],pitch [deg],yaw [deg]")
    for p in poses:
        print(",".join([f"{v:.6f}" for v in p[:3]] + [f"{np.degrees(v):.8f}" for v in p[3:]]))
    return 0


# --- study ----------------------------------------------------------------------------------

def cmd_study(args) -> int:
    from station.core.study import chapter_studies
    from station.io.robot_files import load_robot

    model = load_robot(args.robot)
    reports = chapter_studies(model, seed=args.seed, n_sets=args.sets)
    if args.json:
        _print_json([{"study": r.name, "rows": [vars(x) for x in r.rows]} for r in reports])
        return 0
    for r in reports:
        print(f"\n== {r.name}")
        print(f"   {'quantity':44s} {'station':30s} chapter")
        for row in r.rows:
            print(f"   {row.quantity:44s} {row.station:30s} {row.chapter}")
    return 0
