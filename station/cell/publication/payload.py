"""What the fleet store receives for one finished run: built once, from the run database and
the run's configuration, when the run ends (or, for an older run, from its stored
configuration), and kept in the station's queue until it is sent.

Plain JSON types only: the queue stores it as JSON text; :mod:`station.fleet.store` writes it.
"""

from __future__ import annotations

import dataclasses
import math
import socket
from typing import Any

import numpy as np

from station.cell.config.cell_config import CellConfig
from station.cell.records.rundb import RunDB

__all__ = ["build_publication", "station_name", "robot_key"]


def station_name(cfg: CellConfig) -> str:
    """This station's name in the fleet: ``[fleet] station``, else the host name."""
    return cfg.fleet.station or socket.gethostname() or "station"


def robot_key(serial: str, station: str, cell: str) -> str:
    """The robot's key in the fleet: its serial; without one, ``station/cell`` (one robot per cell)."""
    return serial if serial else f"{station}/{cell}"


def _num(v: Any) -> float | None:
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) else None


def _clean(obj: Any) -> Any:
    """JSON for PostgreSQL's jsonb: NaN and infinities (which jsonb refuses) become null."""
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _clean(obj.tolist())
    if isinstance(obj, (np.floating, np.integer)):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def _parameters(stored: dict[str, Any], cfg: CellConfig) -> list[dict[str, Any]] | None:
    """One entry per identified parameter: its name, nominal, identified value and σ in the
    model's units, and that unit (``mm`` or ``rad``), paired by name through the robot's model
    (issue 39: the stored ``params`` are the whole model's vector, the names only the chosen ones)."""
    chosen, params, sigma = stored.get("chosen"), stored.get("params"), stored.get("sigma")
    if not isinstance(chosen, list) or not isinstance(params, list) or not isinstance(sigma, list) \
            or len(sigma) != len(chosen):
        return None
    names, nominal, angle = cfg.model.param_names, np.asarray(cfg.model.nominal), cfg.model.is_angle()
    if len(params) != len(names) or not all(isinstance(n, str) and n in names for n in chosen):
        return None  # not this model's vector: no pairing is better than a wrong one
    out = []
    for name, s in zip(chosen, sigma):
        i = names.index(name)
        out.append({"name": name, "unit": "rad" if angle[i] else "mm", "nominal": float(nominal[i]),
                    "value": params[i], "sigma": s})
    return out


def _identification(stored: Any, summary: dict[str, Any], cfg: CellConfig) -> dict[str, Any] | None:
    """The identified parameters (each with its unit), σ and the covariance of the chosen ones."""
    if not isinstance(stored, dict):
        return None
    names = [p.get("name") for p in summary.get("identification", {}).get("parameters", [])]
    return {"names": names, "chosen": stored.get("chosen"), "params": stored.get("params"),
            "parameters": _parameters(stored, cfg),
            "sigma": stored.get("sigma"), "covariance": stored.get("covariance"),
            "rms_normalized": stored.get("rms_normalized"), "outliers": stored.get("outliers")}


def _operator(db: RunDB, run_id: int, cfg: CellConfig) -> str | None:
    """Who ran it: the operator recorded with the run's report (``calibrate --operator``), else
    ``[cell] operator`` (the report's own order, station/ui/report/run.py)."""
    stored = db.load_result(run_id, "operator", default=None)
    if isinstance(stored, str) and stored.strip():
        return stored.strip()
    return cfg.identity.operator or None


def build_publication(db: RunDB, run_id: int, cfg: CellConfig, run_uuid: str, finished_utc: str) -> dict[str, Any]:
    """The publication of run ``run_id``: identity, headline figures (the fleet page's columns)
    and the detail (summary, parameters with covariance, verification, recheck, certificates)."""
    run = db.run(run_id)
    summary = db.load_result(run_id, "summary", default=None) or {}
    kind = "recheck" if summary.get("kind") == "recheck" or "recheck" in summary else "calibration"
    station = station_name(cfg)
    serial = cfg.identity.robot_serial
    cell = str(summary.get("cell") or cfg.name)
    before, after = summary.get("before") or {}, summary.get("after") or {}
    recheck = summary.get("recheck") or {}
    tolerances = recheck.get("tolerances") or {}
    detail: dict[str, Any] = {
        "summary": summary,
        "identification": _identification(db.load_result(run_id, "identification", default=None), summary, cfg),
        "devices": db.load_result(run_id, "devices", default=None),
        "head_certificate": dataclasses.asdict(cfg.head_certificate),
        "body_certificate": dataclasses.asdict(cfg.body_certificate),
        "controller": cfg.identity.controller,
        "operator": _operator(db, run_id, cfg),
        "recheck": recheck or None,
        "baseline": summary.get("baseline"),
    }
    return _clean({
        "run_uuid": run_uuid,
        "robot_key": robot_key(serial, station, cell),
        "robot_serial": serial or None,
        "robot_model": str(summary.get("robot") or cfg.model.name),
        "cell": cell,
        "station": station,
        "station_version": run.station_version,
        "local_run_id": run.id,
        "kind": kind,
        "outcome": str(summary.get("outcome", "INTERNAL_ERROR")),
        "started_utc": run.created_utc,
        "finished_utc": finished_utc,
        "rms_before_um": _num(before.get("rms_um")),
        "rms_after_um": _num(after.get("rms_um")),
        "gain": _num(summary.get("gain")),
        "ap_max_um": _num(after.get("ap_max_um")),
        "rp_max_um": _num(after.get("rp_max_um")),
        "drift_rms_um": _num(recheck.get("rms_um")),
        "drift_max_um": _num(recheck.get("max_um")),
        "tolerance_um": _num(tolerances.get("position_um")),
        "recheck_interval_days": cfg.fleet.recheck_interval_days,
        "fingerprint": db.load_result(run_id, "fingerprint", default=None) or {},
        "detail": detail,
        # a rehearsal on the simulator: it stores its seed (as the report's banner reads it) or an oracle
        "simulated": run.seed is not None or bool(summary.get("oracle")),
        "operator": _operator(db, run_id, cfg),
    })
