"""CSV export of a run's measurements (docs/run-database.md, "Export"): one row per
measurement, units in the header (:func:`export_csv`, the run's full record), or the
identification measurements as a pose file ``station identify`` reads (:func:`export_pose_file`,
docs/data-files.md). It reads the run database; the database knows nothing of it."""

from __future__ import annotations

import csv
import tomllib
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from station.cell.records.run_records import RunDatabaseError, _num
from station.cell.records.rundb import RunDB
from station.core.kinematics.transforms import matrix_to_pose

#: a cell that starts with one of these is read as a formula by spreadsheet programs
_FORMULA_START = ("=", "+", "-", "@", "\t", "\r")


def csv_text(value: object) -> str:
    """A text cell safe to open in a spreadsheet: one that begins like a formula (``=``, ``+``,
    ``-``, ``@``, tab, carriage return) gets a leading single quote, as the OWASP guidance on
    CSV injection says, so ``=HYPERLINK(…)`` stays text. Numbers are written by ``_num`` and
    never pass through here."""
    s = "" if value is None else str(value)
    return "'" + s if s.startswith(_FORMULA_START) else s


def export_csv(db: RunDB, run_id: int, path: str | Path,
               joint_units: Sequence[str] | None = None) -> Path:
    """Write one CSV row per measurement (docs/run-database.md, "Export").

    Joints and orientations in degrees, as everywhere else the station shows them (issue 29):
    ``q1 [deg]`` for a revolute joint, ``[mm]`` for a prismatic one, ``roll [deg]`` … ``yaw [deg]``.
    ``joint_units`` ('rad' or 'deg' for a revolute joint, 'mm' for a prismatic one) says which
    is which; by default the run's robot says (its stored configuration, else the joint types
    in the snapshot: ``joint = "revolute" | "prismatic"`` entries); joints of unknown type are
    written as stored, labelled ``rad|mm``.
    """
    run = db.run(run_id)
    ms = db.measurements(run_id)
    n_q = max((len(m.joints_commanded) for m in ms), default=0)
    n_q = max([n_q] + [len(m.joints_read) for m in ms if m.joints_read is not None])
    n_p = max((len(m.readings_mm) for m in ms if m.readings_mm is not None), default=0)
    given = list(joint_units) if joint_units is not None else _run_joint_units(db, run_id, run.config_toml)
    units = [("deg" if u in ("rad", "deg") else u) for u in (given + ["rad|mm"] * n_q)[:n_q]]
    header = (["step", "kind", "point_id", "label", "t_utc"]
              + [f"q{i + 1} [{u}]" for i, u in enumerate(units)]
              + [f"q{i + 1}_cmd [{u}]" for i, u in enumerate(units)]
              + ["x [mm]", "y [mm]", "z [mm]", "roll [deg]", "pitch [deg]", "yaw [deg]",
                 "residual [um]"]
              + [f"p{i + 1} [mm]" for i in range(n_p)]
              + ["status", "ok", "message"])

    def cells(a: np.ndarray | None, n: int, deg: Sequence[bool] = ()) -> list[str]:
        vals = [] if a is None else [_num(float(np.degrees(v)) if i < len(deg) and deg[i] else v)
                                     for i, v in enumerate(a)]
        return (vals + [""] * n)[:n]

    q_deg = [u == "deg" for u in units]
    pose_deg = [False, False, False, True, True, True]

    out = Path(path)
    try:
        with open(out, "w", newline="", encoding="utf-8") as f:
            w = csv.writer(f)
            w.writerow(header)
            for m in ms:
                pose = None if m.pose is None else matrix_to_pose(m.pose)
                status = "" if m.channel_status is None else ";".join(
                    str(s) for s in m.channel_status)
                w.writerow([m.step_index, csv_text(m.kind), csv_text(m.point_id), csv_text(m.label),
                            csv_text(m.t_utc)]
                           + cells(m.joints_read, n_q, q_deg) + cells(m.joints_commanded, n_q, q_deg)
                           + cells(pose, 6, pose_deg) + [_num(m.pose_residual_um)]
                           + cells(m.readings_mm, n_p)
                           + [csv_text(status), int(m.ok), csv_text(m.message)])
    except OSError as e:
        raise RunDatabaseError(f"{out}: cannot write the CSV export ({e.strerror or e}); free space on its disk, "
                               f"check the folder and its permissions, or choose another path") from e
    return out


def _run_joint_units(db: RunDB, run_id: int, config_toml: str) -> list[str]:
    """'rad'/'mm' per joint of the run's robot: its stored configuration's, else the snapshot's
    inline joint types (:func:`_joint_units`); [] when neither says."""
    try:
        from station.cell.records.reading.stored_config import stored_config

        return ["rad" if k == "revolute" else "mm" for k in stored_config(db, run_id).model.joint_types]
    except Exception:  # noqa: BLE001 - a snapshot this version cannot load: the inline types, else unknown
        return _joint_units(config_toml)


def _joint_units(config_toml: str) -> list[str]:
    """'rad'/'mm' per joint from ``joint = "revolute"|"prismatic"`` tables in the config."""
    try:
        cfg = tomllib.loads(config_toml)
    except tomllib.TOMLDecodeError:
        return []
    found: list[list[str]] = []

    def walk(obj: Any) -> None:
        if isinstance(obj, dict):
            for v in obj.values():
                walk(v)
        elif isinstance(obj, list):
            types = [t.get("joint") for t in obj if isinstance(t, dict)]
            joints = [t for t in types if t in ("revolute", "prismatic")]
            if joints:
                found.append(["rad" if t == "revolute" else "mm" for t in joints])
            for v in obj:
                walk(v)

    walk(cfg)
    return found[0] if len(found) == 1 else []


def export_pose_file(db: RunDB, run_id: int, path: str | Path) -> tuple[Path, int, str]:
    """The run's valid identification measurements as a pose file (docs/data-files.md): the
    joints read, ``q1 [deg]`` or ``[mm]`` per joint, and the measured head frame in the body
    frame (what the run identified from: the touched point's CMM pose times the inverse of the
    measured point-in-head pose), ``x [mm] … yaw [deg]``. ``station identify PATH --robot ROBOT``
    reads it as it is. Returns the path, the rows written and the robot (its file or name)."""
    from station.cell.records.reading.stored_config import stored_config
    from station.core.kinematics.transforms import invert

    cfg = stored_config(db, run_id)
    index = {pid: i for i, pid in enumerate(cfg.point_ids)}
    kinds = cfg.model.joint_types
    header = ([f"q{i + 1} [{'deg' if k == 'revolute' else 'mm'}]" for i, k in enumerate(kinds)]
              + ["x [mm]", "y [mm]", "z [mm]", "roll [deg]", "pitch [deg]", "yaw [deg]"])
    rows = []
    for m in db.measurements(run_id):
        if (m.kind != "identification" or not m.ok or m.pose is None or m.joints_read is None
                or m.point_id not in index or len(m.joints_read) != len(kinds)):
            continue
        head = matrix_to_pose(cfg.body_points[index[m.point_id]] @ invert(m.pose))
        q = [np.degrees(v) if k == "revolute" else v for v, k in zip(m.joints_read, kinds)]
        vals = [*q, *head[:3], *np.degrees(head[3:])]
        if not np.all(np.isfinite(vals)):
            continue
        rows.append([_num(v) for v in vals])
    if len(rows) < 2:
        raise RunDatabaseError(f"run {run_id} has {len(rows)} valid identification measurements; a pose file "
                               f"for 'station identify' needs at least two")
    out = Path(path)
    try:
        with open(out, "w", newline="", encoding="utf-8") as f:
            f.write(f"# run {run_id} of {db.path}: cell {cfg.name}, robot {cfg.model.name}; valid identification "
                    f"measurements, head frame in the body frame\n")
            w = csv.writer(f)
            w.writerow(header)
            w.writerows(rows)
    except OSError as e:
        raise RunDatabaseError(f"{out}: cannot write the pose file ({e.strerror or e}); free space on its disk, "
                               f"check the folder and its permissions, or choose another path") from e
    return out, len(rows), _robot_argument(cfg)


def _robot_argument(cfg: Any) -> str:
    """What to give ``station identify --robot``: the configured robot file (absolute, resolved
    beside the configuration as the run did), else the built-in robot's name."""
    try:
        model = tomllib.loads(cfg.source_text).get("robot", {}).get("model")
    except tomllib.TOMLDecodeError:
        model = None
    if not isinstance(model, str) or not model:
        return str(cfg.model.name)
    path = Path(model)
    if not path.is_absolute() and cfg.source and not cfg.source.startswith("<"):
        path = Path(cfg.source).parent / model
    try:
        return str(path.resolve()) if path.is_file() else model
    except (OSError, ValueError):
        return model
