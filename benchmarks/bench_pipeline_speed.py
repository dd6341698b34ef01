"""CPU time of whole station commands, each run as its own process (issue 42's suite time is mostly
end-to-end simulated calibrations; issue 38's ``station study --sets 10000`` ≤ 5 s).

    .venv/bin/python benchmarks/bench_pipeline_speed.py [--repeat 3] [--only scara,six,study]

For each command: the median over ``--repeat`` runs of the CPU time (user + system) of the child
process, read with ``resource.getrusage(RUSAGE_CHILDREN)`` before and after it (the station's
simulator threads run in the same process, so they count; waiting on sockets does not), and the
median wall time beside it (which carries the machine's other load). The commands:

* ``scara``: ``station calibrate --simulated`` (the built-in SR 800 cell, seed 1, instant motion);
* ``six``: ``station calibrate --simulated --robot irb2600`` (the built-in six-axis cell);
* ``study``: ``station study --sets 10000``.

Each run works in a fresh temporary folder (its own run database). Prints figures; asserts nothing.
The station imported is the one on ``PYTHONPATH`` (else this checkout's), so the tree before a
change can be timed beside it (``git archive HEAD~N | tar -x -C /tmp/old``, then
``PYTHONPATH=/tmp/old``).

Figures on the project's 2-core machine, 7 Dec 2026, the old tree and the new one back to back at
load 1.9-3.4 (median of 3 CPU times; the spread of one command is ±1.5 s at this load):

    command                                  before (69de579)   after (speed branch)
    calibrate --simulated (SR 800)           17.56 s            14.46 s (runs 12.48-15.18)
    calibrate --simulated --robot irb2600    21.37 s            19.42 s
    study --sets 10000                        5.90 s             5.63 s (wall 3.3 s)

The run database's reader keeping the records it parsed and checked (speed2 branch; old tree and new
back to back, load 1.7-2.5, median of 3 CPU times): calibrate --simulated 12.22 -> 11.97 s (within
the spread), --robot irb2600 19.33 -> 16.54 s (runs 19.10, 16.54, 16.53); ``station report`` of the
finished SCARA run 5.13 -> 4.67 s (its pages identical).

The simulated SCARA's CPU is spread over the station's thread (~10.4 s: the table's design ~3 s,
the plan's and the runner's collision checks ~2 s, the Modbus client ~1.5 s, imports ~1 s) and the
simulated controller's (~2.3 s) and probe unit's (~0.8 s).
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

COMMANDS = {
    "scara": ["calibrate", "--simulated"],
    "six": ["calibrate", "--simulated", "--robot", "irb2600"],
    "study": ["study", "--sets", "10000"],
}
#: the targets [s of CPU] where an issue names one (study: issue 38, on wall time)
TARGETS = {"study": 5.0}


def _cpu_children() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def run_once(args: list[str]) -> tuple[float, float]:
    """CPU [s] and wall [s] of one station command in a fresh folder; raises on a failed run."""
    env = dict(os.environ)
    env.setdefault("PYTHONPATH", str(ROOT))
    with tempfile.TemporaryDirectory() as tmp:
        c0, t0 = _cpu_children(), time.perf_counter()
        done = subprocess.run([sys.executable, "-m", "station.ui.cli.main", *args], cwd=tmp, env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        wall, cpu = time.perf_counter() - t0, _cpu_children() - c0
    if done.returncode != 0:
        raise SystemExit(f"station {' '.join(args)} ended with {done.returncode}:\n{done.stderr[-2000:]}")
    return cpu, wall


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--only", default=",".join(COMMANDS), help="comma-separated: " + ", ".join(COMMANDS))
    a = ap.parse_args(argv)
    print(f"station from {os.environ.get('PYTHONPATH', ROOT)}; load average {os.getloadavg()[0]:.1f}")
    for key in a.only.split(","):
        args = COMMANDS[key]
        runs = [run_once(args) for _ in range(a.repeat)]
        cpu = statistics.median(r[0] for r in runs)
        wall = statistics.median(r[1] for r in runs)
        target = f"  (target ≤ {TARGETS[key]:.1f} s wall)" if key in TARGETS else ""
        print(f"station {' '.join(args)}: CPU {cpu:.2f} s, wall {wall:.2f} s "
              f"(median of {a.repeat}; CPU runs {', '.join(f'{r[0]:.2f}' for r in runs)}){target}")
    print(f"load average after {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
