"""The fleet store at plant scale (issue 31): a generated fleet in a throwaway PostgreSQL server,
then medians of repeated runs after a warm-up.

    .venv/bin/python benchmarks/bench_fleet.py [--robots 200] [--years 5] [--repeat 7]

The fleet: ROBOTS robots, YEARS years of nightly rechecks and monthly calibrations each (200 × 5:
377 200 runs), loaded with COPY, then ANALYZE. It prints:

* the time to publish one run: a finished run queued in a station's SQLite run database and sent
  by ``sync`` (connecting as the station's role included), and the store's insert alone on an
  open connection;
* the fleet page's server time (``GET /``, the app in-process; goal ≤ 200 ms);
* the fleet table's CSV export (``GET /fleet.csv``, issue 39);
* a robot's history page (``GET /robots/KEY``, its runs and both SVG plots; goal ≤ 200 ms);
* the database's size.

Needs the distribution's PostgreSQL (``apt-get install postgresql``); as root the server runs as
``nobody`` (tests/fleet/pg_server.py). No asserts.
"""

from __future__ import annotations

import argparse
import json
import random
import statistics
import sys
import tempfile
import time
import uuid
from collections.abc import Callable
from datetime import datetime, timedelta, timezone
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _median_ms(fn: Callable[[], object], repeat: int) -> tuple[float, float]:
    fn()  # warm-up
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t) * 1e3)
    return statistics.median(times), min(times)


def _rows(robots: int, years: int, seed: int = 31):
    """(robot_key, run tuple) for the COPY, oldest first per robot."""
    rng = random.Random(seed)
    start = datetime(2021, 1, 1, 2, 0, tzinfo=timezone.utc)
    days = 365 * years
    n_par = 20
    cov = [[round(rng.gauss(0, 1e-6), 9) for _ in range(n_par)] for _ in range(n_par)]
    for r in range(robots):
        key = f"SR800-{r:05d}"
        cell, station = f"cell {r // 4:03d}", f"cart-{r // 20:02d}"
        after, tol = 10.0 + rng.random() * 5, 30.0
        for d in range(days):
            t = start + timedelta(days=d, minutes=rng.randint(0, 120))
            if d % 30 == 0:  # the monthly calibration
                after = 9.0 + rng.random() * 6
                detail = {"identification": {"names": [f"p{i}" for i in range(n_par)],
                                             "params": [rng.gauss(0, 1) for _ in range(n_par)],
                                             "sigma": [1e-3] * n_par, "covariance": cov}}
                yield (str(uuid.uuid4()), key, key, "sr800", cell, station, "0.1.0", d, "calibration", "SUCCESS",
                       t - timedelta(hours=1), t, 650 + rng.random() * 100, after, 680 / after, after + 3, 20.0,
                       None, None, None, 30, json.dumps({"[cell]": "5d3478fb28c75e88"}), json.dumps(detail), False,
                       "operator Y")
            t += timedelta(hours=1)  # the nightly recheck (on a calibration's day too, an hour after it)
            drift = max(0.5, rng.gauss(4 + (d % 30) * 0.3, 1.5))
            yield (str(uuid.uuid4()), key, key, "sr800", cell, station, "0.1.0", d, "recheck",
                   "SUCCESS" if drift <= tol else "DRIFTED", t - timedelta(minutes=10), t, None, None, None, None,
                   None, drift, drift * 1.6, tol, 30, "{}", json.dumps({"recheck": {"rms_um": drift}}), False,
                   "operator Y")  # schema 4's columns: simulated, operator


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robots", type=int, default=200)
    ap.add_argument("--years", type=int, default=5)
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args(argv)

    sys.path[:0] = [str(ROOT), str(ROOT / "tests" / "fleet")]
    import psycopg
    from pg_server import PgServer, find_bin  # the tests' throwaway server
    from starlette.testclient import TestClient

    from station.fleet import store
    from station.fleet.migrate import migrate
    from station.fleet.store import _RUN_COLUMNS
    from station.ui.dashboard.app import create_app

    bin_dir = find_bin()
    if bin_dir is None:
        print("PostgreSQL is not installed (apt-get install postgresql)", file=sys.stderr)
        return 2
    server = PgServer(bin_dir)
    try:
        server.start()
        admin = server.url()
        with psycopg.connect(admin, autocommit=True) as c:
            migrate(c)
            c.execute("CREATE ROLE bench_station LOGIN IN ROLE fleet_station")
            c.execute("CREATE ROLE bench_qa LOGIN IN ROLE fleet_dashboard")
            t = time.perf_counter()
            c.execute("INSERT INTO robots (robot_key, serial) SELECT 'SR800-' || lpad(g::text, 5, '0'), "
                      "'SR800-' || lpad(g::text, 5, '0') FROM generate_series(0, %s) g", (args.robots - 1,))
            n = 0
            cols = ", ".join(_RUN_COLUMNS)
            with c.cursor() as cur, cur.copy(f"COPY runs ({cols}) FROM STDIN".encode()) as copy:
                for row in _rows(args.robots, args.years):
                    copy.write_row(row)
                    n += 1
            c.execute("ANALYZE")
            load_s = time.perf_counter() - t
            size = c.execute("SELECT pg_size_pretty(pg_database_size(current_database())), "
                             "pg_database_size(current_database())").fetchone()
        assert size is not None
        print(f"fleet: {args.robots} robots × {args.years} year(s) of nightly rechecks and monthly calibrations = "
              f"{n} runs, loaded in {load_s:.1f} s (COPY + ANALYZE)")

        station_url, qa_url = server.url(user="bench_station"), server.url(user="bench_qa")
        from fleet_runs import example_config, finished_run

        from station.cell.publication.outbox import enqueue_run, sync

        cfg = example_config("SR800-00000", station="cart-00")
        with tempfile.TemporaryDirectory() as tmp:
            local = Path(tmp) / "runs.sqlite"
            run_ids = [finished_run(local, cfg) for _ in range(args.repeat + 1)]
            for rid in run_ids:
                enqueue_run(local, rid, cfg)
            queue = iter(run_ids)
            sync_med, sync_best = _median_ms(lambda: sync(local, station_url, only_run=next(queue)), args.repeat)
        with store.connect(station_url) as conn:
            template = dict(json.loads(json.dumps(_publication_example())))

            def insert_one() -> None:
                store.insert_publication(conn, {**template, "run_uuid": str(uuid.uuid4())})

            ins_med, ins_best = _median_ms(insert_one, args.repeat)

        with TestClient(create_app(qa_url)) as client:
            def page(path: str) -> Callable[[], None]:
                def get() -> None:
                    r = client.get(path)
                    assert r.status_code == 200, (path, r.status_code)
                return get

            fleet_med, fleet_best = _median_ms(page("/"), args.repeat)
            csv_med, csv_best = _median_ms(page("/fleet.csv"), args.repeat)  # the export (issue 39)
            robot = f"/robots/SR800-{min(42, args.robots - 1):05d}"
            hist_med, hist_best = _median_ms(page(robot), args.repeat)
            history = client.get(robot).text
            hist_len, hist_runs = len(history), history.count('<tr class="run ')

        print(f"publish one run (queued run sent by sync, connect included): median {sync_med:.1f} ms (best {sync_best:.1f})")
        print(f"publish one run (the store's insert on an open connection):  median {ins_med:.2f} ms (best {ins_best:.2f})")
        print(f"fleet page GET / ({args.robots} robots):                        median {fleet_med:.1f} ms (best "
              f"{fleet_best:.1f}); goal 200 ms")
        print(f"fleet export GET /fleet.csv ({args.robots} robots, with the drift forecasts): median {csv_med:.1f} ms "
              f"(best {csv_best:.1f})")
        print(f"robot history GET /robots/KEY ({hist_runs} runs, {hist_len // 1024} KiB): median "
              f"{hist_med:.1f} ms (best {hist_best:.1f}); goal 200 ms")
        print(f"database size: {size[0]} ({size[1] / n:.0f} bytes per run)")
    finally:
        server.cleanup()
    return 0


def _publication_example() -> dict:
    now = datetime.now(timezone.utc)
    return {"run_uuid": "", "robot_key": "SR800-00001", "robot_serial": "SR800-00001", "robot_model": "sr800",
            "cell": "cell 000", "station": "cart-00", "station_version": "0.1.0", "local_run_id": 1,
            "kind": "recheck", "outcome": "SUCCESS", "started_utc": now.isoformat(), "finished_utc": now.isoformat(),
            "rms_before_um": None, "rms_after_um": None, "gain": None, "ap_max_um": None, "rp_max_um": None,
            "drift_rms_um": 4.0, "drift_max_um": 6.0, "tolerance_um": 30.0, "recheck_interval_days": 30,
            "fingerprint": {}, "detail": {"recheck": {"rms_um": 4.0}}}


if __name__ == "__main__":
    sys.exit(main())
