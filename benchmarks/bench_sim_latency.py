"""Can the station's numerics or a loaded PC starve the simulated cell or the heartbeat? (issue 19)

    .venv/bin/python benchmarks/bench_sim_latency.py [--seconds 4] [--hogs 2]

A poller thread reads the controller's status block every 20 ms (what the runner's waits do)
and the driver's heartbeat thread runs at its default 0.2 s period, while the main thread does
each load in turn: nothing; the identification numerics (numpy/scipy, 1000 poses, repeated);
pure-Python arithmetic that holds the GIL. The simulated controller runs in the station's process
(``--simulated``'s threads) and, for comparison, in its own process (``python -m simulators``).
With ``--hogs N`` as many ``while True: pass`` processes load the cores throughout.

Prints, per case, the median and worst status round trip [ms] and the worst gap between heartbeat
exchanges [ms] against the deadlines a simulated run uses (5 s reply, 5 s heartbeat) and a real
controller's watchdog (1 s). No asserts.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from drivers.controller import ModbusController  # noqa: E402


class _Beats(ModbusController):
    def __init__(self, *a, **kw) -> None:
        super().__init__(*a, **kw)
        self.beats: list[float] = []

    def _heartbeat_once(self) -> int:
        self.beats.append(time.monotonic())
        return super()._heartbeat_once()


def _numerics() -> Callable[[], None]:
    from station.core.accuracy.studies import StudyInputs, perturbed
    from station.core.identification.identify import identify
    from station.core.kinematics.poses import spread_joints
    from station.core.measurement.measurements import synthetic_set
    from station.io.robot.files import load_robot

    model = load_robot("sr800")
    rng = np.random.default_rng(0)
    inputs = StudyInputs()
    true = perturbed(model, rng, inputs)
    sig = np.array([inputs.sigma_position_mm] * 3 + [inputs.sigma_angle_rad] * 3)
    data = synthetic_set(model, "pose", spread_joints(model, 1000, rng), true, sigma=sig, rng=rng)
    return lambda: identify(model, data)


def _gil_loop() -> None:
    acc = 0.0
    for i in range(50_000):
        acc += (i * 1.000001) ** 0.5


def _measure(host: str, port: int, load: Callable[[], None] | None, seconds: float) -> tuple[float, float, float]:
    with _Beats(host, port, timeout=5.0) as c:
        rtts: list[float] = []
        stop = threading.Event()

        def poll() -> None:
            while not stop.is_set():
                t0 = time.perf_counter()
                c.status()
                rtts.append(time.perf_counter() - t0)
                stop.wait(0.02)

        t = threading.Thread(target=poll)
        start = time.monotonic()
        t.start()
        while time.monotonic() - start < seconds:
            if load is None:
                time.sleep(0.05)
            else:
                load()
        stop.set()
        t.join()
        beats = [b for b in c.beats if b >= start]
    gaps = np.diff(beats) if len(beats) > 1 else np.array([np.nan])
    return statistics.median(rtts) * 1e3, max(rtts) * 1e3, float(np.max(gaps)) * 1e3


def _own_process() -> tuple[subprocess.Popen, str, int]:
    p = subprocess.Popen([sys.executable, "-m", "simulators"], cwd=ROOT, stdin=subprocess.DEVNULL,
                         stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                         env={**os.environ, "PYTHONUNBUFFERED": "1"})
    host, port = json.loads(p.stdout.readline())["controller"].rsplit(":", 1)
    return p, host, int(port)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=4.0, help="seconds per case")
    ap.add_argument("--hogs", type=int, default=2, help="CPU hog processes beside the cases")
    args = ap.parse_args(argv)
    loads: list[tuple[str, Callable[[], None] | None]] = [
        ("idle", None), ("identify 1000 poses", _numerics()), ("pure-Python GIL loop", _gil_loop)]
    hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"], stdin=subprocess.DEVNULL)
            for _ in range(args.hogs)]
    try:
        from simulators import start_simulated_cell

        print(f"{args.hogs} CPU hog(s), {args.seconds:.0f} s per case; status median / worst [ms], "
              f"worst heartbeat gap [ms] (period 200 ms; watchdog 1000 ms)")
        with start_simulated_cell(seed=1) as servers:
            for name, load in loads:
                med, worst, gap = _measure(servers.controller_host, servers.controller_port, load, args.seconds)
                print(f"  in-process simulator, {name:22s} {med:7.1f} / {worst:7.1f}   gap {gap:7.1f}")
        p, host, port = _own_process()
        try:
            for name, load in loads:
                med, worst, gap = _measure(host, port, load, args.seconds)
                print(f"  own-process simulator, {name:21s} {med:7.1f} / {worst:7.1f}   gap {gap:7.1f}")
        finally:
            p.send_signal(signal.SIGTERM)
            p.wait(timeout=20)
    finally:
        for h in hogs:
            h.kill()
            h.wait()
    return 0


if __name__ == "__main__":
    sys.exit(main())
