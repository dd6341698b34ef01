"""Finished runs written into a station's run database without a cell (the fleet tests need
their summaries, not an hour of measuring), and publications for the store directly."""

from __future__ import annotations

import dataclasses
import uuid
from datetime import datetime, timedelta, timezone
from pathlib import Path
from typing import Any

from station.cell.config.cell_config import CellConfig, load_config
from station.cell.config.sections import CellIdentity
from station.cell.records.rundb import RunDB

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "scara_arc" / "cell.toml"


def example_config(serial: str = "SR-0001", station: str = "cart-1") -> CellConfig:
    cfg = load_config(EXAMPLE)
    return dataclasses.replace(cfg, identity=CellIdentity(serial, "controller X", "operator Y"),
                               fleet=dataclasses.replace(cfg.fleet, station=station))


def calibration_summary(run_id: int, cell: str, after_um: float = 11.0) -> dict[str, Any]:
    return {"outcome": "SUCCESS", "exit_code": 0, "run_id": run_id, "cell": cell, "robot": "scara550",
            "identification": {"objective": "pose", "n_measurements": 140, "n_parameters": 2, "rms_normalized": 0.9,
                               "rms_residual_um": 10.0, "outliers": [],
                               "parameters": [{"name": "R.x", "value": -446.8, "sigma": 0.002},
                                              {"name": "R.y", "value": -1.29, "sigma": 0.0014}]},
            "before": {"n": 55, "rms_um": 680.0, "max_um": 900.0, "ap_max_um": 700.0, "rp_max_um": 30.0},
            "after": {"n": 55, "rms_um": after_um, "max_um": 25.0, "ap_max_um": after_um + 3, "rp_max_um": 25.0},
            "gain": 680.0 / after_um}


def recheck_summary(run_id: int, cell: str, drift_um: float, tolerance_um: float = 30.0) -> dict[str, Any]:
    outcome = "SUCCESS" if drift_um <= tolerance_um else "DRIFTED"
    return {"outcome": outcome, "exit_code": 0 if outcome == "SUCCESS" else 12, "run_id": run_id, "kind": "recheck",
            "cell": cell, "robot": "scara550",
            "baseline": {"run_id": 1, "created_utc": "2026-01-01T00:00:00Z", "outcome": "SUCCESS"},
            "recheck": {"outcome": outcome, "rms_um": drift_um, "max_um": drift_um * 1.5,
                        "tolerances": {"position_um": tolerance_um}}}


def finished_run(db_path: Path, cfg: CellConfig, summary_of=calibration_summary, **kw: Any) -> int:
    """A finished run in ``db_path`` whose stored summary is ``summary_of(run_id, cell, **kw)``."""
    with RunDB(db_path) as db:
        run_id = db.create_run(cfg.source_text or "[cell]\n", [], None)
        db.save_result(run_id, "config_source", str(EXAMPLE))  # its robot and body files resolve beside it
        db.save_result(run_id, "fingerprint", {"[cell]": "5d3478fb28c75e88"})
        db.save_result(run_id, "identification", {"params": [-446.8, -1.29], "chosen": [0, 1], "sigma": [0.002, 0.0014],
                                                  "covariance": [[4e-6, 1e-7], [1e-7, 2e-6]]})
        db.save_result(run_id, "summary", summary_of(run_id, cfg.name, **kw))
        db.set_status(run_id, "verified")
    return run_id


def publication(robot: str, kind: str, finished: datetime, *, outcome: str = "SUCCESS", after_um: float = 11.0,
                drift_um: float | None = None, tolerance_um: float | None = None, cell: str = "cell A",
                station: str = "cart-1", interval_days: int | None = 30) -> dict[str, Any]:
    """A publication as :func:`station.cell.publication.payload.build_publication` makes one."""
    return {"run_uuid": str(uuid.uuid4()), "robot_key": robot, "robot_serial": robot, "robot_model": "sr800",
            "cell": cell, "station": station, "station_version": "0.1.0", "local_run_id": 1, "kind": kind,
            "outcome": outcome, "started_utc": (finished - timedelta(hours=1)).isoformat(),
            "finished_utc": finished.isoformat(),
            "rms_before_um": 680.0 if kind == "calibration" else None,
            "rms_after_um": after_um if kind == "calibration" else None,
            "gain": 680.0 / after_um if kind == "calibration" else None,
            "ap_max_um": after_um + 3 if kind == "calibration" else None, "rp_max_um": None,
            "drift_rms_um": drift_um, "drift_max_um": drift_um, "tolerance_um": tolerance_um,
            "recheck_interval_days": interval_days, "fingerprint": {}, "detail": {}}


#: the tests' now: their runs are dated before it and the states and due dates reckoned at it
#: (create_app's clock, 'station fleet --as-of'), so no test follows the wall clock
NOW = datetime(2026, 6, 15, 12, 0, tzinfo=timezone.utc)
#: 'station fleet' at the tests' now
AS_OF = ("--as-of", NOW.isoformat())


def clock() -> datetime:
    """The dashboard's clock in the tests: always :data:`NOW`."""
    return NOW


def days_ago(n: float) -> datetime:
    return NOW - timedelta(days=n)
