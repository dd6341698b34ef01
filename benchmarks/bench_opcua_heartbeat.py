"""Does a subscribed OPC UA client disturb a run's timing? (issue 32)

    .venv/bin/python benchmarks/bench_opcua_heartbeat.py [--runs 3] [--time-scale 0.1]

Calibrates the example cell once in simulation (the baseline), starts ``station
serve --opcua examples/scara600/cell.toml --simulated`` in this process (the server's event loop
in the main thread, the run in its worker thread, as in production), then runs rechecks an
operator client starts over OPC UA (SignAndEncrypt), ``--runs``
without and ``--runs`` with a busy client: a separate process subscribed to the station's
progress at a 10 ms publishing interval that also reads the state every 50 ms throughout the
run. The controller driver's heartbeat exchanges are timestamped (its period is 0.2 s; a real
controller's watchdog trips after 1 s without one).

Prints per case the median over the runs of each run's median and largest heartbeat gap [ms] and
of the run's wall time [s]. No asserts: the figures are quoted in docs/opcua.md.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

CLIENT_URI = "urn:example.org:FreeOpcUa:opcua-asyncio"  # asyncua's clients announce it
#: the busy observer: subscribes to the progress at 10 ms and reads the state every 50 ms
BUSY = """
import asyncio, sys
from asyncua import Client
async def main(url, cert, key):
    c = Client(url, timeout=20)
    await c.set_security_string(f"Basic256Sha256,SignAndEncrypt,{cert},{key}")
    c.set_user("watch"); c.set_password("bench-observer")
    async with c:
        idx = await c.get_namespace_index("urn:robot-calibration-station:opcua:station")
        st = await c.nodes.objects.get_child([f"{idx}:CalibrationStation"])
        class H:
            def datachange_notification(self, node, val, data): pass
        sub = await c.create_subscription(10, H())
        for name in ("State", "Phase", "Step", "StepCount", "TimeLeftSeconds", "Message"):
            await sub.subscribe_data_change(await st.get_child([f"{idx}:{name}"]))
        state = await st.get_child([f"{idx}:State"])
        print("subscribed", flush=True)
        while True:
            await state.read_value()
            await asyncio.sleep(0.05)
asyncio.run(main(*sys.argv[1:]))
"""


def _instrument() -> list[float]:
    """Timestamp every heartbeat exchange of the controller driver (whatever instance the run opens)."""
    from drivers.controller import ModbusController

    beats: list[float] = []
    original = ModbusController._heartbeat_once

    def timed(self):  # type: ignore[no-untyped-def]
        beats.append(time.monotonic())
        return original(self)

    ModbusController._heartbeat_once = timed  # type: ignore[method-assign]
    return beats


def _baseline(opts) -> None:  # type: ignore[no-untyped-def]
    """The recheck's baseline: one simulated calibration (the figures are the rechecks')."""
    from station.cell.session.calibrate import CellRequest, run_calibration_session
    from station.ui.simulated_cell import load_cell

    # the same time scale as the rechecks: it is part of the simulated cell a baseline must match
    summary = run_calibration_session(CellRequest(config=opts.config, simulated=True, db=opts.db,
                                                  time_scale=opts.time_scale), lambda e: None, load=load_cell)
    if summary.outcome.name != "SUCCESS":
        raise SystemExit(f"the baseline calibration ended {summary.outcome.name}: no figures")


async def _run(client, idx: int, node, service, kind: str) -> float:
    t0 = time.monotonic()
    await node.call_method(f"{idx}:Start{kind}")
    while service.state in ("Running", "Paused"):
        await asyncio.sleep(0.05)
    wall = time.monotonic() - t0
    outcome = service.state
    await node.call_method(f"{idx}:Acknowledge")
    if outcome not in ("SUCCESS", "DRIFTED"):
        raise SystemExit(f"the {kind.lower()} ended {outcome}: no figures")
    return wall


async def bench(args: argparse.Namespace, work: Path) -> None:
    from asyncua import Client

    from station.ui.opcua.security import add_user, init_pki, make_certificate
    from station.ui.opcua.server import ServeOptions, build_server

    host = "localhost"
    init_pki(work / "pki", "urn:robot-calibration-station:bench", host)
    make_certificate(work / "client.der", work / "client.pem", CLIENT_URI, host, server=False)
    (work / "pki" / "trusted" / "client.der").write_bytes((work / "client.der").read_bytes())
    add_user(work / "users.toml", "line", "operator", "bench-operator")
    add_user(work / "users.toml", "watch", "observer", "bench-observer")
    opts = ServeOptions(config=str(ROOT / "examples" / "scara600" / "cell.toml"), users=str(work / "users.toml"),
                        pki=str(work / "pki"), host="127.0.0.1", port=args.port, simulated=True,
                        time_scale=args.time_scale, db=str(work / "runs.sqlite"))
    print(f"baseline calibration (time scale {args.time_scale:g}, through the session the server runs) …", flush=True)
    await asyncio.to_thread(_baseline, opts)
    beats = _instrument()
    server, service, url = await build_server(opts)
    async with server:
        await service.start()
        client = Client(url, timeout=30)
        await client.set_security_string(f"Basic256Sha256,SignAndEncrypt,{work / 'client.der'},{work / 'client.pem'}")
        client.set_user("line")
        client.set_password("bench-operator")
        async with client:
            idx = await client.get_namespace_index("urn:robot-calibration-station:opcua:station")
            node = await client.nodes.objects.get_child([f"{idx}:CalibrationStation"])
            print(f"{args.runs} rechecks per case; per run: median / largest heartbeat gap [ms] (period 200 ms, "
                  f"watchdog 1000 ms), wall time [s]; medians over the runs:")
            for case in ("no client subscribed", "a client subscribed at 10 ms, reading every 50 ms"):
                busy = None
                if case.startswith("a client"):
                    busy = subprocess.Popen([sys.executable, "-c", BUSY, url, str(work / "client.der"),
                                             str(work / "client.pem")], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                                            text=True,
                                            env={**os.environ, "PYTHONPATH": str(ROOT)})
                    assert busy.stdout is not None
                    await asyncio.to_thread(busy.stdout.readline)  # "subscribed"
                medians, largest, walls = [], [], []
                try:
                    for _ in range(args.runs):
                        start = time.monotonic()
                        walls.append(await _run(client, idx, node, service, "Recheck"))
                        gaps = np.diff([b for b in beats if b >= start]) * 1e3
                        medians.append(float(np.median(gaps)))
                        largest.append(float(np.max(gaps)))
                finally:
                    if busy is not None:
                        busy.kill()
                        busy.wait()
                print(f"  {case:52s} {statistics.median(medians):7.1f} / {statistics.median(largest):7.1f} ms"
                      f"   {statistics.median(walls):6.2f} s")
        await service.stop()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--runs", type=int, default=3, help="rechecks per case")
    ap.add_argument("--time-scale", type=float, default=0.1, help="simulated motion: 1 real time, 0 instant; "
                    "default 0.1: a recheck of some seconds. The baseline calibration runs at it too")
    ap.add_argument("--port", type=int, default=48440)
    args = ap.parse_args(argv)
    import logging

    logging.getLogger("asyncua").setLevel(logging.ERROR)
    with tempfile.TemporaryDirectory() as tmp:
        asyncio.run(bench(args, Path(tmp)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
