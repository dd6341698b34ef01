"""``station export --tool NAME``: a tool's correction of a stored run as a file for the controller
(``[[tool]]``, :mod:`station.cell.correction.robot_tools`; ``docs/correction.md`` "Tools after the head").
A SCARA's table is rebuilt from the run's configuration snapshot and model and checked against the
CRC-32 the run stored; an articulated arm's compensated targets are the run's own."""

from __future__ import annotations

from typing import Any

import numpy as np

from drivers.controller_map import MAX_TABLE_VALUES
from station.cell.correction.design import head_in_flange
from station.cell.correction.robot_tools import find_tool, result_key, tool_grid
from station.cell.records.reading.stored_config import stored_config
from station.cell.records.reading.stored_error_model import stored_error_model
from station.cell.records.rundb import RunDB
from station.core.kinematics.tool_frame import derive_tool
from station.core.table.build import build_correction_table
from station.core.table.values import CorrectionTableData
from station.errors import ConfigError, Outcome, StationError

__all__ = ["EXPORT_FORMAT", "table_to_json", "table_from_json", "ToolTableBeyondBound", "tool_export"]

#: the format tag of an exported tool correction
EXPORT_FORMAT = "station-tool-correction/1"
_AXIS_NAMES = ("x_mm", "y_mm", "z_mm", "yaw_rad")


def table_to_json(data: CorrectionTableData) -> dict[str, Any]:
    """A correction table as JSON types: its axes (x, y, z [mm], yaw [rad]) and the float32
    values ``(n_configs, nx, ny, nz, nyaw, n_joints)`` [rad | mm] written exactly (read back by
    :func:`table_from_json` they give the same CRC-32)."""
    return {"axes": [{"name": _AXIS_NAMES[k] if k < len(_AXIS_NAMES) else f"axis{k}", "start": a.start,
                      "step": a.step, "count": a.count, "periodic": a.periodic} for k, a in enumerate(data.axes)],
            "shape": list(data.values.shape), "crc32": f"{data.crc32():08x}",
            "values": [float(v) for v in data.values.ravel()]}


def table_from_json(obj: dict[str, Any]) -> CorrectionTableData:
    """The table of :func:`table_to_json` (its CRC-32 checked)."""
    from station.core.table.values import TableAxis

    axes = tuple(TableAxis(float(a["start"]), float(a["step"]), int(a["count"]), bool(a["periodic"]))
                 for a in obj["axes"])
    data = CorrectionTableData(axes, np.asarray(obj["values"], dtype=np.float32).reshape(obj["shape"]))
    if f"{data.crc32():08x}" != obj["crc32"]:
        raise ValueError(f"table CRC-32 {data.crc32():08x} differs from the stated {obj['crc32']}")
    return data


class ToolTableBeyondBound(StationError):
    """``station export --tool``: the tool's table interpolates beyond its
    ``correction.max_interpolation_um``; nothing was written (``--force`` writes it with the
    warning inside). Exit 9, as a table the controller must not get."""

    outcome = Outcome.UPLOAD_FAILED


def tool_export(db: RunDB, run_id: int, name: str, force: bool = False) -> dict[str, Any]:
    """The tool's correction of run ``run_id`` as JSON types: for a SCARA its table, rebuilt from
    the run's configuration snapshot and identification — a run that kept error terms: its stored
    error model, the geometry fitted with the terms and their joint error δ(q), as the run built
    it — and checked against the CRC-32 the run stored; for other robots the compensated targets
    the run stored (with the terms where it kept them). :class:`ConfigError` when the
    run has no such tool or no identification; :class:`ToolTableBeyondBound` when the table's
    interpolation bound exceeds the tool's ``max_interpolation_um`` and ``force`` is not given
    (with ``force`` the export carries that ``warning``)."""
    stored = db.load_result(run_id, result_key(name), default=None)
    ident = db.load_result(run_id, "identification", default=None)
    cfg = stored_config(db, run_id)
    tool = find_tool(cfg, name)
    if stored is None or ident is None:
        raise ConfigError(f"run {run_id} has no correction for tool {name!r} (it did not reach the correction "
                          f"step, or ran before tools were configured); run 'station calibrate' with the tool "
                          f"configured")
    if "error" in stored:
        raise ConfigError(f"run {run_id}: no correction was built for tool {name!r}: {stored['error']}")
    tcp = [float(v) for v in tool.tcp[:3]] + [float(np.degrees(v)) for v in tool.tcp[3:]]
    em = stored_error_model(cfg, db.load_result(run_id, "error_model", default=None))  # the terms kept, if any
    out: dict[str, Any] = {"format": EXPORT_FORMAT, "run_id": run_id, "tool": name, "tcp_mm_deg": tcp,
                           "robot": cfg.model.name, "joint_types": list(cfg.model.joint_types),
                           "joint_units": ["rad" if k == "revolute" else "mm" for k in cfg.model.joint_types],
                           "tool_params_nominal": stored.get("tool_params_nominal"),
                           "tool_params_identified": stored.get("tool_params_identified"),
                           "units": "lengths mm, angles rad; the controller's nominal model takes tool_params_nominal's "
                                    "last six values (x, y, z, roll, pitch, yaw) as its tool",
                           # the error terms beyond geometry the correction carries (docs/error-terms.md)
                           "error_terms": [] if em is None else list(em.families)}
    if cfg.model.is_scara:
        kin = derive_tool(cfg.model, np.asarray(ident["params"] if em is None else em.params, dtype=float),
                          head_in_flange(cfg), tool.tcp_matrix)
        table = build_correction_table(kin.nominal, kin.params, tool_grid(cfg, tool), capacity=MAX_TABLE_VALUES,
                                       delta=None if em is None else em.joint_delta(cfg))
        want = str(stored.get("summary", {}).get("crc32"))
        if f"{table.data.crc32():08x}" != want:
            raise ConfigError(f"run {run_id}: the rebuilt table of tool {name!r} has CRC-32 {table.data.crc32():08x}, "
                              f"the run stored {want}; this station version builds it differently: re-run the "
                              f"calibration to export it")
        out["elbows"] = list(table.elbows)
        out["interpolation_bound_um"] = float(table.interpolation_bound_um)
        limit = float(tool.correction.max_interpolation_um)
        out["max_interpolation_um"] = limit
        if table.interpolation_bound_um > limit:
            why = (f"tool {name!r}: its table interpolates with up to {table.interpolation_bound_um:.1f} µm, "
                   f"{table.interpolation_bound_um / limit:.1f}× its correction.max_interpolation_um = {limit:g}")
            if not force:
                raise ToolTableBeyondBound(f"run {run_id}: {why}; nothing was written. Give the tool a finer or "
                                           f"smaller grid ([[tool]] x_mm, y_mm, z_mm) and calibrate again, or pass "
                                           f"--force to write it with this warning inside")
            out["warning"] = f"{why}; written with --force: the controller's correction may miss by that much"
        out["table"] = table_to_json(table.data)
    else:
        out["targets"] = stored.get("targets")
        out["commands_pose_mm_rad"] = stored.get("commands_pose_mm_rad")
    return out
