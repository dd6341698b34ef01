"""The pre-motion collision check's path, stored once with the run (issue 42): every pose the run
commands for its checked steps (vias included, :func:`station.cell.plan.collision.plan_path`) and
what the check found on them (the least clearance and its pair). The report's picture of the cell
(station/ui/report/render/cell_picture.py) draws from this record instead of planning the vias and
checking the path again: one fact, one stored value. A report of a run without the record (made
before it, or whose steps differ from the checked ones) plans and checks anew.

The record is used only where it is the check of exactly the steps drawn (their stored records
compared field by field) under exactly the configuration text the run stored; JSON keeps a float
bit for bit (its shortest repr), so the poses read back are the ones checked.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from station.cell.config.cell_config import CellConfig
from station.cell.plan.assembly import Plan
from station.cell.plan.collision import Clash, CollisionReport
from station.cell.plan.run_path import plan_path
from station.cell.plan.steps import PlannedStep

__all__ = ["PATH_RESULT", "path_record", "checked_path_record", "stored_path"]

#: the run database's result key (RunDB.save_result)
PATH_RESULT = "collision_path"

Poses = list[tuple[np.ndarray, str, int]]


def _config_digest(cfg: CellConfig) -> str:
    return hashlib.sha256(cfg.source_text.encode("utf-8")).hexdigest()


def _clash(c: Clash | None) -> dict[str, Any] | None:
    return None if c is None else {"a": c.a, "b": c.b, "where": c.where, "clearance_mm": c.clearance_mm,
                                   "limit_mm": c.limit_mm}


def path_record(cfg: CellConfig, steps: Sequence[PlannedStep], poses: Poses, report: CollisionReport) -> dict:
    """The record of ``report``, the collision check of ``poses``, the poses the run commands for
    ``steps`` (joints in rad, mm for a prismatic joint; clearances in mm)."""
    return {"units": {"joints": "rad (revolute), mm (prismatic)", "clearance": "mm"},
            "config_sha256": _config_digest(cfg), "steps": [s.to_record() for s in steps],
            "poses": [[np.asarray(q, dtype=float).tolist(), label, int(point)] for q, label, point in poses],
            "check": {"poses": report.poses, "samples": report.samples, "margin_mm": report.margin_mm,
                      "closest": _clash(report.closest), "closest_touch": _clash(report.closest_touch),
                      "evaluated": report.evaluated, "vias": report.vias}}


def _same(a: Poses, b: Poses) -> bool:
    return len(a) == len(b) and all(la == lb and pa == pb and qa.tobytes() == qb.tobytes()
                                    for (qa, la, pa), (qb, lb, pb) in zip(a, b))


def checked_path_record(cfg: CellConfig, plan: Plan, steps: Sequence[PlannedStep],
                        report: CollisionReport) -> dict | None:
    """The record of the pre-motion check (``report``, :func:`~station.cell.plan.collision.check_plan`
    of ``plan``) for the run's checked ``steps``, where the poses the picture draws for ``steps``
    (the path of a plan holding exactly them) are the ones checked, bit for bit; None otherwise
    (the picture then checks its own). Both paths reuse the check's vias
    (:mod:`station.cell.plan.via_memo`)."""
    drawn = plan_path(cfg, Plan(tuple(steps), (), ()))
    return path_record(cfg, steps, drawn, report) if _same(drawn, plan_path(cfg, plan)) else None


def _read_clash(rec: Any) -> Clash | None:
    if rec is None:
        return None
    return Clash(str(rec["a"]), str(rec["b"]), str(rec["where"]), float(rec["clearance_mm"]), float(rec["limit_mm"]))


def stored_path(cfg: CellConfig, steps: Sequence[PlannedStep], record: Any) -> tuple[Poses, CollisionReport] | None:
    """The poses and the check of ``steps`` from ``record`` (:func:`path_record`); None where there
    is none, it is not of these steps under this configuration's text, or it does not read (the
    caller then plans and checks anew)."""
    if not isinstance(record, Mapping) or record.get("config_sha256") != _config_digest(cfg):
        return None
    if record.get("steps") != [s.to_record() for s in steps]:
        return None
    try:
        poses = [(np.array(q, dtype=float), str(label), int(point)) for q, label, point in record["poses"]]
        chk = record["check"]
        report = CollisionReport(int(chk["poses"]), int(chk["samples"]), None, float(chk["margin_mm"]),
                                 _read_clash(chk["closest"]), _read_clash(chk["closest_touch"]),
                                 evaluated=int(chk["evaluated"]), vias=int(chk["vias"]))
    except (KeyError, TypeError, ValueError):
        return None
    if report.poses != len(poses) or any(q.shape != (cfg.model.n_joints,) for q, _l, _p in poses):
        return None
    return poses, report
