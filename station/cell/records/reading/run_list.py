"""The runs a run database holds, as the operator and a nightly script read them: id, cell,
robot, status, outcome, figures, and whether the run can be resumed. Rechecks (``station
recheck``) stand beside the calibrations with their drift figures: the trend of a robot."""

from __future__ import annotations

import sqlite3
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from station.cell.records.record_checks import checked
from station.cell.records.run_records import RunDatabaseError
from station.cell.records.rundb import RunDB
from station.cell.records.summary import RunSummary

#: outcomes of a run that reached its end: nothing left to resume
_ENDED = ("SUCCESS", "NOT_UPLOADED", "TARGET_MISSED", "DRIFTED")


@dataclass(frozen=True)
class RunInfo:
    id: int
    created_utc: str
    cell: str
    robot: str
    status: str
    steps_done: int
    steps_total: int
    outcome: str | None  # the stored summary's outcome name; None while unfinished
    rms_before_um: float | None
    rms_after_um: float | None
    gain: float | None
    kind: str = "calibration"  # or "recheck"
    baseline: int | None = None  # a recheck's baseline calibration
    drift_rms_um: float | None = None  # a recheck's RMS position drift against its baseline
    drift_max_um: float | None = None
    drift_tolerance_um: float | None = None
    moved: tuple[str, ...] = ()  # parameters a recheck found moved (names such as "A2.yaw")

    @property
    def resumable(self) -> bool:
        """Interrupted or failed before its end: ``--resume`` continues at the next missing step
        (an untrusted recheck only while it has steps without a valid measurement)."""
        if self.outcome == "RECHECK_UNTRUSTED":
            return self.steps_done < self.steps_total
        return self.outcome not in _ENDED

    def to_json(self) -> dict[str, Any]:
        return {"run_id": self.id, "created_utc": self.created_utc, "cell": self.cell, "robot": self.robot,
                "status": self.status, "steps_done": self.steps_done, "steps_total": self.steps_total,
                "outcome": self.outcome, "rms_before_um": self.rms_before_um, "rms_after_um": self.rms_after_um,
                "gain": self.gain, "resumable": self.resumable, "kind": self.kind, "baseline": self.baseline,
                "drift_rms_um": self.drift_rms_um, "drift_max_um": self.drift_max_um,
                "drift_tolerance_um": self.drift_tolerance_um, "moved": list(self.moved)}


def _names(config_toml: str) -> tuple[str, str]:
    try:
        data = tomllib.loads(config_toml)
    except tomllib.TOMLDecodeError:
        return "?", "?"
    cell = data.get("cell", {}).get("name", "calibration cell") if isinstance(data.get("cell"), dict) else "?"
    robot = data.get("robot", {}).get("model", "?") if isinstance(data.get("robot"), dict) else "?"
    return str(cell), Path(str(robot)).name


def list_runs(db: RunDB) -> list[RunInfo]:
    """Every run, newest first."""
    out = []
    for run in db.runs():
        stored = db.load_result(run.id, "summary", default=None)
        summary = checked(run.id, "result 'summary'", RunSummary.from_json, stored) if stored else None
        cell, robot = _names(run.config_toml)
        recheck = checked(run.id, "recheck results", _recheck_figures, db, run.id, run.plan)
        out.append(RunInfo(
            id=run.id, created_utc=run.created_utc, cell=summary.cell if summary else cell,
            robot=summary.robot if summary else robot, status=run.status,
            steps_done=len(db.completed_steps(run.id, ok_only=True)), steps_total=run.n_steps,
            outcome=summary.outcome.name if summary else None,
            rms_before_um=summary.before.rms_um if summary and summary.before else None,
            rms_after_um=summary.after.rms_um if summary and summary.after else None,
            gain=summary.gain if summary else None, **recheck))
    return out


def _recheck_figures(db: RunDB, run_id: int, plan: tuple) -> dict[str, Any]:
    """A recheck's fields of :class:`RunInfo` (empty for a calibration)."""
    if not plan or not all(isinstance(r, dict) and r.get("kind") == "recheck" for r in plan):
        return {}
    base = db.load_result(run_id, "recheck_baseline", default=None) or {}
    res = db.load_result(run_id, "recheck", default=None) or {}
    tol = res.get("tolerances") or {}
    return {"kind": "recheck", "baseline": base.get("run_id"), "drift_rms_um": res.get("rms_um"),
            "drift_max_um": res.get("max_um"), "drift_tolerance_um": tol.get("position_um"),
            "moved": tuple(res.get("moved", ()))}


def committed_steps(db_path: str | Path, run_id: int | None = None) -> list[int]:
    """The steps of run ``run_id`` (None: the latest) committed so far, in order: what a script
    watching a station at work reads. [] while the database or the run is still being created (the
    station writes both in its first seconds; a half-made file is read again later, not refused)."""
    path = Path(db_path)
    if not path.exists():
        return []
    try:
        with RunDB(path) as db:
            run = db.latest_run() if run_id is None else db.run(run_id)
            return sorted(db.completed_steps(run.id)) if run is not None else []
    except (RunDatabaseError, sqlite3.Error):  # created right now: its schema or run row not yet written
        return []
