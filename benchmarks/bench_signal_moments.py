"""SIGTERM at many moments of a simulated session, side by side (issue 19's sweep, issue 42).

tests/ui/test_process_io.py keeps the moment the handlers exist, one committed step and two
moments side by side (8 and 32 steps); this script sweeps as many moments as asked. Each moment is
``station calibrate --simulated --no-upload --json`` as its own process, sent SIGTERM once the
run database holds that many committed steps (0: the moment its SIGTERM handler is installed),
synced on the database, never on a clock. Per moment it prints the exit code, the JSON outcome,
the run's status, the steps committed and the seconds; then how many behaved as documented: one
JSON object whose exit_code is the process's, ABORTED (6) with the run marked aborted and every
committed step kept, and no internal-error log. Exit 1 if any did not.

    .venv/bin/python benchmarks/bench_signal_moments.py [--moments 0 1 2 4 8 16 32 64 128] [--jobs 5]
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from station.cell.records.reading.run_list import committed_steps
from station.cell.records.rundb import RunDB

ROOT = Path(__file__).resolve().parents[1]
ABORTED = 6


def _committed(db: Path) -> int:
    return len(committed_steps(db))


def _handlers_installed(pid: int) -> bool:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("SigCgt:"):
                return bool(int(line.split()[1], 16) & (1 << (signal.SIGTERM - 1)))
    except OSError:
        pass
    return False


def one(steps: int, folder: Path) -> dict:
    """One process stopped by SIGTERM after ``steps`` committed steps; what it answered."""
    folder.mkdir(parents=True)
    db = folder / "runs.sqlite"
    t0 = time.perf_counter()
    p = subprocess.Popen([sys.executable, "-m", "station.ui.cli.main", "calibrate", "--simulated", "--no-upload",
                          "--json", "--db", str(db)], cwd=folder, env=dict(os.environ, PYTHONPATH=str(ROOT)),
                         text=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    while p.poll() is None and not (_committed(db) >= steps if steps else _handlers_installed(p.pid)):
        time.sleep(0.02 if steps else 0.0005)  # spares the CPU; the sync is on the database
    p.send_signal(signal.SIGTERM)
    out, _ = p.communicate()
    lines = [ln for ln in out.splitlines() if ln.strip()]
    s = json.loads(lines[0]) if len(lines) == 1 else {}
    status = None
    if s.get("run_id") is not None:
        with RunDB(db) as rdb:
            status = rdb.run(s["run_id"]).status
    ok = (len(lines) == 1 and s.get("exit_code") == p.returncode == ABORTED and s.get("outcome") == "ABORTED"
          and not list(folder.glob("station-error-*.log"))
          and (s.get("run_id") is None if steps == 0 else status == "aborted" and _committed(db) >= steps))
    return {"steps": steps, "rc": p.returncode, "outcome": s.get("outcome"), "status": status,
            "committed": _committed(db), "seconds": time.perf_counter() - t0, "ok": ok}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--moments", type=int, nargs="+", default=[0, 1, 2, 4, 8, 16, 32, 64, 128],
                    help="committed steps before the SIGTERM (0: when the handlers exist)")
    ap.add_argument("--jobs", type=int, default=5, help="processes side by side")
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp, ThreadPoolExecutor(a.jobs) as pool:
        rows = list(pool.map(lambda im: one(im[1], Path(tmp) / f"m{im[0]}"), enumerate(a.moments)))
    print("steps  exit  outcome   status    committed  seconds  as documented")
    for r in rows:
        print(f"{r['steps']:5d}  {r['rc']:4d}  {r['outcome'] or '-':8s}  {r['status'] or '-':8s}  "
              f"{r['committed']:9d}  {r['seconds']:7.1f}  {'yes' if r['ok'] else 'NO'}")
    good = sum(r["ok"] for r in rows)
    print(f"{good} of {len(rows)} moments as documented ({a.jobs} side by side)")
    return 0 if good == len(rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
