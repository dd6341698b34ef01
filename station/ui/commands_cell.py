"""Station commands of the CLI: ``init``, ``check``, ``calibrate``, ``export``, ``tui``.

``station calibrate`` prints progress on stderr and (with ``--json``) one JSON summary on
stdout; its exit code tells the outcome (:class:`station.cell.pipeline.Outcome`).
"""

from __future__ import annotations

import json
import sys
from contextlib import ExitStack
from pathlib import Path

import numpy as np

from station.errors import ConfigError, StationError


# --- devices --------------------------------------------------------------------------------

def open_devices(cfg, stack: ExitStack):
    """Connect the probe head and the controller named in the configuration."""
    from drivers.controller import ModbusController
    from drivers.controller_map import WordOrder
    from drivers.probe_head import ProbeHead

    probe = stack.enter_context(ProbeHead(cfg.devices.probe_head, baudrate=cfg.devices.baudrate,
                                          timeout=cfg.devices.probe_timeout_s))
    ctrl = ModbusController(cfg.devices.controller_host, cfg.devices.controller_port,
                            device_id=cfg.devices.device_id,
                            word_order=WordOrder.BIG if cfg.devices.word_order == "big" else WordOrder.LITTLE,
                            timeout=cfg.devices.controller_timeout_s)
    ctrl.connect()
    stack.callback(ctrl.close)
    return probe, ctrl


def simulated_config_text(servers, seed: int) -> str:
    """A cell configuration for the built-in simulated cell (its CMM body report, endpoints)."""
    from simulators.cell import DEFAULT_SETUP

    cell = servers.cell
    from station.core.transforms import matrix_to_pose

    lines = []
    for (cube, corner), T in zip(cell.body.labels, cell.body.nominal):
        p = matrix_to_pose(T)
        vals = [*p[:3], *np.degrees(p[3:])]
        lines.append(f'  {{ id = "C{cube + 1}.{"abcd"[corner]}", pose = [{", ".join(repr(float(v)) for v in vals)}] }},')
    setup = [*DEFAULT_SETUP[:3], *np.degrees(DEFAULT_SETUP[3:])]
    return f"""# Built-in simulated reference cell (seed {seed}).
[cell]
name = "simulated reference cell"

[robot]
model = "sr800"
setup = [{", ".join(repr(float(v)) for v in setup)}]

[limits]
joints = [[-125.0, 125.0], [-140.0, 140.0], [-195.0, -5.0], [-355.0, 355.0]]

[body]
cube_edge_mm = {cell.body.cube_edge_mm!r}
points = [
{chr(10).join(lines)}
]

[devices]
probe_head = "{servers.probe_port}"
baudrate = 38400
controller = "{servers.controller_host}:{servers.controller_port}"
motion_timeout_s = 30.0

[plan]
settle_s = 0.0
repeats = 4
verification_cycles = 5

[identification]
# The simulated head: 0.5 µm probe noise over ~25 mm probe spacing (≈ 4″) on top of the robot's
# ≈ 5 µm repeatability; weights follow the measurement, not the data sheet.
sigma_position_um = 6.0
sigma_angle_arcsec = 6.0

[simulation]
seed = {seed}
"""


def outcome_for(exc: BaseException) -> int:
    from station.cell.pipeline import Outcome

    name = type(exc).__name__
    mods = type(exc).__module__
    if name in ("EmergencyStop", "DriveFault"):
        return Outcome.SAFETY_STOP
    if name.startswith("Table"):
        return Outcome.UPLOAD_FAILED
    if name == "RunAborted":
        return Outcome.ABORTED
    if isinstance(exc, StationError):
        return exc.exit_code
    if mods.startswith("drivers"):
        return Outcome.DEVICE_FAULT
    return 1


HINTS = {
    "EmergencyStop": "release the e-stop, check the cell, then 'station calibrate CONFIG --resume RUN'",
    "DriveFault": "clear the drive fault at the controller, then resume with --resume RUN",
    "HandshakeTimeout": "the motion command was NOT re-sent; check the robot program, then resume with --resume RUN",
    "ControllerLinkLost": "check the network cable / controller, then resume with --resume RUN",
    "ProbeTimeout": "check the probe cable and baud rate, then resume with --resume RUN",
    "ProbeDisconnected": "reconnect the probe head, then resume with --resume RUN",
    "TableVerifyError": "the table was NOT activated; re-run the upload (resume with --resume RUN)",
}


def _progress_printer(stream):
    from station.cell import events as ev

    def emit(e):
        if isinstance(e, ev.PhaseChanged):
            print(f"[{e.phase}] {e.detail}", file=stream, flush=True)
        elif isinstance(e, ev.RunStarted):
            print(f"run {e.run_id}: {e.n_steps} steps ({e.resumed_from} already on disk)", file=stream, flush=True)
        elif isinstance(e, ev.MeasurementRecorded):
            res = "" if np.isnan(e.residual_um) else f" residual {e.residual_um:.2f} µm"
            print(f"  {e.index + 1:4d}/{e.total} {e.label}: {'ok' if e.ok else 'NOT OK ' + e.message}{res}",
                  file=stream, flush=True)
        elif isinstance(e, ev.Notice):
            print(f"  {e.level}: {e.message}", file=stream, flush=True)
    return emit


# --- commands -------------------------------------------------------------------------------

def cmd_init(args) -> int:
    from station.cell.config import TEMPLATE

    p = Path(args.path)
    if p.exists() and not args.force:
        raise ConfigError(f"{p} exists; pass --force to overwrite it")
    p.write_text(TEMPLATE, encoding="utf-8")
    print(f"wrote a commented template to {p}; edit [body], [devices] and [robot].setup")
    return 0


def cmd_check(args) -> int:
    from station.cell.config import load_config

    cfg = load_config(args.config)
    ok = True
    print(f"configuration {args.config}: valid ({len(cfg.point_ids)} measuring points, robot {cfg.model.name})")
    from drivers.probe_head import ProbeHead

    try:
        with ProbeHead(cfg.devices.probe_head, baudrate=cfg.devices.baudrate, timeout=cfg.devices.probe_timeout_s) as ph:
            info = ph.identify()
            snap = ph.read_all()
            print(f"probe head {cfg.devices.probe_head}: {info}; channels {[str(s) for s in snap.status]}")
    except Exception as exc:  # report every device, then fail
        ok = False
        print(f"probe head {cfg.devices.probe_head}: FAILED: {type(exc).__name__}: {exc}")
    from drivers.controller import ModbusController

    try:
        with ModbusController(cfg.devices.controller_host, cfg.devices.controller_port,
                              device_id=cfg.devices.device_id, timeout=cfg.devices.controller_timeout_s) as c:
            st = c.status()
            q = c.read_joints()
            lim = c.soft_limits()
            print(f"controller {cfg.devices.controller_host}:{cfg.devices.controller_port}: {st}; joints {np.round(q, 5).tolist()}")
            wide = (cfg.soft_limits[:, 0] < lim[:, 0]) | (cfg.soft_limits[:, 1] > lim[:, 1])
            if np.any(wide):
                print(f"  warning: [limits] are wider than the controller's soft limits for joints {list(np.nonzero(wide)[0] + 1)}")
    except Exception as exc:
        ok = False
        print(f"controller {cfg.devices.controller_host}:{cfg.devices.controller_port}: FAILED: {type(exc).__name__}: {exc}")
    return 0 if ok else 7


def cmd_calibrate(args) -> int:
    from station.cell.pipeline import Options, run_calibration
    from station.cell.config import load_config, parse_text
    from station.cell.rundb import RunDB

    emit = _progress_printer(sys.stderr)
    with ExitStack() as stack:
        truth = None
        seed = None
        if args.simulated:
            from simulators import start_simulated_cell

            seed = args.seed
            servers = start_simulated_cell(seed=seed, time_scale=args.time_scale)
            stack.callback(servers.stop)
            text = simulated_config_text(servers, seed)
            cfg = parse_text(text, "<simulated cell>")
            truth = servers.cell.truth
            print(f"simulated cell (seed {seed}): controller {servers.controller_host}:{servers.controller_port}, "
                  f"probe head {servers.probe_port}", file=sys.stderr)
        else:
            if not args.config:
                raise ConfigError("give a configuration file, or --simulated for the built-in simulated cell")
            cfg = load_config(args.config)
        db = stack.enter_context(RunDB(args.db))
        if args.resume is not None and not args.simulated:
            stored = db.run(args.resume)
            if stored.config_toml != cfg.source_text:
                print("note: the configuration file differs from the run's snapshot; the snapshot's plan is used",
                      file=sys.stderr)
        probe, ctrl = open_devices(cfg, stack)
        try:
            summary = run_calibration(cfg, probe, ctrl, db, emit, options=Options(upload=not args.no_upload, oracle_truth=truth),
                                      resume_run=args.resume, seed=seed)
        except BaseException as exc:
            code = outcome_for(exc)
            if isinstance(exc, KeyboardInterrupt):
                raise
            hint = HINTS.get(type(exc).__name__, "")
            run = db.latest_run()
            msg = f"station: {type(exc).__name__}: {exc}"
            if run is not None:
                msg += f"\n  everything measured so far is in {args.db} (run {run.id})"
            if hint:
                msg += f"\n  what to do: {hint.replace('RUN', str(run.id) if run else 'RUN')}"
            print(msg, file=sys.stderr)
            if args.json:
                print(json.dumps({"outcome": type(exc).__name__, "exit_code": int(code), "message": str(exc),
                                  "run_id": run.id if run else None}))
            if code == 1:
                raise
            return int(code)
    if args.report:
        from station.ui.report_data import report_for_run

        path = report_for_run(args.db, summary["run_id"], Path(args.report))
        summary["report"] = str(path)
    _print_summary(summary)
    if args.json:
        print(json.dumps(summary, default=float))
    from station.cell.pipeline import Outcome

    return int(Outcome[summary["outcome"]])


def _print_summary(s: dict) -> None:
    e = sys.stderr
    print(f"\nrun {s['run_id']}: {s['outcome']}", file=e)
    idn = s.get("identification", {})
    if idn:
        print(f"  identified {idn['n_parameters']} parameters from {idn['n_measurements']} poses, "
              f"RMS residual {idn['rms_residual_um']:.1f} µm", file=e)
    for key in ("before", "after", "oracle"):
        if key in s and s[key].get("n"):
            v = s[key]
            print(f"  {key:7s} RMS {v['rms_um']:8.1f} µm  max {v['max_um']:8.1f} µm  AP≤{v['ap_max_um']:.1f} µm  RP≤{v['rp_max_um']:.1f} µm", file=e)
    if "gain" in s:
        print(f"  improvement ×{s['gain']:.1f}" + (f"; after/oracle {s['after_vs_oracle']:.2f}" if "after_vs_oracle" in s else ""), file=e)


def cmd_export(args) -> int:
    from station.cell.rundb import RunDB

    with RunDB(args.db) as db:
        run = db.run(args.run) if args.run else db.latest_run()
        if run is None:
            raise ConfigError(f"{args.db} holds no runs")
        db.export_csv(run.id, args.output)
    print(f"run {run.id} exported to {args.output}")
    return 0


def cmd_tui(args) -> int:
    from station.ui.tui_launch import launch

    return launch(args)


def register(sub) -> None:
    p = sub.add_parser("init", help="write a commented cell configuration template")
    p.add_argument("path")
    p.add_argument("--force", action="store_true")
    p.set_defaults(func=cmd_init)

    p = sub.add_parser("check", help="validate a configuration and connect to every device")
    p.add_argument("config")
    p.set_defaults(func=cmd_check)

    p = sub.add_parser("calibrate", help="measure, identify, correct, upload, verify")
    p.add_argument("config", nargs="?")
    p.add_argument("--simulated", action="store_true", help="run against the built-in simulated cell")
    p.add_argument("--seed", type=int, default=1, help="simulated cell seed (default 1)")
    p.add_argument("--time-scale", type=float, default=0.0, help="simulated motion time scale (0 = instant)")
    p.add_argument("--db", default="runs.sqlite", help="run database (default runs.sqlite)")
    p.add_argument("--resume", type=int, metavar="RUN", help="continue an interrupted run")
    p.add_argument("--no-upload", action="store_true", help="identify and verify 'before' only")
    p.add_argument("--report", metavar="DIR", help="write a report (Markdown + plots) here")
    p.add_argument("--json", action="store_true", help="JSON summary on stdout")
    p.set_defaults(func=cmd_calibrate)

    p = sub.add_parser("export", help="export a run's measurements to CSV")
    p.add_argument("--db", default="runs.sqlite")
    p.add_argument("--run", type=int)
    p.add_argument("output")
    p.set_defaults(func=cmd_export)

    p = sub.add_parser("tui", help="terminal UI for the operator")
    p.add_argument("config", nargs="?")
    p.add_argument("--simulated", action="store_true")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--db", default="runs.sqlite")
    p.set_defaults(func=cmd_tui)
