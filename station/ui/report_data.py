"""Build a run's report (station.ui.report) from what the run database holds.

The identification is recomputed from the stored measurements (it is deterministic and cheap),
so the report shows exactly what the run identified, with the full covariance.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from station.cell.config import CellConfig, parse_text
from station.cell.pipeline import identify_run, stored_plan, verification_errors
from station.cell.plan import build_plan
from station.cell.rundb import RunDB
from station.cell.steps import PlannedStep, StepKind
from station.cell.summary import RunSummary
from station.core.kinematics import forward
from station.core.uncertainty import pose_accuracy
from station.ui.report import ReportData, write_report


def _errors_um(cfg: CellConfig, steps: Sequence[PlannedStep], db: RunDB, run_id: int,
               kind: StepKind) -> tuple[np.ndarray, list[str]]:
    """Per verification pose and cycle: the position error [µm] and its label."""
    errs = verification_errors(cfg, steps, db.measurements(run_id, kind=kind.value))
    labels: list[str] = []
    vals: list[float] = []
    for (pid, elbow), e in errs.items():
        for k, v in enumerate(e):
            labels.append(f"{pid} elbow {elbow:+d} #{k + 1}")
            vals.append(float(np.linalg.norm(v) * 1e3))
    return np.array(vals), labels


def report_data_for_run(db: RunDB, run_id: int) -> ReportData:
    run = db.run(run_id)
    cfg = parse_text(run.config_toml, f"run {run_id}")
    steps = stored_plan(db, run_id)
    res = identify_run(cfg, db.measurements(run_id, kind=StepKind.IDENTIFICATION.value))
    # predicted accuracy over the workspace: the body's reachable head poses
    plan = build_plan(cfg)
    q = np.array([s.q for s in plan.identification] + [t.joints for t in plan.verification])
    acc = pose_accuracy(cfg.model, res.params, res.chosen_index, res.uncertainty.covariance, q, setup=True)
    xy = forward(cfg.model, q, res.params)[:, :2, 3]
    before, before_labels = _errors_um(cfg, steps, db, run_id, StepKind.VERIFY_BEFORE)
    after, labels = _errors_um(cfg, steps, db, run_id, StepKind.VERIFY_AFTER)
    oracle, _ = _errors_um(cfg, steps, db, run_id, StepKind.ORACLE)
    stored = db.load_result(run_id, "summary", default=None)
    summary = RunSummary.from_json(stored) if stored else None
    idx = res.chosen_index
    return ReportData(
        robot_name=cfg.model.name, run_id=run_id,
        param_names=list(res.chosen), param_nominal=np.asarray(cfg.model.nominal)[idx],
        param_identified=res.estimates, param_sigma=res.uncertainty.sigma,
        param_is_angle=cfg.model.is_angle()[idx], residuals=res.residuals,
        accuracy_xy_mm=xy, accuracy_sigma_mm=np.linalg.norm(acc.sigma[:, :3], axis=1),
        errors_before_um=before, errors_after_um=after,
        oracle_after_um=oracle if oracle.size and oracle.size == after.size else None, summary=summary,
        verify_labels=before_labels if len(before_labels) == len(before) else None, created=run.created_utc)


def report_for_run(db_path: str | Path, run_id: int, out_dir: Path) -> Path:
    with RunDB(db_path) as db:
        data = report_data_for_run(db, run_id)
    return write_report(Path(out_dir), data)
