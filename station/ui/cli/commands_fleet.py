"""``station sync``, ``station fleet`` and ``station serve``: the plant's fleet store (issue 31).

``sync`` sends what the run database's queue holds to the fleet store; ``fleet`` lists the
robots of the store (text or ``--json``; ``--overdue`` exits 12 when a robot needs a recheck or
a calibration; ``--migrate`` brings the store's schema up to date, for its administrator);
``serve`` is the read-only QA dashboard.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING

from station.cell.records.summary import RunSummary
from station.errors import ConfigError, Outcome

if TYPE_CHECKING:
    from station.fleet.overview import RobotStatus

#: the dashboard's bearer token, where --token-file does not name one
TOKEN_ENV = "STATION_DASHBOARD_TOKEN"
LOCAL_HOSTS = ("127.0.0.1", "localhost", "::1")


def _url(args: argparse.Namespace) -> str:
    """--url (or --fleet), else STATION_FLEET_URL, else CONFIG's [fleet] url."""
    from station.fleet.settings import ENV_URL, fleet_url

    given = getattr(args, "url", None)
    if given:
        return str(given)
    configured = None
    if getattr(args, "config", None):
        from station.cell.config.cell_config import load_config

        configured = load_config(args.config).fleet.url
    url = fleet_url(configured)
    if not url:
        raise ConfigError(f"no fleet store: give --url, set {ENV_URL}, or [fleet] url in the cell configuration")
    return url


def _configured_station(args: argparse.Namespace) -> str | None:
    """CONFIG's ``[fleet] station`` (None without CONFIG or without one)."""
    if not getattr(args, "config", None):
        return None
    from station.cell.config.cell_config import load_config

    return load_config(args.config).fleet.station


def cmd_sync(args: argparse.Namespace) -> int:
    from station.cell.publication.outbox import pending, sync

    if not Path(args.db).is_file():
        raise ConfigError(f"{args.db}: no such run database")
    url = _url(args)
    backfilled, problems = 0, list[str]()
    if args.all:
        from station.cell.publication.outbox import enqueue_finished
        from station.ui.report.paths import report_dir

        backfilled, problems = enqueue_finished(args.db, station=_configured_station(args),
                                                report_dir=lambda run_id: report_dir(args.db, run_id))
        for line in problems:
            print(f"  not queued: {line}", file=sys.stderr)
    before = len(pending(args.db))
    result = sync(args.db, url)
    from station.cell.publication.certificates import send_certificates

    certs = send_certificates(args.db, url)
    out = {"newly_queued": backfilled, "not_queued": problems, "queued_before": before, "sent": result.sent, "already_in_store": result.already,
           "reports": result.reports, "still_queued": result.failed, "error": result.error or certs.error or None,
           "certificates": certs.sent, "certificates_unsent": certs.waiting + certs.failed}
    if args.json:
        print(json.dumps(out))
    else:
        print(f"fleet sync: {result.sent} run(s) sent, {result.already} already in the store, "
              f"{result.reports} report(s) attached, {certs.sent} certificate(s) attached, {result.failed} still queued")
        for error in (result.error, certs.error):
            if error:
                print(f"  not sent: {error}", file=sys.stderr)
    return int(Outcome.SUCCESS if result.ok and certs.ok else Outcome.DATABASE_ERROR)


def _fmt(v: float | None, digits: int = 1, unit: str = "") -> str:
    return "—" if v is None else f"{v:.{digits}f}{unit}"


def cmd_fleet(args: argparse.Namespace) -> int:
    from station.fleet import store
    from station.fleet.migrate import current_version, migrate
    from station.fleet.overview import fleet_status

    url = _url(args)
    if args.migrate:
        with store.store_errors(url), store.connect(url, check_schema=False, autocommit=True) as conn:
            applied = migrate(conn)
            version = current_version(conn)
        print(json.dumps({"applied": applied, "version": version}) if args.json
              else f"fleet store at schema version {version}; applied: {applied or 'none'}")
        return 0
    now = _as_of(getattr(args, "as_of", None))
    with store.store_errors(url), store.connect(url, read_only=True) as conn:
        robots = fleet_status(conn, now, default_interval_days=args.interval_days,
                              include_simulated=bool(getattr(args, "include_simulated", False)))
    overdue = [r for r in robots if r.overdue]
    if args.json:
        print(json.dumps({"robots": [r.to_json() for r in robots], "overdue": len(overdue)}))
    else:
        _print_fleet(robots)
        print(f"{len(robots)} robot(s), {len(overdue)} needing a recheck or calibration")
    if args.overdue and overdue:
        return int(Outcome.DRIFTED)
    return 0


def _as_of(text: str | None) -> datetime | None:
    """--as-of: a date (its midnight, UTC) or an ISO 8601 time (UTC where it names no zone)."""
    if text is None:
        return None
    try:
        t = datetime.fromisoformat(text.strip().replace("Z", "+00:00"))
    except ValueError:
        raise ConfigError(f"--as-of {text!r}: give a date or an ISO 8601 time, e.g. 2027-01-15 or "
                          f"2027-01-15T06:00:00Z") from None
    return t if t.tzinfo else t.replace(tzinfo=timezone.utc)


def _forecast(r: RobotStatus) -> str:
    """When the drift trend crosses the tolerance, with its 95 % interval (the dashboard's forecast)."""
    if r.drift_crossing_utc is None:
        return "—"
    return (f"{r.drift_crossing_utc[:10]} [{(r.drift_crossing_earliest_utc or '?')[:10]} … "
            f"{(r.drift_crossing_latest_utc or '?')[:10]}]")


def _print_fleet(robots: list[RobotStatus]) -> None:
    """The fleet table as text: the dashboard's columns, its drift forecast included."""
    print(f"{'robot':<24} {'cell':<22} {'station':<14} {'calibrated':<11} {'gain':>6} {'RMS after':>10} "
          f"{'AP max':>8} {'recheck':<20} {'drift µm':>9} {'trend µm/30 d':>13} {'drift reaches tolerance [95 %]':<36} "
          f"{'due':<21} state")
    for r in robots:
        rec = f"{(r.last_recheck_utc or '')[:10]} {r.last_recheck_verdict or ''}".strip() or "—"
        due = (r.next_recheck_due_utc or "—")[:10] + (" (forecast)" if r.due_from == "forecast" else "")
        print(f"{r.robot_key[:24]:<24} {r.cell[:22]:<22} {r.station[:14]:<14} "
              f"{(r.last_calibration_utc or '—')[:10]:<11} {_fmt(r.gain, 1, '×'):>6} "
              f"{_fmt(r.rms_after_um, 1, ' µm'):>10} {_fmt(r.ap_max_um, 1, ' µm'):>8} {rec[:20]:<20} "
              f"{_fmt(r.drift_rms_um, 1):>9} {_fmt(r.drift_trend_um_per_30d, 2):>13} {_forecast(r):<36} {due:<21} "
              f"{r.state}"
              + (f" (simulated run {r.last_simulated_utc[:10]}, not counted)" if r.last_simulated_utc else "")
              + (f" ({r.damaged})" if r.damaged else ""))
    if any(r.due_from == "forecast" for r in robots):
        print("due (forecast): the drift trend over the rechecks since the calibration (ILAC-G24 control chart) may "
              "reach the tolerance before the interval ends; due by the earliest date of its 95 % interval")


def cmd_serve(args: argparse.Namespace) -> int:
    if any(getattr(args, k, None) for k in ("opcua", "init_pki", "add_user")):  # the line's OPC UA server (issue 32)
        from station.ui.opcua.command import cmd_serve_opcua

        return cmd_serve_opcua(args)
    from station.ui.dashboard.app import DashboardAuth, create_app

    args.host = args.host or "127.0.0.1"
    args.port = args.port or 8031
    url = _url(args)
    token = None
    if args.token_file:
        token = Path(args.token_file).read_text(encoding="utf-8").strip()
        if not token:  # an empty token would turn authentication off without a word (issue 39)
            raise ConfigError(f"{args.token_file}: the token file is empty; write the bearer token into it "
                              f"(e.g. 'openssl rand -hex 32 > {args.token_file}')")
    elif os.environ.get(TOKEN_ENV):
        token = os.environ[TOKEN_ENV].strip()
    basic = None
    if args.basic_auth_file:
        user, _, password = Path(args.basic_auth_file).read_text(encoding="utf-8").strip().partition(":")
        if not user or not password:
            raise ConfigError(f"{args.basic_auth_file}: write one line USER:PASSWORD")
        basic = (user, password)
    auth = DashboardAuth(token=token or None, basic=basic)
    local = args.host in LOCAL_HOSTS
    if not local and not auth.enabled:
        raise ConfigError(f"--host {args.host}: a dashboard reachable from other machines needs --token-file "
                          f"(or {TOKEN_ENV}) or --basic-auth-file; it binds to 127.0.0.1 by default")
    if not local and not (args.tls_cert or args.behind_proxy):
        raise ConfigError(f"--host {args.host}: give --tls-cert/--tls-key, or --behind-proxy when a reverse proxy "
                          f"terminates TLS (docs/fleet.md); credentials never cross the network in clear text")
    if bool(args.tls_cert) != bool(args.tls_key):
        raise ConfigError("give --tls-cert and --tls-key together")
    import uvicorn

    app = create_app(url, auth=auth, interval_days=args.interval_days)
    print(f"QA dashboard on {'https' if args.tls_cert else 'http'}://{args.host}:{args.port}/ (read only; Ctrl-C stops)",
          file=sys.stderr)
    uvicorn.run(app, host=args.host, port=args.port, log_level="warning", ssl_certfile=args.tls_cert,
                ssl_keyfile=args.tls_key, proxy_headers=bool(args.behind_proxy),
                forwarded_allow_ips="127.0.0.1" if args.behind_proxy else None)
    return 0


def fleet_report_written(db: str, run_id: int, report: str) -> str | None:
    """After ``calibrate --report``: attach the report to the run's publication and send it now
    (queued when the store is unreachable); None when the run is not queued for a fleet store."""
    from station.cell.publication.outbox import attach_report, sync
    from station.fleet.settings import fleet_url

    try:
        if not attach_report(db, run_id, report):
            return None
        url = fleet_url(_queued_url(db, run_id))
        if url is None:
            return None
        result = sync(db, url, only_run=run_id)
    except Exception as exc:  # noqa: BLE001 - the run's result and its report stand
        return f"fleet: report of run {run_id} queued ({exc})"
    return None if result.ok else f"fleet: report of run {run_id} queued ({result.error}); 'station sync' sends it"


def _queued_url(db: str, run_id: int) -> str | None:
    """The [fleet] url the run was configured with (from its stored configuration)."""
    from station.cell.records.reading.stored_config import stored_config
    from station.cell.records.rundb import RunDB

    try:
        with RunDB(db) as rdb:
            return stored_config(rdb, run_id).fleet.url
    except Exception:  # noqa: BLE001 - a simulated cell's stored text: STATION_FLEET_URL then
        return None


def with_fleet_report(summary: RunSummary, db: str) -> RunSummary:
    """``calibrate --report``: the written report goes to the fleet store with its run; a note
    says so where it could only be queued."""
    if summary.report is None or summary.run_id is None:
        return summary
    note = fleet_report_written(db, summary.run_id, summary.report)
    return summary if note is None else summary.replace(notes=(*summary.notes, note))
