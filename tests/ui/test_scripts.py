"""The station as a nightly script sees it: signals stop at a safe point with one JSON object,
--resume finishes with the result of an uninterrupted run; 'runs' and 'report' read the database."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from station.cell.records.rundb import RunDB
from station.ui.cli.main import main

ROOT = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "PYTHONUNBUFFERED": "1"}


def _calibrate(db: Path, *extra: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "station.ui.cli.main", "calibrate", "--simulated", "--seed", "1",
                             "--db", str(db), "--json", *extra], cwd=ROOT, env=ENV, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)


def _wait_for_steps(proc: subprocess.Popen, n: int, timeout: float = 540.0) -> list[str]:
    lines = []
    deadline = time.monotonic() + timeout
    assert proc.stderr is not None
    while time.monotonic() < deadline:
        line = proc.stderr.readline()
        if not line:
            break
        lines.append(line)
        if line.strip().startswith(f"{n}/"):
            return lines
    raise AssertionError("the run did not reach step %d:\n%s" % (n, "".join(lines[-20:])))


@pytest.mark.slow
def test_sigterm_stops_at_a_safe_point_and_resume_gives_the_uninterrupted_result(tmp_path, seed1_run):
    db = tmp_path / "runs.sqlite"
    proc = _calibrate(db)
    seen = _wait_for_steps(proc, 30)
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=540)
    assert proc.returncode == 6, err[-2000:]
    objects = [json.loads(line) for line in out.splitlines() if line.strip()]
    assert len(objects) == 1  # one JSON object, naming the run
    stopped = objects[0]
    assert stopped["outcome"] == "ABORTED" and stopped["run_id"] == 1
    assert "--resume 1" in stopped["failure"]["hint"] and "Traceback" not in err
    # a signal is reported as a signal, with the command that continues this very run (issue 29)
    assert stopped["failure"]["message"].startswith("stopped by SIGTERM at a safe point")
    assert f"station calibrate --simulated --seed 1 --db {db} --resume 1" in stopped["failure"]["hint"]
    assert "CONFIG" not in stopped["failure"]["hint"]
    progress = [ln for ln in seen if ln.strip().startswith("30/")]
    assert progress and " elapsed" in progress[0] and " left (" in progress[0]  # time on every progress line
    with RunDB(db) as d:  # the stored summary (the report's, 'runs'') says the same
        assert d.load_result(1, "summary")["failure"]["message"] == stopped["failure"]["message"]

    resumed = subprocess.run([sys.executable, "-m", "station.ui.cli.main", "calibrate", "--simulated", "--seed", "1",
                              "--db", str(db), "--json", "--resume", "1"], cwd=ROOT, env=ENV, text=True,
                             capture_output=True, timeout=300)
    assert resumed.returncode == 0, resumed.stderr[-2000:]
    done = json.loads(resumed.stdout)
    with RunDB(seed1_run.db) as whole:  # the same command, uninterrupted: the suite's seed-1 run
        reference = whole.load_result(1, "summary")
    for key in ("before", "after", "oracle"):
        assert done[key]["rms_um"] == pytest.approx(reference[key]["rms_um"], rel=1e-9), key
    assert [p["value"] for p in done["identification"]["parameters"]] == pytest.approx(
        [p["value"] for p in reference["identification"]["parameters"]], rel=1e-12, abs=1e-12)

    # 'station runs' shows both attempts' outcome now that it finished, and nothing to resume
    assert main(["runs", "--db", str(db), "--json"]) == 0


def test_runs_lists_outcomes_and_what_can_be_resumed(tmp_path, capsys, seed1_not_uploaded):
    db = seed1_not_uploaded.copy_to(tmp_path).db  # calibrate --simulated --no-upload: exit 11
    cfg = tmp_path / "bad.toml"
    assert main(["runs", "--db", str(db), "--json"]) == 0
    listing = json.loads(capsys.readouterr().out)
    (run,) = listing["runs"]
    assert run["run_id"] == 1 and run["outcome"] == "NOT_UPLOADED" and run["resumable"] is False
    assert run["steps_done"] == run["steps_total"] and run["rms_before_um"] > 100
    assert main(["runs", "--db", str(db)]) == 0
    table = capsys.readouterr().out
    assert "NOT_UPLOADED" in table and "sr800" in table
    assert main(["runs", "--db", str(cfg)]) == 5  # no database there: a database error naming the path (issue 29)
    assert f"no run database at {cfg}" in capsys.readouterr().err
    assert main(["runs", "--db", str(cfg), "--json"]) == 5
    failed = json.loads(capsys.readouterr().out)
    assert failed["outcome"] == "DATABASE_ERROR" and failed["db"] == str(cfg) and failed["failure"]["hint"]


def test_report_rebuilds_a_runs_report(tmp_path, capsys, seed1_not_uploaded):
    db = seed1_not_uploaded.copy_to(tmp_path).db  # calibrate --simulated --no-upload: exit 11
    out = tmp_path / "again"
    assert main(["report", "1", "--db", str(db), "-o", str(out)]) == 0
    assert (out / "report.md").exists() and "report of run 1" in capsys.readouterr().out
    assert main(["report", "7", "--db", str(db), "-o", str(out)]) == 5
    err = capsys.readouterr().err
    assert "no run 7" in err and "runs are 1..1" in err
