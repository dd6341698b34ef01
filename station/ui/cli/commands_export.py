"""``station export-model --format urdf|ur-calibration`` (issue 41 §2): the identified model into
the robot's own URDF, and as the kinematics YAML of UR's ROS 2 driver.

What a format cannot hold (the set-up R, the tool K, error terms beyond geometry, a joint map) is
named in the file's header and on stderr, never dropped silently (docs/exports.md).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from station.core.kinematics.transforms import matrix_to_pose, pose_to_matrix
from station.core.units import ARCSEC, UM
from station.errors import ConfigError
from station.ui.cli.process.output import write_file


def _urdf_source(args) -> Path:
    """The URDF the robot comes from: MODEL itself, or ``--robot`` for an identified model."""
    for s in (getattr(args, "robot", None), args.model):
        if s is not None and str(s).endswith(".urdf"):
            return Path(s)
    raise ConfigError(f"robot {args.model!r} does not come from a URDF: --format urdf writes the calibrated joint "
                      f"origins into the robot's own URDF. Give the URDF it was identified with as --robot FILE.urdf "
                      f"(with --base-link/--tip-link as in identify), or use --format urdf-new for a new URDF of the "
                      f"model, one joint per transform")


def _not_held(model, p: np.ndarray, args, fmt: str) -> list[str]:
    """The set-up R, when the model carries one and --base was not given."""
    if args.base or not np.abs(p[:6]).max() > 0.0:
        return []
    pose = p[:6]
    return [f"the set-up R (the robot base in the measurement frame: x {pose[0]:.4f} mm, y {pose[1]:.4f} mm, "
            f"z {pose[2]:.4f} mm, roll {np.degrees(pose[3]):.6f}°, pitch {np.degrees(pose[4]):.6f}°, yaw "
            f"{np.degrees(pose[5]):.6f}°): the {fmt} starts at the robot's base; the file describes the robot in "
            f"its base frame"]


def export_calibrated(args, model, jmap, terms_note: str | None) -> int:
    """Write ``model`` (identified, geometric) as ``args.format`` into ``args.output``."""
    if not jmap.is_identity:
        raise ConfigError(f"the model maps the controller's joints ({'; '.join(jmap.describe())}); "
                          f"{args.format} counts joints as the controller does and has no place for a map: "
                          f"export --format toml to keep it")
    p = np.array(model.nominal, dtype=float)
    notes = _not_held(model, p, args, "URDF" if args.format == "urdf" else "kinematics file")
    if terms_note:
        notes.append(terms_note)
    if args.format == "urdf":
        text, extra, dp, da = _urdf(args, model, p, notes)
    else:
        text, extra, dp, da = _ur(model, p, notes)
    write_file(args.output, text)
    for n in extra:
        print(f"station: not held: {n}", file=sys.stderr)
    if args.json:
        print(json.dumps({"outcome": "success", "exit_code": 0, "model": model.name, "format": args.format,
                          "output": args.output, "frame": "base", "max_position_difference_um": dp / UM,
                          "max_orientation_difference_arcsec": da / ARCSEC, "not_held": list(extra)}, indent=2))
        return 0
    print(f"{model.name} written to {args.output} ({args.format}, robot base frame)")
    print(f"re-imported: forward kinematics differ by at most {dp / UM:.3g} µm and {da / ARCSEC:.3g}″ "
          f"over the workspace")
    return 0


def _urdf(args, model, p, notes):
    from station.io.export.model_files import fk_difference
    from station.io.export.urdf_calibrated import write_calibrated_urdf
    from station.io.robot.files import load_robot

    path = _urdf_source(args)
    nominal = load_robot(path, args.base_link, args.tip_link)
    if [t.name for t in nominal.transforms] != [t.name for t in model.transforms] or \
            nominal.joint_types != model.joint_types:
        raise ConfigError(f"{path}: its chain ({', '.join(nominal.joint_types)}) is not the model's "
                          f"({', '.join(model.joint_types)}): give the URDF, --base-link and --tip-link the model "
                          f"was identified with")
    q = p.copy()
    q[:6] = 0.0
    edit = write_calibrated_urdf(path, nominal, q, args.base_link, args.tip_link, tuple(notes))
    text = edit.data.decode("utf-8")
    import tempfile

    with tempfile.TemporaryDirectory() as d:  # reloaded the station's way; the tests use another reader
        back = Path(d) / path.name
        back.write_bytes(edit.data)
        again = load_robot(back, args.base_link, args.tip_link)
    dp, da = fk_difference(model.with_params(q), q, again, setup=False)
    return text, edit.notes, dp, da


def _ur(model, p, notes):
    from station.io.export.model_files import fk_difference
    from station.io.export.ur_calibration import frames_params, reload_frames, ur_calibration_yaml

    K = matrix_to_pose(pose_to_matrix(p[-6:]))
    if np.abs(K).max() > 0.0:
        notes.append(f"the tool K (x {K[0]:.4f} mm, y {K[1]:.4f} mm, z {K[2]:.4f} mm, roll "
                     f"{np.degrees(K[3]):.6f}°, pitch {np.degrees(K[4]):.6f}°, yaw {np.degrees(K[5]):.6f}° from "
                     f"the wrist_3 frame): the description fixes flange and tool0 on wrist_3_link; set the tool "
                     f"as the controller's TCP")
    res = ur_calibration_yaml(model, p, tuple(notes))
    bare = p.copy()
    bare[:6] = bare[-6:] = 0.0  # what the file holds: the robot base to the wrist_3 frame
    wrist = model.with_params(bare)
    back = wrist.with_params(frames_params(wrist, reload_frames(res.text)))
    dp, da = fk_difference(wrist, bare, back, setup=False)
    return res.text, res.notes, dp, da
