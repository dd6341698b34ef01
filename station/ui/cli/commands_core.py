"""The numeric commands of ``station``: ``analyze``, ``identify``, ``predict``, ``study``.

They work on robot and data files only (no cell); the parser is in :mod:`station.ui.cli.main`.
"""

from __future__ import annotations

import json

import numpy as np

from station.core.units import ARCSEC
from station.errors import ConfigError
from station.ui.cli.process.output import write_file


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


def _robot(args, name):
    """``(model, joint map)`` of the robot ``name``; a URDF's chain from ``--base``/``--tip``.
    Controller joints from data files go through the map (``jmap.to_model``) before the model
    sees them (docs/robot-file.md, "Joint map")."""
    from station.io.robot.files import load_mapped_robot

    return load_mapped_robot(name, getattr(args, "base_link", None), getattr(args, "tip_link", None))


def _print_json(obj) -> None:
    if isinstance(obj, dict) and "outcome" not in obj:  # a command that printed its object succeeded
        obj = _succeeded(obj)
    print(json.dumps(obj, indent=2, default=lambda o: o.tolist() if isinstance(o, np.ndarray) else str(o)))


# --- analyze --------------------------------------------------------------------------------

#: random poses ``station analyze`` draws: a plan measures tens to hundreds, and beyond this
#: the rank and condition no longer change
MAX_ANALYZE_POSES = 10_000
#: the distances (pairs) an analysis forms at most: a range check before numpy sees the count
MAX_ANALYZE_DISTANCES = 10_000_000


#: the complete minimal model's count beyond 4R + 2P per objective (Everett, Hollerbach): full
#: poses 6 (the set-up and the tool frame), positions 3 (no tool orientation), distances −3 (nor
#: the set-up); a tool point on the last axis takes 2 more (that axis's tilt), e.g. irb2600's 25
COMPLETE_COUNT = {"pose": (6, "poses"), "position": (3, "positions of a point off the last axis"),
                  "distance": (-3, "distances between such points")}


def _check_analyze_args(args) -> None:
    """Refuse counts that would give an empty or meaningless analysis, naming the range."""
    low = 2 if args.objective == "distance" else 1  # a distance needs two points
    if not low <= args.poses <= MAX_ANALYZE_POSES:
        raise ConfigError(f"--poses {args.poses}: the number of poses must be {low} … {MAX_ANALYZE_POSES} "
                          f"for --objective {args.objective} (e.g. --poses 30, the default)")
    if args.objective == "distance" and not 1 <= args.distances <= MAX_ANALYZE_DISTANCES:
        raise ConfigError(f"--distances {args.distances}: the number of distances must be at least 1 and at most "
                          f"{MAX_ANALYZE_DISTANCES} (e.g. --distances 200, the default)")


def cmd_analyze(args) -> int:
    from station.core.identification.identifiability import analyze
    from station.core.kinematics.poses import spread_joints
    from station.core.measurement.distance_pairs import make_pairs
    from station.core.measurement.measurements import synthetic_set
    from station.io.datafile import joints_from_table, read_table

    _check_analyze_args(args)
    model, jmap = _robot(args, args.robot)
    rng = np.random.default_rng(args.seed)
    objective = args.objective
    if args.joints:
        q = jmap.to_model(joints_from_table(read_table(args.joints), model))
    else:
        q = spread_joints(model, args.poses, rng, planar=args.planar)
    pairs = (make_pairs(len(q), "cap", cap=args.distances, seed=args.seed) if objective == "distance" else None)
    data = synthetic_set(model, objective, q, model.nominal, pairs=pairs)
    prefer = _names(args.prefer) or model.prefer
    a = analyze(model, data, prefer=prefer, fix=_names(args.fix), exclude=_names(args.exclude))
    if args.json:
        _print_json({"robot": model.name, "objective": objective, "kind": objective, "poses": len(q), **a.to_dict()})
        return 0
    extra, what = COMPLETE_COUNT[objective]
    print(f"robot {model.name}: {model.n_params} parameters, complete minimal model for {what} "
          f"4R+2P{extra:+d} = {model.minimal_param_count - 6 + extra}")
    print(f"{objective} measurements at {len(q)} poses{' in one plane' if args.planar else ''}"
          f"{f', {len(pairs)} distances' if pairs is not None else ''}")
    print(f"identifiable parameters (rank): {a.rank}"
          + (f" (the chain itself: {a.chain_rank})" if a.lost_to_gimbal_lock else ""))
    if a.gimbal_note():
        print(f"note: {a.gimbal_note()}")
    print(f"condition (scaled columns):     {a.condition:.1f} (chosen set {a.chosen_condition:.1f})")
    print(f"minimal set: {', '.join(a.chosen)}")
    if a.held:
        print(f"held at their values: {', '.join(a.held)}")
    print("left out, and what they merge with:")
    for d in a.dependencies:
        print(f"  {d.describe()}")
    return 0


# --- identify -------------------------------------------------------------------------------

def _is_angle(name: str) -> bool:
    return name.split(".")[1] in ("roll", "pitch", "yaw")


def _param_json(name: str, value: float, sigma: float | None = None) -> dict:
    if _is_angle(name):
        d = {"value_rad": float(value), "value_deg": float(np.degrees(value))}
        if sigma is not None:
            d["sigma_arcsec"] = float(sigma / ARCSEC)
        return d
    d = {"value_mm": float(value)}
    if sigma is not None:
        d["sigma_um"] = float(sigma * 1e3)
    return d


def _measurement_set(args, model, kind, q, measured):
    """The MeasurementSet of the chosen objective from a data file's rows."""
    from station.core.measurement.distance_pairs import distances, make_pairs
    from station.core.measurement.measurements import MeasurementSet

    objective = args.objective or kind
    sp, sa = args.sigma_position * 1e-3, args.sigma_angle * ARCSEC
    if not (np.isfinite(sp) and sp > 0 and np.isfinite(sa) and sa > 0):
        raise ConfigError("--sigma-position and --sigma-angle must be positive numbers (µm, arc seconds)")
    if objective == "pose":
        if kind != "pose":
            raise ConfigError(f"{args.data} holds positions only; use --objective position or distance")
        return objective, MeasurementSet("pose", q, measured, np.array([sp, sp, sp, sa, sa, sa]))
    pos = measured[:, :3, 3] if kind == "pose" else measured
    if objective == "position":
        return objective, MeasurementSet("position", q, pos, np.array([sp, sp, sp]))
    if objective == "distance":
        pairs = make_pairs(len(q), args.pairs, cap=args.max_pairs)
        return objective, MeasurementSet("distance", q, distances(pos, pairs), np.sqrt(2) * sp, pairs,
                                         point_sigma=sp)
    raise ConfigError(f"unknown objective {objective!r}; use pose, position or distance")


def _succeeded(d: dict) -> dict:
    """``d`` with ``outcome`` and ``exit_code`` first, as every ``--json`` object carries them."""
    return {"outcome": "SUCCESS", "exit_code": 0, **d}


def _item_label(res, i: int) -> str:
    """Row number(s) of measurement ``i`` of a result (a distance: its two rows)."""
    if res.kind == "distance":
        return "{}–{}".format(*(int(r) + 1 for r in res.item_rows(i)))
    return str(i + 1)


def identify_report(model, res, data, objective: str, pairs_strategy: str | None) -> dict:
    """Everything ``identify`` says about a fit, as JSON-ready numbers with units in the keys."""
    ident = res.identifiability
    out = {
        "robot": model.name, "objective": objective, "n_measurements": int(res.residuals.shape[0]),
        "units": {"lengths": "mm", "angles": "rad (value_deg beside)", "sigma": "µm / arc seconds",
                  "residuals": "mm (pose rows: mm, mm, mm, rad, rad, rad)"},
        "converged": res.converged, "evaluations": res.iterations,
        "rms_normalized": res.rms_normalized,
        "rms_position_residual_um": res.rms_position_mm() * 1e3,
        # the a-posteriori check (issue 38): s0 and the factor the σ were scaled by, if any
        "variance_factor": res.variance.as_dict() if res.variance is not None else None,
        "parameters": {n: _param_json(n, v, s) for n, v, s in
                       zip(res.chosen, res.estimates, res.uncertainty.sigma)},
        "fitted": len(res.chosen), "model_parameters": model.n_params,
        "complete_minimal_model": model.minimal_param_count,
        "rank_at_data": ident.rank, "rank_of_workspace_design": res.design_rank,
        "left_out": [{"name": d.name, "merges_with": {n: c for n, c in d.merges_with},
                      "held_at": _param_json(d.name, res.params[model.param_index(d.name)])}
                     for d in ident.dependencies],
        "held": list(ident.held),
        "condition": ident.chosen_condition,
        "max_abs_correlation": res.uncertainty.max_abs_correlation(),
        "registration": res.registration.to_dict() if res.registration is not None else None,
        "unit_check": (res.registration.unit_check if res.registration is not None
                       else "distances compared with the nominal model's: consistent"),
        "suspected_outlier_rows": [i + 1 for i in res.outliers],
        "loss": res.loss,
        "down_weighted": [{"rows": [int(r) + 1 for r in res.item_rows(i)], "weight": w} for i, w in res.downweighted],
        "dropped_pairs": [[a + 1, b + 1] for a, b in res.dropped_pairs],
        "outliers": list(res.outliers),
        "notes": list(res.notes),
        "residuals": res.residuals.tolist(),
    }
    if objective == "distance":
        out["pairs"] = {"strategy": pairs_strategy, "count": int(res.residuals.shape[0]),
                        "points": int(data.joints.shape[0])}
    return out


def _tool_unknown(args) -> tuple[bool, list[str]]:
    """Whether identify fits the tool point: ``--tool unknown|file``, else the robot file's
    ``[tool] unknown``; and the note that says the file chose it."""
    from station.io.robot.files import tool_marked_unknown

    tool = getattr(args, "tool", None)
    if tool is not None:
        return tool == "unknown", []
    if not tool_marked_unknown(args.robot):
        return False, []
    return True, [f"{args.robot}: [tool] unknown = true: the tool point is fitted (--tool file holds it)"]


def cmd_identify(args) -> int:
    from station.core.identification.identify import MAX_EVALUATIONS, identify, require_converged
    from station.core.kinematics.model import robot_to_toml
    from station.io.datafile import read_measurement_file
    from station.io.robot.files import joint_map_toml

    model, jmap = _robot(args, args.robot)
    mf = read_measurement_file(args.data, model)
    kind, q, measured = mf.kind, jmap.to_model(mf.joints), mf.measured
    objective, data = _measurement_set(args, model, kind, q, measured)
    tool_unknown, tool_note = _tool_unknown(args)
    start = None
    if tool_unknown and objective == "distance":  # distances have no frame: the tool point from the points
        from station.core.kinematics.tool_frame import fit_marker_offset

        start = np.array(model.nominal)
        start[-6:-3] = fit_marker_offset(model, q, measured[:, :3, 3] if kind == "pose" else measured).offset_mm
    res = identify(model, data, start=start, prefer=_names(args.prefer) or None, fix=_names(args.fix),
                   exclude=_names(args.exclude), tool_unknown=tool_unknown,
                   loss=getattr(args, "loss", "linear"), max_nfev=getattr(args, "max_evaluations", MAX_EVALUATIONS))
    require_converged(res)
    from station.core.identification.plausibility import few_angles_text, joint_angle_counts, require_plausible
    from station.ui.cli.commands_model import identify_terms, output_params, print_terms, terms_toml

    # a converged fit is not yet a robot (issue 36): far from its file's geometry it exits 3, named
    plaus = require_plausible(model, data, res.params, res.chosen, res.uncertainty.sigma)
    terms = identify_terms(args, model, data, res, mf, jmap)  # --model (issue 30); None: the geometric fit alone
    file_notes = [f"{args.data}: {n}" for n in mf.notes] + tool_note
    few = few_angles_text(model, data.joints)
    if few is not None:  # flagged even where the result stays plausible: such a model holds near these angles only
        file_notes.append(f"{few}; the model is fitted where that joint stood and holds there only")
    if args.output:
        write_file(args.output, robot_to_toml(model, output_params(res, terms), angle_unit="rad")
                   + joint_map_toml(jmap, model, angle_unit="rad")
                   + terms_toml(terms, args.robot, model, args.base_link, args.tip_link, data, res))
    if args.json:
        rep = identify_report(model, res, data, objective, args.pairs if objective == "distance" else None)
        rep["output"] = args.output
        rep["joint_map"] = jmap.describe()
        rep["notes"] = file_notes + rep["notes"]
        rep["distinct_joint_values"] = list(joint_angle_counts(model, data.joints))
        rep["plausibility"] = plaus.to_dict()
        if terms is not None:
            rep["error_model"] = terms.to_dict()
        _print_json(_succeeded(rep))
        return 0
    ident = res.identifiability
    print(f"identified {len(res.chosen)} of {model.n_params} parameters of {model.name} from {res.residuals.shape[0]} "
          f"{objective} measurements{f' ({args.pairs} pairs of {len(q)} points)' if objective == 'distance' else ''} "
          f"({res.iterations} evaluations, {'converged' if res.converged else 'NOT converged: ' + res.message})")
    if res.registration is not None:
        r = res.registration.to_dict()
        print(f"registration: tracker frame turned {np.degrees(r['rotation_angle_rad']):.1f}°, "
              f"{r['translation_mm'] / 1000:.3f} m from the robot base; nominal model misses by "
              f"{r['rms_residual_mm']:.3f} mm RMS after alignment (limit {r['limit_mm']:.2f} mm)")
        print(f"unit check: {res.registration.unit_check}")
    print(f"rank at the data {ident.rank} (workspace-wide design {res.design_rank}); condition of the "
          f"fitted set {ident.chosen_condition:.1f}; largest |correlation| {res.uncertainty.max_abs_correlation():.2f}")
    print(f"normalised RMS residual {res.rms_normalized:.3f}; RMS position residual "
          f"{res.rms_position_mm() * 1e3:.1f} µm")
    print("distinct values per joint (modulo a turn): "
          + ", ".join(f"J{j + 1} {n}" for j, n in enumerate(joint_angle_counts(model, data.joints)))
          + f"; the identified robot stands {plaus.workspace_mm:.3g} mm RMS from its file's geometry over the joint "
          f"ranges (same tool, best rigid placement)")
    print(f"{'parameter':12s} {'nominal':>16s} {'identified':>16s} {'σ':>12s}")
    for n, i, v, s in zip(res.chosen, res.chosen_index, res.estimates, res.uncertainty.sigma):
        print(f"{n:12s} {_fmt_param(n, model.nominal[i]):>16s} {_fmt_param(n, v):>16s} {_fmt_sigma(n, s):>12s}")
    if ident.dependencies:
        print(f"left out ({len(ident.dependencies)}), held at their values; their effect merges into:")
        for d in ident.dependencies:
            print(f"  {d.describe()}")
    for note in file_notes + list(res.notes):
        print(f"note: {note}")
    if res.downweighted:
        print("down-weighted by the robust loss (" + ("pair of rows" if objective == "distance" else "row")
              + ": weight): " + ", ".join(f"{_item_label(res, i)}: {w:.2f}" for i, w in res.downweighted[:20])
              + (f" … ({len(res.downweighted)} in all)" if len(res.downweighted) > 20 else ""))
    if not jmap.is_identity:
        print(f"joint map applied to the file's joints (rad, mm): {'; '.join(jmap.describe())}")
    if res.outliers:
        print(f"suspected outliers (rows): {', '.join(str(i + 1) for i in res.outliers)}")
    else:
        print("suspected outliers: none")
    if terms is not None:
        print_terms(terms)
    if args.output:
        print(f"identified model written to {args.output}")
    return 0


# --- validate -------------------------------------------------------------------------------

def _errors(model, q, kind, measured, setup_pose=None, delta_q=None):
    """Per-row position errors [mm] (n,) and orientation errors [rad] (n,) or None; ``delta_q``: the
    model file's error terms, ``q ↦ Δq(q)`` (the joints stand at q + Δq; issue 30)."""
    from station.core.kinematics.forward import forward
    from station.core.kinematics.transforms import pose_error

    params = None
    if setup_pose is not None:
        params = np.array(model.nominal)
        params[:6] = setup_pose
    T = forward(model, q if delta_q is None else q + delta_q(q), params)
    if kind == "pose":
        e = pose_error(T, measured)
        return e[:, :3], e[:, 3:]
    return T[:, :3, 3] - measured, None


def _summary(e_pos, e_ang) -> dict:
    d = np.linalg.norm(e_pos, axis=1)
    out = {"rms_position_um": float(np.sqrt(np.mean(d**2)) * 1e3), "max_position_um": float(d.max() * 1e3),
           "mean_position_um": float(d.mean() * 1e3)}
    if e_ang is not None:
        a = np.linalg.norm(e_ang, axis=1)
        out.update({"rms_orientation_arcsec": float(np.sqrt(np.mean(a**2)) / ARCSEC),
                    "max_orientation_arcsec": float(a.max() / ARCSEC)})
    return out


def _iso_repeats(q, e_pos, measured_pos) -> list[dict]:
    """ISO 9283 AP and RP for poses measured more than once (rows with equal joints)."""
    from station.core.accuracy.iso9283 import iso9283_pose

    _, inv, counts = np.unique(np.round(q, 9), axis=0, return_inverse=True, return_counts=True)
    inv = np.asarray(inv).reshape(-1)
    out = []
    for g in np.nonzero(counts >= 2)[0]:
        rows = np.nonzero(inv == g)[0]
        attained = measured_pos[rows]
        commanded = (measured_pos[rows] + e_pos[rows])[0]  # where the model puts the pose
        r = iso9283_pose(commanded, attained)
        out.append({"rows": [int(i) + 1 for i in rows], "AP_um": float(r.AP * 1e3), "RP_um": float(r.RP * 1e3)})
    return out


#: a model's own set-up is taken as this data's frame unless it misses them by more than this
#: factor times (plus 1 mm) what the best rigid alignment leaves: then the set-up is not known
SETUP_UNKNOWN_FACTOR = 10.0
#: orientation errors beyond this [rad] (1°) are no calibration error but an orientation the
#: model's fit did not determine (fitted on positions or distances)
ORIENTATION_UNKNOWN_RAD = np.radians(1.0)


#: poses over the model's joint ranges on which validate places the nominal robot onto the model
#: (without --calibration): enough that the rigid fit no longer depends on the draw
NOMINAL_PLACEMENT_POSES = 200


def _calibration_frame(args, model):
    """``(joints, positions)`` of ``--calibration`` for ``model`` (None without it)."""
    from station.io.datafile import read_measurement_file

    if not getattr(args, "calibration", None):
        return None
    cf = read_measurement_file(args.calibration, model)
    return cf.joints, (cf.measured[:, :3, 3] if cf.kind == "pose" else cf.measured)


def _check_own_setup(model, q, pos, e_pos, kind: str) -> None:
    """Refuse a model whose set-up does not place it in the data's frame (see SETUP_UNKNOWN_FACTOR)."""
    from station.core.identification.registration import rigid_residual_mm

    own = float(np.sqrt(np.mean(np.sum(e_pos**2, axis=1))))
    rigid = rigid_residual_mm(model, q, pos)
    if own > SETUP_UNKNOWN_FACTOR * rigid + 1.0:
        raise ConfigError(
            f"the model's set-up is unknown for these {kind} data: with the set-up it carries it misses them by "
            f"{own:.4g} mm RMS, after a rigid alignment by {rigid:.3g} mm. A model fitted on distances carries no "
            f"set-up (distances do not fix it), nor does one fitted in another instrument frame. Give "
            f"--calibration CALIB.csv, the data it was fitted on (measured in this frame), to register it there")


def cmd_validate(args) -> int:
    from station.core.identification.registration import register
    from station.io.datafile import read_measurement_file

    model, jmap = _robot(args, args.model)
    mf = read_measurement_file(args.data, model)
    kind, q_controller, measured = mf.kind, mf.joints, mf.measured
    q = jmap.to_model(q_controller)
    pos = measured[:, :3, 3] if kind == "pose" else measured
    sigma = args.sigma_position * 1e-3
    if not (np.isfinite(sigma) and sigma > 0):
        raise ConfigError("--sigma-position must be a positive number of µm")
    calib = _calibration_frame(args, model)
    notes = [f"{args.data}: {n}" for n in mf.notes]
    from station.ui.cli.commands_model import gear_ratios_of, gravity_of, joint_delta_of, stored_terms

    terms = stored_terms(args.model)  # [error_terms] (issue 30): the model's joints stand at q + Δq(q)
    dq = None
    if terms is not None and terms.names:
        dq = joint_delta_of(model, terms, gravity_of(args.model, model), gear_ratios_of(args.model, model))
        notes.append(f"error terms of the model applied: {', '.join(terms.names)} (drift and backlash at zero)")
    if calib is not None:  # the model registered on its calibration data, never on the held-out rows
        # with the model it is scored with: its joints at q + Δq(q) there too (issue 36: registered
        # without the terms, an auto model missed the FANUC's held-out poses by 2.1 mm, not 0.53 mm)
        q_cal = jmap.to_model(calib[0])
        reg_m = register(model, q_cal if dq is None else q_cal + dq(q_cal), calib[1], sigma, params=model.nominal)
        e_pos, e_ang = _errors(model, q, kind, measured, setup_pose=reg_m.setup_pose, delta_q=dq)
        setup = f"registered on {args.calibration}"
    else:
        e_pos, e_ang = _errors(model, q, kind, measured, delta_q=dq)
        _check_own_setup(model, q, pos, e_pos, kind)
        setup = "the model's own (identified)"
    if e_ang is not None and np.sqrt(np.mean(np.sum(e_ang**2, axis=1))) > ORIENTATION_UNKNOWN_RAD:
        notes.append(f"orientation not compared: the model misses it by "
                     f"{np.degrees(np.sqrt(np.mean(np.sum(e_ang**2, axis=1)))):.1f}° RMS, which a model fitted on "
                     f"positions or distances does not determine; position errors only")
        e_ang = None
    result = {"model": model.name, "data": str(args.data), "kind": kind, "rows": len(q),
              "units": {"position": "µm", "orientation": "arc seconds"}, "setup": setup,
              "model_errors": _summary(e_pos, e_ang),
              "per_row": [{"row": i + 1, "position_um": float(np.linalg.norm(e_pos[i]) * 1e3),
                           **({"orientation_arcsec": float(np.linalg.norm(e_ang[i]) / ARCSEC)} if e_ang is not None else {})}
                          for i in range(len(q))],
              "iso9283_repeats": _iso_repeats(q, e_pos, pos), "notes": notes}
    _compare_nominal(args, model, jmap, q_controller, kind, measured, calib, sigma, setup, e_ang is not None, result)
    result = _succeeded(result)
    if args.json:
        _print_json(result)
        return 0
    _print_validation(result, model.name, args.data, kind, e_ang is not None, setup, notes)
    return 0


def _compare_nominal(args, model, jmap, q_controller, kind: str, measured, calib, sigma: float, setup: str,
                     with_orientation: bool, result: dict) -> None:
    """``result`` gains the nominal robot's errors on the same rows, registered the way the model
    was (on the calibration data, else on the model's own points), and the improvement."""
    from station.core.identification.registration import register

    nominal_name = args.robot or model.name
    nominal = None
    try:  # the nominal robot file has its own joint map: the data's joints go through it
        nominal, nominal_map = _robot(args if str(nominal_name).endswith(".urdf") else None, nominal_name)
    except ConfigError:
        result["nominal"] = f"no nominal robot {nominal_name!r}; give --robot"
    if nominal is not None:
        if nominal.n_joints != model.n_joints:
            raise ConfigError(f"--robot {nominal_name}: {nominal.n_joints} joints, the model has {model.n_joints}")
        q_nominal = nominal_map.to_model(q_controller)
        if calib is not None:  # registered the same way as the model: on the calibration data
            nominal_setup = register(nominal, nominal_map.to_model(calib[0]), calib[1], sigma).setup_pose
            nominal_how = setup
        else:
            # Onto the model's own points over its workspace, as a registration on calibration data
            # spread there would place it. Not the model's R: a model identified before issue 36, or
            # with `fix` on the set-up, splits the set-up between R and what merges with it (A1.x,
            # A1.y, A2.yaw), and R alone can miss by metres; not the held-out rows, nor these
            # joints: a fit to them would hide part of the nominal's error.
            from station.core.identification.registration import rigid_setup
            from station.core.kinematics.forward import forward
            from station.core.kinematics.poses import spread_joints

            q_spread = spread_joints(model, NOMINAL_PLACEMENT_POSES, np.random.default_rng(0))
            nominal_setup = rigid_setup(nominal, nominal_map.to_model(jmap.to_controller(q_spread)),
                                        forward(model, q_spread)[:, :3, 3])
            nominal_how = (f"registered on the model's own points at {NOMINAL_PLACEMENT_POSES} poses spread over "
                           f"its joint ranges (no measured value used)")
        n_pos, n_ang = _errors(nominal, q_nominal, kind, measured, setup_pose=nominal_setup)
        result["nominal"] = nominal.name
        result["nominal_errors"] = {**_summary(n_pos, n_ang if with_orientation else None),
                                    "registered": True, "setup": nominal_how}
        result["improvement"] = result["nominal_errors"]["rms_position_um"] / max(result["model_errors"]["rms_position_um"], 1e-12)


def _print_validation(result: dict, model_name: str, data, kind: str, with_orientation: bool, setup: str,
                      notes: list[str]) -> None:
    """``station validate``'s table for people: the model's and the nominal robot's errors, the
    ISO 9283 repeats, the worst rows, the set-ups and the notes."""
    m = result["model_errors"]
    print(f"{model_name} on {result['rows']} {kind} measurements of {data} (not used for its fit):")
    print(f"  {'':28s} {'RMS':>10s} {'max':>10s}")
    print(f"  {'model, position':28s} {m['rms_position_um']:8.1f}µm {m['max_position_um']:8.1f}µm")
    if with_orientation:
        print(f"  {'model, orientation':28s} {m['rms_orientation_arcsec']:9.1f}″ {m['max_orientation_arcsec']:9.1f}″")
    if "nominal_errors" in result:
        n = result["nominal_errors"]
        print(f"  {'nominal (registered), pos.':28s} {n['rms_position_um']:8.1f}µm {n['max_position_um']:8.1f}µm")
        if with_orientation:
            print(f"  {'nominal, orientation':28s} {n['rms_orientation_arcsec']:9.1f}″ {n['max_orientation_arcsec']:9.1f}″")
        print(f"  improvement (RMS position): {result['improvement']:.1f}×")
    else:
        print(f"  nominal: {result['nominal']}")
    for r in result["iso9283_repeats"]:
        print(f"  ISO 9283 pose at rows {r['rows']}: AP {r['AP_um']:.1f} µm, RP {r['RP_um']:.1f} µm")
    worst = sorted(result["per_row"], key=lambda r: -r["position_um"])[:5]
    print("  worst rows: " + ", ".join(f"{r['row']}: {r['position_um']:.1f} µm" for r in worst))
    print(f"  set-up: {setup}")
    if "nominal_errors" in result and result["nominal_errors"]["setup"] != setup:
        print(f"  nominal set-up: {result['nominal_errors']['setup']}")
    for note in notes:
        print(f"note: {note}")


# --- export-model ---------------------------------------------------------------------------

def cmd_export_model(args) -> int:
    from station.io.export.model_files import export_model
    from station.io.robot.files import joint_map_toml
    from station.io.robot.terms import gears_toml, gravity_toml
    from station.ui.cli.commands_model import gear_ratios_of, gravity_of, lost_in_format, stored_terms

    if getattr(args, "robot", None) and not str(args.model).endswith(".urdf"):  # the links are --robot's URDF's
        from station.io.robot.files import load_mapped_robot

        model, jmap = load_mapped_robot(args.model)
    else:
        model, jmap = _robot(args, args.model)
    terms = stored_terms(args.model)
    gravity = gravity_of(args.model, model)
    exported = model  # a format without the terms gets the geometric fit of the same data (issue 30)
    if args.format != "toml" and terms is not None and terms.geometric_params is not None:
        exported = model.with_params(np.asarray(terms.geometric_params, dtype=float))
    ratios = gear_ratios_of(args.model, model)
    lost = lost_in_format(model, terms, args.format.removesuffix("-new"), gravity=gravity,
                          ratios=ratios)  # only TOML holds the terms
    if args.format in ("urdf", "ur-calibration"):  # into the robot's own URDF, UR's YAML (issue 41 §2)
        from station.ui.cli.commands_export import export_calibrated

        return export_calibrated(args, exported, jmap, lost)
    args.format = "urdf" if args.format == "urdf-new" else args.format
    res = export_model(exported, args.format, setup=not args.base)
    notes = list(res.notes)
    if lost:
        notes.append(lost)
    text = res.text
    if args.format == "toml":
        text += joint_map_toml(jmap, model, angle_unit="rad")
        if terms is not None and terms.names:
            from station.io.robot.terms import error_terms_toml

            text += error_terms_toml(terms.families, terms.names, terms.values, terms.sigma, terms.units,
                                     terms.effect_on_fit_um, terms.geometric_params)
        text += gravity_toml(gravity) + gears_toml(ratios)
    elif not jmap.is_identity:
        notes.append(f"the joint map ({'; '.join(jmap.describe())}) is not written in {args.format.upper()}: the "
                     f"file's joints are the model's; export --format toml to keep it")
    write_file(args.output, text)
    if args.json:
        _print_json({"model": model.name, "format": args.format, "output": args.output,
                     "frame": "base" if args.base else "measurement", "exact": res.exact,
                     "max_position_difference_um": res.max_position_um,
                     "max_orientation_difference_arcsec": res.max_angle_arcsec, "notes": notes})
        return 0
    print(f"{model.name} written to {args.output} as {args.format.upper()}"
          f" ({'robot base frame, set-up R left out' if args.base else 'with the set-up R'})")
    print(f"re-imported: forward kinematics differ by at most {res.max_position_um:.3g} µm and "
          f"{res.max_angle_arcsec:.3g}″ over the workspace ({'exact' if res.exact else 'NOT exact'})")
    for n in notes:
        print(f"note: {n}")
    return 0


# --- predict --------------------------------------------------------------------------------

def cmd_predict(args) -> int:
    from station.core.kinematics.transforms import matrix_to_pose
    from station.io.datafile import joints_from_table, read_table
    from station.ui.cli.commands_model import forward_with_terms

    model, jmap = _robot(args, args.model)
    q = jmap.to_model(joints_from_table(read_table(args.joints), model))
    T, term_notes, _ = forward_with_terms(model, args.model, q, setup=not args.base)  # [error_terms] (issue 30)
    poses = matrix_to_pose(T)
    if args.json:
        _print_json(_succeeded({"robot": model.name, "frame": "base" if args.base else "measurement",
                                "poses_mm_rad": poses.tolist(), "notes": term_notes}))
        return 0
    for n in term_notes:
        print(f"# {n}")
    print("x [mm],y [mm],z [mm],roll [deg],pitch [deg],yaw [deg]")
    for p in poses:
        print(",".join([f"{v:.6f}" for v in p[:3]] + [f"{np.degrees(v):.8f}" for v in p[3:]]))
    return 0
