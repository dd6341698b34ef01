"""The cell commands of ``station``: ``init``, ``check``, ``calibrate``, ``export``, ``tui``.

``station calibrate`` prints progress on stderr and its result on stdout, as Unix tools do
(``station calibrate … > out.txt`` keeps the summary); with ``--json`` stdout holds only the one
JSON summary and the readable one goes to stderr. Its exit code is the run's
:class:`~station.errors.Outcome`. Devices are opened by
:mod:`station.cell.session.calibrate`, never here; a simulated cell is composed by
:mod:`station.ui.simulated_cell`; the parser is :mod:`station.ui.cli.main`.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import shlex
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TextIO

from station.cell.config.cell_config import load_config
from station.cell.config.template import TEMPLATE
from station.cell.pipeline.outcomes import failure_summary, write_traceback
from station.cell.records.reading.run_list import list_runs
from station.cell.records.rundb import RunDB
from station.cell.records.summary import RunSummary
from station.cell.run.facts import events as ev
from station.cell.run.runcontrol import RunControl
from station.cell.session.calibrate import CellRequest, check_cell, reset_controller, run_calibration_session
from station.core.probe.check import check_head
from station.errors import ConfigError, Outcome, RunAborted, StationError
from station.ui.cli.process.output import DISK_ERRNOS
from station.ui.cli.process.progress_clock import ProgressClock, plan_seconds
from station.ui.cli.process.stop_signals import current as current_stop_signals
from station.ui.cli.process.stop_signals import safe_stop_on_signals
from station.ui.report.before_basis import before_basis_line
from station.ui.report.paths import report_dir
from station.ui.simulated_cell import load_cell


def request_from(args: argparse.Namespace) -> CellRequest:
    """The cell request of a ``calibrate`` or ``tui`` command line."""
    return CellRequest(config=args.config, simulated=args.simulated, seed=args.seed,
                       time_scale=getattr(args, "time_scale", 0.0), db=args.db,
                       resume=getattr(args, "resume", None), upload=not getattr(args, "no_upload", False),
                       robot=getattr(args, "robot", None))


#: what a phase does, for a phase announced without a detail of its own (no empty header)
PHASE_DETAIL = {
    "connect": "connecting the devices",
    "plan": "planning the poses and checking every motion against the soft limits",
    "measure": "measuring",
    "identify": "identifying the parameters from the measurements",
    "correct": "building the correction from the identified model",
    "upload": "uploading the correction table",
    "verify": "verifying",
}


def result_stream(args: argparse.Namespace) -> TextIO:
    """Where a command's readable result goes: stdout, or stderr when ``--json`` owns stdout."""
    return sys.stderr if getattr(args, "json", False) else sys.stdout


def progress_printer(stream: TextIO, clock: ProgressClock | None = None) -> Callable[[ev.Event], None]:
    """Progress on ``stream``: a progress bar that redraws one line at a terminal, plain lines
    otherwise (a log file, a scheduler's journal); each measurement's line carries the elapsed
    time and the time left (``clock``). The count is the run's own k of n (:class:`ev.Progress`:
    touches in the order made, the body's search touches included), never the plan's index."""
    tty = stream.isatty()
    bar_shown = False
    clock = clock or ProgressClock()
    done = total = 0  # the latest Progress

    def line(text: str) -> None:
        nonlocal bar_shown
        if bar_shown:  # finish the bar's line before a message of its own
            print(file=stream)
            bar_shown = False
        print(text, file=stream, flush=True)

    def bar(label: str) -> None:
        nonlocal bar_shown
        filled = int(round(30 * done / max(total, 1)))
        print(f"\r  [{'#' * filled}{'.' * (30 - filled)}] {done:4d}/{total} {label[:24]:24s} "
              f"{clock.text(done, total):44s}", end="", file=stream, flush=True)
        bar_shown = True

    def emit(e: ev.Event) -> None:
        nonlocal done, total
        if isinstance(e, ev.PhaseChanged):
            line(f"[{e.phase}] {e.detail or PHASE_DETAIL.get(e.phase, e.phase)}")
        elif isinstance(e, ev.RunStarted):
            clock.started(e)
            line(f"run {e.run_id}: {e.n_steps} steps ({e.resumed_from} already on disk)")
        elif isinstance(e, ev.Progress):
            done, total = e.done, e.total
            if tty and e.label:
                bar(e.label)
        elif isinstance(e, ev.MeasurementRecorded):
            if not (tty and e.ok):
                res = "" if math.isnan(e.residual_um) else f" residual {e.residual_um:.2f} µm"
                state = "ok" if e.ok else "NOT OK " + e.message
                line(f"  {done:4d}/{total} {e.label}: {state}{res} [{clock.text(done, total)}]")
        elif isinstance(e, ev.Notice):
            line(f"  {e.level}: {e.message}")
        elif isinstance(e, (ev.RunFinished, ev.RunFailed)) and bar_shown:
            line("")
    return emit


def print_summary(s: RunSummary, stream: TextIO) -> None:
    """The human-readable end of a run (the same figures the TUI and the report show). A failure's
    reason also goes to stderr when the summary goes elsewhere: ``> out.txt`` still shows the
    operator why the run stopped."""
    run = f"run {s.run_id}" if s.run_id is not None else "no run"
    print(f"\n{run}: {s.outcome.name} (exit code {s.exit_code})", file=stream)
    if s.failure is not None and stream is not sys.stderr:
        print(f"station: error: {s.failure.message}", file=sys.stderr)
    if s.failure is not None:
        print(f"  {s.failure.message}", file=stream)  # words for people, no Python type name (issue 33)
        if s.run_id is not None:
            print(f"  everything measured so far is in {s.db} (run {s.run_id})", file=stream)
        if s.failure.hint:
            print(f"  what to do: {s.failure.hint}", file=stream)
        if s.report:  # a failed run's report says how far it got
            print(f"  report: {s.report}", file=stream)
        for note in s.notes:  # among them why a report is missing
            print(f"  note: {note}", file=stream)
        return
    idn = s.identification
    if idn is not None:
        print(f"  identified {idn.n_parameters} parameters from {idn.n_measurements} measurements, "
              f"RMS residual {idn.rms_residual_um:.1f} µm", file=stream)
    print_error_table(s, stream)
    if s.upload_skipped:
        print("  upload skipped (--no-upload): no correction is active", file=stream)
    if s.upload is not None:
        print(f"  table {s.upload.crc32} uploaded, read back and activated in {s.upload.seconds:.2f} s", file=stream)
    if s.gain is not None:
        extra = f"; after/oracle {s.after_vs_oracle:.2f}" if s.after_vs_oracle is not None else ""
        print(f"  improvement ×{s.gain:.1f}{extra}", file=stream)
    if (recentred := s.recentring_text()) is not None:
        print(f"  {recentred}", file=stream)
    if s.report:
        print(f"  report: {s.report}", file=stream)
    for note in s.notes:
        print(f"  note: {note}", file=stream)


def print_error_table(s: RunSummary, stream: TextIO) -> None:
    """Before / after / oracle as a table. AP and RP are ISO 9283's pose accuracy and
    repeatability of one pose (station/core/accuracy/iso9283.py); the summary holds the largest over
    the held-out poses, so the columns say "worst pose" rather than a bound sign."""
    rows = [(key, v) for key in ("before", "after", "oracle") if (v := getattr(s, key)) is not None and v.n]
    if not rows:
        return
    print(f"  {'':7s} {'RMS µm':>9s} {'max µm':>9s}  {'AP µm, worst pose':>17s}  {'RP µm, worst pose':>17s}",
          file=stream)
    for key, v in rows:
        rp = "—" if v.rp_max_um is None else f"{v.rp_max_um:.1f}"
        print(f"  {key:7s} {v.rms_um:9.1f} {v.max_um:9.1f}  {v.ap_max_um:17.1f}  {rp:>17s}", file=stream)
    print("  AP: ISO 9283 pose accuracy, |mean attained − commanded position| of a pose's cycles; "
          "RP: its repeatability, l̄ + 3·S_l (— with one cycle per pose)", file=stream)
    if (basis := before_basis_line(s.before)) is not None:  # runs with other plans are not compared blindly
        print(f"  {basis}", file=stream)


def cmd_init(args: argparse.Namespace) -> int:
    p = Path(args.path)
    if p.exists() and not args.force:
        raise ConfigError(f"{p} exists; pass --force to overwrite it")
    robot, head, body = getattr(args, "robot", None), getattr(args, "head", None), getattr(args, "body", None)
    if robot is None and head is None and body is None:
        p.write_text(TEMPLATE, encoding="utf-8")
        print(f"wrote a commented template to {p}; edit [body], [devices] and [robot].setup")
        return 0
    from station.cell.session.new_cell import new_cell_text

    cell = new_cell_text(p, robot, head, body)
    p.write_text(cell.text, encoding="utf-8")
    print(f"wrote {p}, derived from the cell's files; edit [devices], check [robot].setup, then 'station plan {p}'")
    for note in cell.notes:
        print(f"  {note}")
    return 0


def cmd_check(args: argparse.Namespace) -> int:
    cfg = load_config(args.config)
    print(f"configuration {args.config}: valid ({len(cfg.point_ids)} measuring points, robot {cfg.model.name})")
    print("\n".join(check_head(cfg.head).lines()))  # the probe head (docs/probe-head.md)
    report = check_cell(cfg)
    for line in report.lines:
        print(line)
    return int(report.outcome)


def cmd_calibrate(args: argparse.Namespace) -> int:
    request = request_from(args)
    if not request.simulated and not request.config:
        raise ConfigError("give a configuration file, or --simulated for the built-in simulated cell")
    if args.report:  # checked before the first motion, not after an hour of measuring
        _check_report_dir(Path(args.report))
    if args.operator is not None:  # likewise the name the report will carry
        from station.ui.report.run import check_operator

        check_operator(args.operator)
    control = RunControl()
    summary = stopped_before_start(request)
    if summary is None:
        clock = ProgressClock(lambda run: plan_seconds(args.db, run, args.time_scale if args.simulated else None))
        with safe_stop_on_signals(control):
            summary = run_calibration_session(request, progress_printer(sys.stderr, clock), control, load=load_cell)
        summary = as_stopped(summary, args)
    if args.report and summary.run_id is not None:  # every run that ends: its report says how far it got
        summary = _with_report(summary, args)
        from station.ui.cli.commands_fleet import with_fleet_report  # issue 31: the report joins its run

        summary = with_fleet_report(summary, args.db)
    print_summary(summary, result_stream(args))
    if args.json:
        print(json.dumps(summary.to_json()), flush=True)
    return summary.exit_code


def resume_command(args: argparse.Namespace, run_id: int, verb: str = "calibrate") -> str:
    """The command line that continues run ``run_id`` of this ``calibrate`` (or ``recheck``): its
    configuration, simulated cell, seed, robot and database as given, and ``--resume``."""
    words = ["station", verb]
    if args.config:
        words.append(args.config)
    if args.simulated:
        words.append("--simulated")
        if args.seed is not None:
            words += ["--seed", str(args.seed)]
        if getattr(args, "robot", None):
            words += ["--robot", args.robot]
        if getattr(args, "time_scale", 0.0):
            words += ["--time-scale", f"{args.time_scale:g}"]
    words += ["--db", str(args.db), "--resume", str(run_id)]
    return " ".join(shlex.quote(w) for w in words)


def as_stopped(summary: RunSummary, args: argparse.Namespace, verb: str = "calibrate") -> RunSummary:
    """A run a signal stopped says so ("stopped by SIGTERM", not "aborted by the operator"), and a
    failure's hint names the real resume command instead of 'CONFIG --resume RUN'; the stored
    summary is updated alike, so that 'station runs' and the report say the same."""
    failure, run_id = summary.failure, summary.run_id
    if failure is None or run_id is None:
        return summary
    stops = current_stop_signals()
    message = failure.message
    if summary.outcome is Outcome.ABORTED and stops is not None and stops.requested and "operator" in message:
        message = (f"stopped by {stops.name} at a safe point (not by the operator at the station); every "
                   f"measurement taken is stored")
    placeholder = f"station calibrate CONFIG --resume {run_id}"
    hint = failure.hint.replace(placeholder, resume_command(args, run_id, verb))
    if (message, hint) == (failure.message, failure.hint):
        return summary
    summary = summary.replace(failure=dataclasses.replace(failure, message=message, hint=hint))
    from station.cell.session.calibrate import store_failure

    store_failure(args.db, run_id, {**summary.to_json(), **({"kind": "recheck"} if verb == "recheck" else {})})
    return summary


def _with_report(summary: RunSummary, args: argparse.Namespace) -> RunSummary:
    """``summary`` with its report written (``report``), or a note saying why there is none; a
    report's traceback goes beside the run database, never into the report folder."""
    from station.ui.report.run import report_for_run

    assert summary.run_id is not None
    try:
        path = report_for_run(args.db, summary.run_id, Path(args.report), operator=args.operator)
        return summary.replace(report=str(path))
    except StationError as exc:  # e.g. a stored configuration this version cannot read
        return summary.replace(notes=(*summary.notes, f"no report: {exc}"))
    except Exception as exc:  # noqa: BLE001 - the run's result stands; say why the report is missing
        log = write_traceback(exc, Path(args.db).resolve().parent)
        return summary.replace(notes=(*summary.notes, f"no report: it could not be written ({type(exc).__name__}: "
                                                      f"{exc}); traceback in {log}; rebuild it with 'station report "
                                                      f"{summary.run_id} --db {args.db}'"))


def stopped_before_start(request: CellRequest) -> RunSummary | None:
    """The ABORTED summary of a command that SIGTERM or SIGINT stopped before its session began
    (nothing was opened, nothing moved); None when no signal came."""
    stops = current_stop_signals()
    if stops is None or not stops.requested:
        return None
    exc = RunAborted(f"stopped by {stops.name} before the session started; nothing was opened or moved")
    return failure_summary(exc, run_id=request.resume, log_dir=".", db=request.db)


def cmd_reset(args: argparse.Namespace) -> int:
    """Clear the controller's latched e-stop or fault after the operator confirmed the cell is safe."""
    cfg = load_config(args.config)

    def confirm(question: str) -> bool:
        if args.yes:
            print(f"{question} yes (--yes)")
            return True
        if not sys.stdin.isatty():
            raise ConfigError("the reset needs the operator's confirmation: run it at a terminal, or pass --yes "
                              "once the e-stop is released and the cell is clear")
        return input(f"{question} [y/N] ").strip().lower() in ("y", "yes")

    for line in reset_controller(cfg, confirm):
        print(line)
    return 0


def _check_report_dir(path: Path) -> None:
    if path.exists() and not path.is_dir():
        raise ConfigError(f"--report {path}: that is a file; give a folder for the report (it is created if missing)")
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe = path / ".station-write-test"
        probe.write_text("")
        probe.unlink()
    except OSError as exc:
        raise ConfigError(f"--report {path}: cannot write there ({exc.strerror or exc}); choose another folder") from None


def cmd_plan(args: argparse.Namespace) -> int:
    """The plan preview: nothing moves."""
    from station.cell.correction.design import GRID_POINT
    from station.cell.pipeline.premotion import moves_json, moves_lines, premotion_check
    from station.cell.pipeline.preview import describe, preview
    from station.ui.report.render.cell_picture import check_picture_dir, plan_picture, write_cell_picture

    cfg = load_config(args.config)
    if args.out:
        check_picture_dir(Path(args.out))  # before the planning: a bad folder is refused at once
    pre = premotion_check(cfg)  # what 'calibrate' refuses before moving, refused here the same way (exit 2)
    picture = [] if not args.out else write_cell_picture(Path(args.out), plan_picture(
        cfg, pre.plan, pre.collision, with_upload=not args.no_upload))  # the cell's picture (issue 40)
    design = pre.design
    locating = [] if pre.locating is None else [f"  locating: {pre.locating.describe()}"]  # the run's first motions
    collision = [] if pre.collision is None else [f"  {ln}" for ln in pre.collision.lines()]  # issue 40
    collision += moves_lines(pre)  # the search touches and the first move, checked the same way
    p = preview(cfg, with_upload=not args.no_upload)
    head = check_head(cfg.head)  # the probe head's arrangement and sensitivity (docs/probe-head.md)
    warnings = plan_warnings(p, cfg)
    if args.json:
        correction = None if design is None else {
            "grid_shape": list(design.counts), "n_values": design.n_values, "capacity": design.capacity,
            "region_mm": {"x": list(design.region.x_mm), "y": list(design.region.y_mm), "z": list(design.region.z_mm)},
            "steps": dict(zip(("x_mm", "y_mm", "z_mm", "yaw_deg"), design.steps)),
            "predicted_bound_um": design.predicted_bound_um, "sampled_bounds_um": list(design.bounds_um),
            "max_interpolation_um": design.limit_um, "designed": not cfg.correction.explicit, "grid_point": GRID_POINT}
        print(json.dumps({"outcome": "SUCCESS", "exit_code": 0, **p.to_json(), "head": head.to_json(),
                          "warnings": warnings, "correction": correction,
                          "locating": None if pre.locating is None else pre.locating.describe(),
                          "collision": None if pre.collision is None else pre.collision.to_json(),
                          "picture": {f.suffix[1:]: str(f) for f in picture} or None,
                          **moves_json(pre)}))
    else:
        lines = describe(p)
        at = next((i + 1 for i, ln in enumerate(lines) if ln.lstrip().startswith("predicted accuracy")), len(lines))
        table = [] if design is None else [
            f"  correction table ({'configured' if cfg.correction.explicit else 'designed by the station'}): "
            f"{design.describe()}", f"  the grid's x, y, z and yaw are {GRID_POINT}"]
        drawn = [f"  picture of the cell (from above and from the side): {', '.join(map(str, picture))}"] if picture else []
        print("\n".join([*lines[:at], *table, *locating, *collision, *drawn, *(f"  warning: {w}" for w in warnings),
                          *lines[at:], *head.lines()]))
    return 0


#: a predicted σ after correction beyond this many times the measurement σ means the planned
#: poses do not determine the parameters: the figure is an artefact of the plan, not an accuracy
IMPLAUSIBLE_SIGMA_RATIO = 10.0


def plan_warnings(p, cfg) -> list[str]:
    """What in a plan preview is implausible, and which value to check (exit stays 0)."""
    out = _unmeasured_points(p, cfg)
    sig = cfg.identification.sigma_position_um
    worst = p.sigma_position_um[2]
    if not (math.isfinite(worst) and worst <= IMPLAUSIBLE_SIGMA_RATIO * sig):
        n_points = len(cfg.point_ids)
        return out + [f"the predicted position σ of up to {worst:.1f} µm is implausible for [identification]."
                f"sigma_position_um = {sig:g} µm (over {IMPLAUSIBLE_SIGMA_RATIO:g}×): the planned poses do not "
                f"determine the parameters (condition {p.condition:.3g}). Check [body]: {n_points} measuring "
                f"point{'s' if n_points != 1 else ''} (give every corner of the body, from its CMM report), then "
                f"[plan] elbows and [correction]'s workspace; also check that sigma_position_um is the probe "
                f"head's σ in µm"]
    return out


def _unmeasured_points(p, cfg) -> list[str]:
    """The body's points that no step measures (out of reach or the soft limits in every pose),
    named: a plan that leaves a third of the body out is no plan to run unseen (issue 37). A point
    with no 'NOT measured' line in a configuration the plan measures in had poses there that the
    pose design chose none of (it met its noise rule or [plan] select without them): said apart, as
    no setup or limit is to blame (the PUMA 560 examples' P2 cube, reachable in configuration +1)."""
    used = {s.step.point_id for s in p.steps}
    left = [pid for pid in cfg.point_ids if pid not in used]
    if not left:
        return []
    confs = {s.step.elbow for s in p.steps}
    refused = {(pid, c) for pid, c, _ in p.rejected}
    unchosen = [pid for pid in left if any((pid, c) not in refused for c in confs)]
    word = "elbow" if cfg.model.is_scara else "configuration"

    def names(pids: list[str]) -> str:
        return f"{', '.join(pids[:12])}{', …' if len(pids) > 12 else ''}"

    blocked = [pid for pid in left if pid not in unchosen]
    out = f"{len(left)} of {len(cfg.point_ids)} measuring points are measured in no pose: {names(left)}"
    if blocked:
        out += (f" (the 'NOT measured' lines say why{f' for {names(blocked)}' if unchosen else ''}: out of reach "
                f"or the soft limits in every {word}); check [robot].setup and the body's points")
    if unchosen:
        who = (f"; {names(unchosen)} {'has' if len(unchosen) == 1 else 'have'}" if blocked else
               f" ({'it has' if len(unchosen) == 1 else 'each has'}")
        out += (f"{who} poses the plan could measure, with no 'NOT measured' line in one of its {word}s, but the "
                f"pose design (its noise rule, or [plan] select) chose none of them{'' if blocked else ')'}")
    return [out]


def existing_db(path: str) -> str:
    """``path`` when the run database is there; a database error (exit 5) naming it when not
    (opening it would create an empty one)."""
    if not Path(path).is_file():
        from station.cell.records.run_records import RunDatabaseError

        where = Path(path).resolve()
        raise RunDatabaseError(f"no run database at {where}" + (" (that is a folder)" if where.is_dir() else "")
                               + "; give the path of an existing one with --db (a calibration creates it)")
    return path


def cmd_runs(args: argparse.Namespace) -> int:
    """The runs of a run database: a table for people, one JSON object for scripts."""
    existing_db(args.db)
    if getattr(args, "unlock", None) is not None:
        with RunDB(args.db) as db:
            holder = db.unlock_run(args.unlock)
        print(f"run {args.unlock}: " + (f"lock of {holder.describe()} cleared" if holder else "was not locked"))
        return 0
    with RunDB(args.db) as db:
        runs = list_runs(db)
    if args.json:
        print(json.dumps({"outcome": Outcome.SUCCESS.name, "exit_code": int(Outcome.SUCCESS), "db": str(args.db),
                          "runs": [r.to_json() for r in runs]}))
        return 0
    # names in full: each column as wide as its longest entry (issue 29: "myscara6" for "myscara650")
    w_cell = max([4, *(len(r.cell) for r in runs)])
    w_robot = max([5, *(len(r.robot) for r in runs)])
    print(f"{'run':>4}  {'created (UTC)':20}  {'cell':{w_cell}}  {'robot':{w_robot}}  {'status':10}  {'steps':>9}  "
          f"{'outcome':22}  {'before':>8}  {'after':>8}  resume?")
    for r in runs:
        def um(v: float | None) -> str:
            return "—" if v is None else f"{v:.1f}"
        print(f"{r.id:>4}  {r.created_utc[:19]:20}  {r.cell:{w_cell}}  {r.robot:{w_robot}}  {r.status:10}  "
              f"{r.steps_done:>4}/{r.steps_total:<4}  {(r.outcome or 'unfinished'):22}  {um(r.rms_before_um):>8}  "
              f"{um(r.rms_after_um):>8}  {'--resume ' + str(r.id) if r.resumable else ''}")
        if r.kind == "recheck":  # the trend: a recheck's drift beside the calibrations
            moved = f"; moved: {', '.join(r.moved)}" if r.moved else ""
            tol = "" if r.drift_tolerance_um is None else f" (tolerance {r.drift_tolerance_um:.1f})"
            print(f"        recheck of run {r.baseline}: drift RMS {um(r.drift_rms_um)} µm{tol}, "
                  f"max {um(r.drift_max_um)} µm{moved}")
    if not runs:
        print("(no runs yet)")
    return 0


def cmd_report(args: argparse.Namespace) -> int:
    """Rebuild a run's report from the run database."""
    from station.ui.report.run import report_for_run

    existing_db(args.db)
    out = Path(args.output) if args.output else report_dir(args.db, args.run)
    _check_report_dir(out)
    with RunDB(args.db) as db:
        db.run(args.run)  # a clear error for a run that is not there
    try:
        path = report_for_run(args.db, args.run, out, operator=args.operator)
    except StationError:
        raise  # the stored run cannot be read as a run (its outcome's exit code, never 1)
    except Exception as exc:  # noqa: BLE001 - a stored run always gets a report: the bare one, and why
        if isinstance(exc, OSError) and exc.errno in DISK_ERRNOS:  # a full disk is the operator's (issue 33)
            raise ConfigError(f"{out}: cannot write the report ({exc.strerror or exc}); free space on its disk or "
                              f"give another folder with -o") from None
        from station.ui.report.progress import bare_report_for_run

        log = write_traceback(exc, Path(args.db).resolve().parent)
        why = f"{type(exc).__name__}: {exc} (traceback in {log}; please report it with that file)"
        path = bare_report_for_run(args.db, args.run, out, why)
        print(f"station: warning: the full report of run {args.run} could not be built ({why}); the report "
              f"written holds the run's record and outcome only", file=sys.stderr)
    print(f"report of run {args.run}: {path}")
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    existing_db(args.db)
    with RunDB(args.db) as db:
        run = db.run(args.run) if args.run else db.latest_run()
        if run is None:
            raise ConfigError(f"{args.db} holds no runs")
        if getattr(args, "tool", None):  # a [[tool]]'s own correction (docs/correction.md, "Tools after the head")
            from station.cell.correction.tool_export import tool_export

            out = tool_export(db, run.id, args.tool, force=getattr(args, "force", False))
            try:
                Path(args.output).write_text(json.dumps(out), encoding="utf-8")
            except OSError as exc:
                raise ConfigError(f"cannot write {args.output}: {exc.strerror or exc}; choose another path") from None
            what = f"table CRC-32 {out['table']['crc32']}" if "table" in out else "compensated targets"
            print(f"run {run.id}: tool {args.tool!r} correction ({what}) written to {args.output}")
            if "warning" in out:
                print(f"station: warning: {out['warning']}", file=sys.stderr)
            return 0
        if getattr(args, "force", False):
            raise ConfigError("--force goes with --tool NAME")
        from station.cell.records.reading.run_export import export_csv, export_pose_file

        if getattr(args, "format", "record") == "identify":
            _, n, robot = export_pose_file(db, run.id, args.output)
            print(f"run {run.id}: {n} identification measurements written to {args.output} as a pose file; "
                  f"identify with: station identify {args.output} --robot {robot}")
            return 0
        export_csv(db, run.id, args.output)
    print(f"run {run.id} exported to {args.output} (every measurement with its status); for 'station identify' "
          f"export a pose file: station export --db {args.db} --run {run.id} --format identify OUT.csv")
    return 0


def cmd_tui(args: argparse.Namespace) -> int:
    from station.cell.recheck.measure import RecheckOptions
    from station.ui.tui.launch import launch

    recheck = getattr(args, "recheck", False)
    baseline, poses = getattr(args, "baseline", None), getattr(args, "poses", None)
    if not recheck and (baseline is not None or poses is not None):
        raise ConfigError("--baseline and --poses go with --recheck")
    if poses is not None and not 3 <= poses <= 100:
        raise ConfigError(f"--poses {poses}: give 3 … 100 poses")
    if args.config and not Path(args.config).is_file():  # before the full-screen UI takes the terminal
        raise ConfigError(f"no such configuration file: {args.config}; give the path of a cell configuration "
                          f"('station init' writes one)")
    return launch(request_from(args), recheck=RecheckOptions(baseline=baseline, poses=poses) if recheck else None)


__all__ = ["as_stopped", "cmd_calibrate", "print_summary", "progress_printer", "request_from", "safe_stop_on_signals",
           "stopped_before_start"]
