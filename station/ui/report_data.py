"""Build a run's report (station.ui.report) from what the run database holds.

The identification is recomputed from the stored measurements (it is deterministic and cheap),
so the report shows exactly what the run identified, with the full covariance.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from station.cell.pipeline import identify_run, verification_errors
from station.cell.config import parse_text
from station.ui.report import ReportData, write_report
from station.cell.rundb import RunDB
from station.core.uncertainty import pose_accuracy


def _errors_um(cfg, db, run_id, kind):
    errs = verification_errors(cfg, db.measurements(run_id, kind=kind))
    labels = []
    vals = []
    for (pid, label), e in errs.items():
        for k, v in enumerate(e):
            labels.append(f"{label} #{k + 1}")
            vals.append(np.linalg.norm(v) * 1e3)
    return np.array(vals), labels


def report_data_for_run(db: RunDB, run_id: int) -> ReportData:
    run = db.run(run_id)
    cfg = parse_text(run.config_toml, f"run {run_id}")
    res = identify_run(cfg, db.measurements(run_id, kind="identification"))
    # predicted accuracy over the workspace: a grid of the body's reachable head poses
    from station.cell.plan import build_plan

    plan = build_plan(cfg)
    q = np.array([s.target.joints for s in plan.identification] + [t.joints for t in plan.verification])
    acc = pose_accuracy(cfg.model, res.params, res.chosen_index, res.uncertainty.covariance, q, setup=True)
    from station.core.kinematics import forward

    xy = forward(cfg.model, q, res.params)[:, :2, 3]
    before, _ = _errors_um(cfg, db, run_id, "verification_before")
    after, labels = _errors_um(cfg, db, run_id, "verification_after")
    oracle, _ = _errors_um(cfg, db, run_id, "oracle")
    summary = db.load_result(run_id, "summary", default={})
    idx = res.chosen_index
    return ReportData(
        robot_name=cfg.model.name, run_id=run_id,
        param_names=list(res.chosen), param_nominal=np.asarray(cfg.model.nominal)[idx],
        param_identified=res.estimates, param_sigma=res.uncertainty.sigma,
        param_is_angle=cfg.model.is_angle()[idx], residuals=res.residuals,
        accuracy_xy_mm=xy, accuracy_sigma_mm=np.linalg.norm(acc.sigma[:, :3], axis=1),
        errors_before_um=before, errors_after_um=after,
        oracle_after_um=oracle if oracle.size else None, summary=summary,
        verify_labels=labels if len(labels) == len(after) else None, created=run.created_utc)


def report_for_run(db_path, run_id: int, out_dir: Path) -> Path:
    with RunDB(db_path) as db:
        data = report_data_for_run(db, run_id)
    return write_report(Path(out_dir), data)
