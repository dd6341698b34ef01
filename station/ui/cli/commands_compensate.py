"""``station compensate MODEL TARGETS.csv -o OUT.csv``: a target list filtered through the
identified model, the way offline-programming users filter their programs (docs/correction.md,
"Robots without a table").

TARGETS.csv: optional ``#`` comment lines, a header, one target per row. Columns
``x_mm, y_mm, z_mm, roll_deg, pitch_deg, yaw_deg`` (the tool frame K in the robot base frame;
``--setup``: in the measurement frame) and optionally ``shoulder, elbow, wrist`` (+1, −1, or
0/empty for "any"; a SCARA has only ``elbow``). Any other column is refused.

OUT.csv: one row per input row, in order: ``row`` (1-based data row), ``status`` (``ok`` or
the reason code), the compensated target in the same columns, the configuration to command it
with, the joints ``q1_deg …`` (``_mm`` for prismatic joints), ``residual_um``/``residual_arcsec``
(what the identified robot misses the target by: round-off), ``correction_um``/
``correction_arcsec`` (how far the command lies from the target) and ``reason``. A row that
could not be compensated is written with its status and reason and empty values, so the row
numbers still match the program; its reason also goes to stderr (and ``--json``), and the exit
code is 4 (UNREACHABLE).

The nominal model — what the controller computes with — is ``--robot`` (default: the built-in
robot of the model's name, as ``station validate`` does). ``--base-link``/``--tip-link`` choose
the chain of whichever of the model and ``--robot`` is a URDF (docs/robot-file.md).
"""

from __future__ import annotations

import csv
import io
import json
import math
import sys
from pathlib import Path

import numpy as np

from station.errors import ConfigError, Outcome
from station.ui.cli.process.output import write_file

POSE_COLUMNS = ("x_mm", "y_mm", "z_mm", "roll_deg", "pitch_deg", "yaw_deg")
CONFIG_COLUMNS = ("shoulder", "elbow", "wrist")
MAX_TARGET_FILE_BYTES = 64 * 2**20


def read_targets(path: str | Path) -> tuple[np.ndarray, np.ndarray | None, list[int]]:
    """Poses ``(n, 6)`` [mm, rad], configurations ``(n, 3)`` (None without those columns) and
    the file line of each row. Any defect is a :class:`ConfigError` naming line and column."""
    from station.io.robot.files import read_user_text

    text = read_user_text(Path(path), MAX_TARGET_FILE_BYTES, "target file")
    lines = [(i + 1, ln) for i, ln in enumerate(text.splitlines()) if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise ConfigError(f"{path}: empty; expected a header {','.join(POSE_COLUMNS)} and one target per row")
    head_line, head = lines[0]
    header = [h.strip() for h in next(csv.reader([head]))]
    allowed = POSE_COLUMNS + CONFIG_COLUMNS
    for c, h in enumerate(header, start=1):
        if h not in allowed:
            raise ConfigError(f"{path} line {head_line}, column {c}: unknown column {h!r}; allowed: "
                              f"{', '.join(allowed)}")
        if header.index(h) != c - 1:
            raise ConfigError(f"{path} line {head_line}, column {c}: column {h!r} appears twice")
    missing = [h for h in POSE_COLUMNS if h not in header]
    if missing:
        raise ConfigError(f"{path} line {head_line}: missing columns {', '.join(missing)}; the header needs "
                          f"{','.join(POSE_COLUMNS)}")
    has_cfg = any(h in header for h in CONFIG_COLUMNS)
    poses, cfgs, line_of = [], [], []
    for ln, raw in lines[1:]:
        fields = [f.strip() for f in next(csv.reader([raw]))]
        if len(fields) != len(header):
            raise ConfigError(f"{path} line {ln}: {len(fields)} fields, the header has {len(header)}")
        rec = dict(zip(header, fields))
        pose = []
        for h in POSE_COLUMNS:
            col = header.index(h) + 1
            try:
                v = float(rec[h])
            except ValueError:
                raise ConfigError(f"{path} line {ln}, column {col} ({h}): {rec[h]!r} is not a number") from None
            if not math.isfinite(v):
                raise ConfigError(f"{path} line {ln}, column {col} ({h}): {rec[h]!r} is not a finite number")
            pose.append(v if h.endswith("_mm") else math.radians(v))
        cfg = []
        for h in CONFIG_COLUMNS:
            s = rec.get(h, "")
            if s in ("", "0", "+0", "-0"):
                cfg.append(0)
            elif s in ("1", "+1", "-1"):
                cfg.append(int(s))
            else:
                raise ConfigError(f"{path} line {ln}, column {header.index(h) + 1} ({h}): {s!r}; write +1, -1, "
                                  f"or 0 / leave it empty for any")
        poses.append(pose)
        cfgs.append(cfg)
        line_of.append(ln)
    if not poses:
        raise ConfigError(f"{path}: no targets below the header")
    return np.array(poses), (np.array(cfgs, dtype=int) if has_cfg else None), line_of


def _chains(args) -> tuple[tuple[str | None, str | None], tuple[str | None, str | None]]:
    """``(base, tip)`` for the model and for ``--robot``: a URDF's links go to the URDF (an
    identified model is TOML, its nominal often the URDF it came from); where neither is one,
    to the model, whose loader refuses them."""
    chain = (getattr(args, "base_link", None), getattr(args, "tip_link", None))
    none = (None, None)
    model_urdf = str(args.model).endswith(".urdf")
    robot_urdf = args.robot is not None and str(args.robot).endswith(".urdf")
    return (chain if model_urdf or not robot_urdf else none), (chain if robot_urdf else none)


def _nominal_for(model, robot_arg: str | None, jmap, chain: tuple[str | None, str | None] = (None, None)):
    from station.io.robot.files import builtin_robots, load_mapped_robot

    name = robot_arg or model.name
    if robot_arg is None and name not in builtin_robots():
        raise ConfigError(f"model {model.name!r} is no built-in robot: give the controller's nominal robot "
                          f"file with --robot")
    nominal, nominal_map = load_mapped_robot(name, *chain)
    if not nominal_map.close_to(jmap):  # the joints written out must be the controller's, by one map
        raise ConfigError(f"--robot {name}: its joint map ({'; '.join(nominal_map.describe()) or 'none'}) is not the "
                          f"model's ({'; '.join(jmap.describe()) or 'none'}); give the nominal robot file the model "
                          f"was identified from")
    if (tuple(t.joint for t in nominal.transforms) != tuple(t.joint for t in model.transforms)
            or nominal.n_params != model.n_params):
        raise ConfigError(f"--robot {name}: its chain ({nominal.n_joints} joints, {len(nominal.transforms)} "
                          f"transforms) is not the model's ({model.n_joints}, {len(model.transforms)}); give the "
                          f"nominal robot file the model was identified from")
    return nominal


def _out_header(model) -> list[str]:
    joints = [f"q{j + 1}_{'deg' if t == 'revolute' else 'mm'}" for j, t in enumerate(model.joint_types)]
    return (["row", "status", *POSE_COLUMNS, *CONFIG_COLUMNS, *joints, "residual_um", "residual_arcsec",
             "correction_um", "correction_arcsec", "reason"])


def _out_rows(model, res, n: int, jmap) -> list[list[str]]:
    """The output rows, the joints as the controller counts them (the robot file's joint map inverted)."""
    from station.core.kinematics.transforms import matrix_to_pose

    rows = []
    ok = res.ok
    q_controller = jmap.to_controller(res.joints)
    for i in range(n):
        if not ok[i]:
            rows.append([str(i + 1), res.status[i].value] + [""] * (len(_out_header(model)) - 3) + [res.reason[i]])
            continue
        pose = matrix_to_pose(res.commands[i])
        vals = [f"{v:.6f}" for v in pose[:3]] + [f"{math.degrees(v):.9f}" for v in pose[3:]]
        cfg = [str(int(c)) if c != 0 else "" for c in res.config[i]]
        q = [f"{math.degrees(v):.9f}" if t == "revolute" else f"{v:.6f}"
             for v, t in zip(q_controller[i], model.joint_types)]
        figs = [f"{res.residual_um[i]:.4f}", f"{res.residual_arcsec[i]:.4f}", f"{res.correction_um[i]:.3f}",
                f"{res.correction_arcsec[i]:.3f}"]
        rows.append([str(i + 1), "ok", *vals, *cfg, *q, *figs, ""])
    return rows


def cmd_compensate(args) -> int:
    from station.core.kinematics.compensation import compensated_targets
    from station.core.kinematics.transforms import pose_to_matrix
    from station.io.robot.files import load_mapped_robot

    model_chain, robot_chain = _chains(args)
    model, jmap = load_mapped_robot(args.model, *model_chain)
    nominal = _nominal_for(model, args.robot, jmap, robot_chain)
    poses, cfgs, line_of = read_targets(args.targets)
    if cfgs is not None and nominal.is_scara and np.any(cfgs[:, [0, 2]] != 0):
        bad = int(np.argmax(np.any(cfgs[:, [0, 2]] != 0, axis=1)))
        raise ConfigError(f"{args.targets} line {line_of[bad]}: a SCARA has only the elbow configuration; "
                          f"leave shoulder and wrist empty")
    n = len(poses)
    from station.ui.cli.commands_model import gear_ratios_of, gravity_of, joint_delta_of, stored_terms

    terms = stored_terms(args.model)  # [error_terms] (issue 30): the joints stand at q + Δq(q)
    if terms is not None and terms.names:
        from station.core.terms.compensation import compensated_targets_with_terms

        res = compensated_targets_with_terms(nominal, model.nominal,
                                             joint_delta_of(model, terms, gravity_of(args.model, model),
                                                            gear_ratios_of(args.model, model)),
                                             pose_to_matrix(poses), setup=args.setup, configuration=cfgs,
                                             allow_singular=args.allow_singular)
    else:
        res = compensated_targets(nominal, model.nominal, pose_to_matrix(poses), setup=args.setup,
                                  configuration=cfgs, allow_singular=args.allow_singular)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(_out_header(nominal))
    w.writerows(_out_rows(nominal, res, n, jmap))
    write_file(args.output, buf.getvalue())
    failures = [{"row": i + 1, "line": line_of[i], "status": s.value, "reason": r} for i, s, r in res.failures()]
    ok = res.ok
    summary: dict = {
        "model": str(args.model), "robot": model.name, "nominal": nominal.name, "targets": str(args.targets),
        "output": str(args.output), "frame": "measurement (set-up R)" if args.setup else "robot base",
        "rows": n, "compensated": int(ok.sum()), "failed": failures,
        "max_correction_um": float(np.max(res.correction_um[ok])) if ok.any() else None,
        "max_correction_arcsec": float(np.max(res.correction_arcsec[ok])) if ok.any() else None,
        "max_residual_um": float(np.max(res.residual_um[ok])) if ok.any() else None,
        "max_residual_arcsec": float(np.max(res.residual_arcsec[ok])) if ok.any() else None,
        "error_terms": [] if terms is None else list(terms.names),
    }
    if args.joint_offsets:
        summary["joint_offsets"] = _joint_offsets(nominal, model.nominal, res, jmap)
    code = int(Outcome.UNREACHABLE) if failures else 0
    summary["outcome"], summary["exit_code"] = Outcome(code).name, code
    for f in failures:
        print(f"station: row {f['row']} (line {f['line']}): {f['reason']}", file=sys.stderr)
    if args.json:
        print(json.dumps(summary, indent=2))
        return code
    print(f"compensated {summary['compensated']} of {n} targets of {args.targets} with {args.model} "
          f"(controller's nominal model: {nominal.name}; targets in the {summary['frame']} frame)")
    if ok.any():
        print(f"  corrections up to {summary['max_correction_um']:.1f} µm and {summary['max_correction_arcsec']:.1f}″; "
              f"the identified model reaches every compensated target to {summary['max_residual_um']:.2g} µm")
    if failures:
        print(f"  {len(failures)} rows not compensated (reasons above); written with their status")
    if args.joint_offsets:
        _print_offsets(summary["joint_offsets"])
    print(f"written to {args.output}")
    return code


def _joint_offsets(nominal, identified, res, jmap) -> dict:
    """Joint-zero offsets fitted over the workspace (given as the controller's joints count them),
    and their accuracy on the compensated targets next to the full model's (predicted: the
    identified model is the robot)."""
    import dataclasses

    from station.core.kinematics.forward import forward
    from station.core.kinematics.joint_offsets import fit_joint_offsets, offset_accuracy
    from station.core.kinematics.poses import spread_joints

    q = spread_joints(nominal, 500, np.random.default_rng(0))
    fit = fit_joint_offsets(nominal, identified, q)
    ok = res.ok
    out = dataclasses.replace(fit, offsets=jmap.delta_to_controller(fit.offsets)).to_dict()
    if ok.any():
        targets = forward(nominal, res.joints[ok], identified, setup=False)  # the wanted poses (base frame)
        acc = offset_accuracy(nominal, identified, fit.offsets, targets, configuration=res.config[ok])
        out["accuracy_on_targets"] = acc.to_dict()
    return out


def _print_offsets(d: dict) -> None:
    print("joint-zero offsets only (for controllers that take nothing else; fitted over the workspace):")
    for o in d["offsets"]:
        v = f"{o['offset_deg']:+.6f}°" if "offset_deg" in o else f"{o['offset_mm']:+.4f} mm"
        print(f"  {o['joint']}: {v}")
    if d["unobservable"]:
        print(f"  held at 0 (not observable): {', '.join(d['unobservable'])}")
    acc = d.get("accuracy_on_targets")
    if acc:
        print(f"  on these {acc['targets']} targets (predicted by the identified model):")
        print(f"    {'':16s} {'RMS µm':>10s} {'max µm':>10s} {'RMS ″':>9s} {'max ″':>9s}")
        for key, label in (("uncorrected", "uncorrected"), ("joint_offsets", "joint offsets"),
                           ("full_model", "full model")):
            f = acc[key]
            print(f"    {label:16s} {f['rms_position_um']:10.1f} {f['max_position_um']:10.1f} "
                  f"{f['rms_orientation_arcsec']:9.1f} {f['max_orientation_arcsec']:9.1f}")
