"""``station`` command line: the one parser. Readable output by default, ``--json`` for scripts.

Every error ends the program with its message and the exit code of its
:class:`~station.errors.Outcome`, never with a traceback; an unexpected error (a bug) writes its
traceback to a log file the message names and exits 1.

Each subcommand names its function as ``"module:function"``, imported only when that command
runs: ``station --help`` or ``station identify`` must not pay for the cell layer, its drivers,
pymodbus, serial or textual (tests/ui/test_import_set.py checks the import set).
"""

from __future__ import annotations

import argparse
import importlib
import json
import math
import sys
from collections.abc import Callable, Sequence
from typing import NoReturn

from station.errors import ConfigError, Outcome, StationError
from station.ui.cli.process.library_log import route_library_logs
from station.ui.cli.process.output import DISK_ERRNOS, guarded_streams
from station.ui.cli.process.stop_signals import catch_stop_signals
from station.ui.cli.process.warning_policy import station_warnings

#: the commands that run a session: their SIGTERM and SIGINT are caught from main()'s first line
SESSION_COMMANDS = ("calibrate", "recheck")


class UsageError(Exception):
    """A command line argparse refused; main() turns it into a message (and JSON) and exit 2."""


class StationArgumentParser(argparse.ArgumentParser):
    """argparse's parser whose errors come back to main() instead of exiting, so that ``--json``
    still gets its one JSON object (the subcommands' parsers are of this class too)."""

    def error(self, message: str) -> NoReturn:
        self.print_usage(sys.stderr)
        raise UsageError(f"{self.prog}: error: {message}")


def time_scale(text: str) -> float:
    """``--time-scale``: 0 (instant) or a positive, finite factor."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"{text!r}: give 0 (instant motion) or a positive number "
                                         f"(1 = real time)")
    return value


def _integer(text: str, what: str, lo: int, hi: int) -> int:
    """An integer argument in ``lo … hi``: a run number, seed or count is range-checked before it
    reaches SQLite (64-bit integers) or numpy."""
    try:
        value = int(text.strip().replace("_", ""), 10)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: give {what} as a whole number ({lo} … {hi})") from None
    if not lo <= value <= hi:
        raise argparse.ArgumentTypeError(f"{text}: {what} must lie in {lo} … {hi}")
    return value


#: run ids are SQLite's 64-bit row ids
MAX_RUN = 2**63 - 1
#: the simulated cell's seed range ([simulation] seed)
MAX_SEED = 2**32 - 1


def run_number(text: str) -> int:
    """A run number (``report RUN``, ``--run``, ``--resume``, ``--unlock``, ``--baseline``)."""
    return _integer(text, "a run number", 1, MAX_RUN)


def seed(text: str) -> int:
    """``--seed``: the simulated cell's and the studies' random seed."""
    return _integer(text, "a seed", 0, MAX_SEED)


def count(hi: int) -> Callable[[str], int]:
    """A positive count (poses, sets, pairs) up to ``hi``."""
    def parse(text: str) -> int:
        return _integer(text, "a count", 1, hi)
    parse.__name__ = "count"
    return parse


def _command(spec: str) -> Callable[[argparse.Namespace], int | None]:
    """The function a ``"module:function"`` spec names, its module imported now."""
    module, _, name = spec.partition(":")
    func: Callable[[argparse.Namespace], int | None] = getattr(importlib.import_module(module), name)
    return func


def _add_cell(p):
    """The cell a session runs on: a configuration, or a simulated cell (CONFIG's or the built-in)."""
    p.add_argument("config", nargs="?", help="cell configuration; with --simulated: the cell to rehearse "
                   "(a file with only [simulation], [recheck], [warmup], [fleet]: the built-in cell with those)")
    p.add_argument("--simulated", action="store_true", help="run against a simulated cell: CONFIG's (rehearse "
                   "your cell), or the built-in one")
    p.add_argument("--seed", type=seed, default=None, help="simulated cell seed (default [simulation].seed, else 1)")
    p.add_argument("--time-scale", type=time_scale, default=0.0, help="simulated motion time scale (0 = instant)")


def _add_robot(p):
    p.add_argument("--robot", default="sr800", help="built-in robot name or robot file (default sr800)")
    _add_chain(p)


def _add_chain(p, short: bool = True):
    """``--base LINK`` / ``--tip LINK``: the chain of a URDF robot (``--base-link``/``--tip-link``
    where ``--base`` already means the robot base frame)."""
    base, tip = (["--base", "--base-link"], ["--tip", "--tip-link"]) if short else (["--base-link"], ["--tip-link"])
    p.add_argument(*base, dest="base_link", metavar="LINK", help="URDF: the link the chain starts at (default the root)")
    p.add_argument(*tip, dest="tip_link", metavar="LINK", help="URDF: the link the chain ends at (needed where it branches)")


def _add_prefs(p):
    p.add_argument("--prefer", default="", help="comma-separated parameters to prefer in the minimal set")
    p.add_argument("--fix", default="", help="comma-separated parameters held at their values")
    p.add_argument("--exclude", default="", help="comma-separated parameters left out of the model")


def build_parser() -> argparse.ArgumentParser:
    ap = StationArgumentParser(prog="station", description="Robot calibration station")
    sub = ap.add_subparsers(dest="command", required=True)

    _add_model_commands(sub)
    _add_cell_commands(sub)
    _add_record_commands(sub)
    _add_fleet(sub)
    return ap


def _add_model_commands(sub) -> None:
    """The commands on robot models and measurement files: nothing moves."""
    p = sub.add_parser("analyze", help="identifiability of a robot's parameters")
    _add_robot(p)
    p.add_argument("--objective", "--kind", dest="objective", choices=["pose", "position", "distance"],
                   default="pose", help="what is measured (--kind: the former name)")
    p.add_argument("--planar", action="store_true", help="all poses in one plane normal to z")
    p.add_argument("--poses", type=int, default=30)
    p.add_argument("--distances", "--max-pairs", dest="distances", type=int, default=200,
                   help="distances (pairs) formed from the poses (default 200)")
    p.add_argument("--joints", help="joint file (CSV with units) instead of random poses")
    p.add_argument("--seed", type=seed, default=0)
    _add_prefs(p)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func="station.ui.cli.commands_core:cmd_analyze")

    p = sub.add_parser("identify", help="identify a robot from a measurement file")
    p.add_argument("data", help="measurement CSV (docs/data-files.md)")
    _add_robot(p)
    p.add_argument("--objective", choices=["pose", "position", "distance"])
    p.add_argument("--sigma-position", type=float, default=15.0, help="µm per coordinate of a measured point (default 15)")
    p.add_argument("--sigma-angle", type=float, default=20.0, help="arc seconds (default 20)")
    p.add_argument("--pairs", choices=["cap", "all", "independent"], default="cap",
                   help="distance objective: which pairs of points (default cap)")
    p.add_argument("--max-pairs", type=count(10_000_000), default=20_000, help="distance objective: the cap (default 20000)")
    p.add_argument("--output", "-o", help="write the identified robot file here")
    p.add_argument("--tool", choices=["file", "unknown"], default=None,
                   help="unknown: fit the tool/marker point too (a reflector or marker offset); file: hold the robot "
                        "file's (default: file, or unknown where the robot file has [tool] unknown = true)")
    p.add_argument("--model", dest="error_model", metavar="MODEL", default="geometric",
                   help="error terms beyond geometry: geometric (default), auto (chosen by cross-validation), or "
                        "terms joined by '+': compliance, cyclic, cyclic2, cyclic.q<j>, drift, backlash")
    p.add_argument("--loss", choices=["linear", "huber"], default="linear",
                   help="huber: robust fit for outliers, listing the rows it down-weighted (default linear)")
    p.add_argument("--max-evaluations", type=count(100_000), default=200,
                   help="the fit's evaluations at most; a fit that has not converged by then exits 3 (default 200)")
    _add_prefs(p)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func="station.ui.cli.commands_core:cmd_identify")

    p = sub.add_parser("validate", help="held-out errors of a model on measurements it was not fitted on")
    p.add_argument("model", help="identified robot file (or built-in robot)")
    p.add_argument("data", help="measurement CSV (docs/data-files.md)")
    p.add_argument("--robot", default=None, help="nominal robot shown beside (default: the model's name)")
    _add_chain(p)
    p.add_argument("--sigma-position", type=float, default=15.0, help="µm (default 15), for the registration check")
    p.add_argument("--calibration", metavar="DATA",
                   help="the measurement CSV the model was fitted on: model and nominal are registered on it")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func="station.ui.cli.commands_core:cmd_validate")

    p = sub.add_parser("export-model", help="a model as MDH, DH, URDF or TOML, into its own URDF, or for UR's driver")
    p.add_argument("model", help="identified robot file (or built-in robot)")
    p.add_argument("--format", choices=["mdh", "dh", "urdf", "urdf-new", "toml", "ur-calibration"], required=True,
                   help="urdf: into the robot's own URDF; urdf-new: a new URDF; ur-calibration: UR's kinematics YAML")
    p.add_argument("--robot", metavar="FILE.urdf", help="--format urdf: the URDF the model was identified with")
    p.add_argument("--output", "-o", required=True, help="file to write")
    p.add_argument("--base", action="store_true", help="robot base frame (leave out the set-up R)")
    _add_chain(p, short=False)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func="station.ui.cli.commands_core:cmd_export_model")

    p = sub.add_parser("predict", help="poses of a model for given joint values")
    p.add_argument("model", help="built-in robot name or robot file")
    p.add_argument("joints", help="joint CSV with units")
    p.add_argument("--base", action="store_true", help="robot base frame (leave out the set-up R)")
    _add_chain(p, short=False)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func="station.ui.cli.commands_core:cmd_predict")

    p = sub.add_parser("compensate", help="compensated targets: filter a target list through the identified model "
                       "(robots without a correction table)")
    p.add_argument("model", help="identified robot file (station identify --output)")
    p.add_argument("targets", help="target CSV: x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg[,shoulder,elbow,wrist]")
    p.add_argument("--output", "-o", required=True, help="CSV to write: every row, compensated or marked failed")
    p.add_argument("--robot", default=None, help="the controller's nominal robot (default: the model's name)")
    p.add_argument("--setup", action="store_true", help="targets in the measurement frame (default: robot base)")
    p.add_argument("--allow-singular", action="store_true", help="compensate targets near a singularity too")
    p.add_argument("--joint-offsets", action="store_true",
                   help="also fit joint-zero offsets only and show their accuracy beside the full model's")
    _add_chain(p)  # the chain of whichever of MODEL and --robot is a URDF; --base is free here
    p.add_argument("--json", action="store_true")
    p.set_defaults(func="station.ui.cli.commands_compensate:cmd_compensate")

    p = sub.add_parser("study", help="re-run the chapter's simulation studies (§7.5)")
    _add_robot(p)
    p.add_argument("--seed", type=seed, default=0)
    p.add_argument("--sets", type=count(10_000_000), default=1000, help="Monte Carlo data sets for pose studies")
    p.add_argument("--quick", action="store_true", help="fewer Monte Carlo sets and seeds (a smoke run)")
    p.add_argument("--model", dest="error_model", metavar="MODEL", default="geometric",
                   help="instead of the chapter's geometric studies, the σ-versus-scatter study of the geometry with "
                        "error terms: auto (compliance and every first harmonic), or terms joined by '+': "
                        "compliance, cyclic, cyclic2, cyclic.q<j> (300 sets by default)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func="station.ui.cli.commands_study:cmd_study")


def _add_cell_commands(sub) -> None:
    """The commands on a cell: its configuration, its devices, its plan and its runs."""
    p = sub.add_parser("init", help="write a commented cell configuration: the template, or one derived from the "
                       "cell's robot, head and body files")
    p.add_argument("path")
    p.add_argument("--force", action="store_true")
    p.add_argument("--robot", help="the robot file (or a built-in name): limits, a set-up guess, repeats and cycles")
    p.add_argument("--head", help="the probe-head file (docs/probe-head.md)")
    p.add_argument("--body", help="the body's CMM report (CSV, docs/data-files.md)")
    p.set_defaults(func="station.ui.cli.commands_cell:cmd_init")

    p = sub.add_parser("check", help="validate a configuration and connect to every device")
    p.add_argument("config")
    p.set_defaults(func="station.ui.cli.commands_cell:cmd_check")

    p = sub.add_parser("conformance", help="check the robot program against the register map and handshake "
                       "(the robot parked at [conformance].park_joints)")
    p.add_argument("config")
    p.add_argument("--json", action="store_true", help="one JSON object on stdout")
    p.set_defaults(func="station.ui.cli.commands_conformance:cmd_conformance")

    p = sub.add_parser("calibrate", help="measure, identify, correct, upload, verify")
    _add_cell(p)
    p.add_argument("--robot", metavar="NAME", help="with --simulated: the built-in simulated cell of this robot "
                   "(sr800, the default; irb2600: a six-axis arm)")
    p.add_argument("--db", default="runs.sqlite", help="run database (default runs.sqlite)")
    p.add_argument("--resume", type=run_number, metavar="RUN", help="continue an interrupted run")
    p.add_argument("--no-upload", action="store_true", help="identify and verify 'before' only")
    p.add_argument("--report", metavar="DIR", help="write the run's report here: one self-contained report.html (printable), report.md beside it")
    p.add_argument("--operator", metavar="NAME", help="the operator the report names (default [cell] operator)")
    p.add_argument("--json", action="store_true", help="JSON summary on stdout")
    p.set_defaults(func="station.ui.cli.commands_cell:cmd_calibrate")

    p = sub.add_parser("recheck", help="a short accuracy check against the last calibration (drift)")
    _add_cell(p)
    p.add_argument("--db", default="runs.sqlite", help="run database (default runs.sqlite)")
    p.add_argument("--baseline", type=run_number, metavar="RUN", help="calibration to compare with (default: the latest "
                   "successful calibration of this cell)")
    p.add_argument("--poses", type=int, metavar="N", help="poses to measure (default [recheck].poses, 10)")
    p.add_argument("--resume", type=run_number, metavar="RUN", help="continue an interrupted recheck")
    p.add_argument("--json", action="store_true", help="JSON summary on stdout")
    p.set_defaults(func="station.ui.cli.commands_recheck:cmd_recheck")

    p = sub.add_parser("reset", help="clear the controller's latched e-stop or fault (asks for confirmation)")
    p.add_argument("config")
    p.add_argument("--yes", action="store_true", help="confirm without asking: the e-stop is released, the cell clear")
    p.set_defaults(func="station.ui.cli.commands_cell:cmd_reset")

    p = sub.add_parser("plan", help="preview a calibration's plan: steps, margins, expected accuracy (nothing moves)")
    p.add_argument("config")
    p.add_argument("--no-upload", action="store_true", help="the plan of a run without the upload")
    p.add_argument("--out", metavar="DIR", help="write the plan's files here: cell.svg and cell.png, the cell from "
                   "above and from the side with the plan's poses (docs/collision.md)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func="station.ui.cli.commands_cell:cmd_plan")


def _add_record_commands(sub) -> None:
    """The commands on a run database: lists, reports, exports, and the operator's UI."""
    p = sub.add_parser("runs", help="list the runs of a run database (status, outcome, figures, resumable)")
    p.add_argument("--db", default="runs.sqlite")
    p.add_argument("--unlock", type=run_number, metavar="RUN",
                   help="clear RUN's run lock (its process is gone, e.g. on another PC)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func="station.ui.cli.commands_cell:cmd_runs")

    p = sub.add_parser("report", help="rebuild a run's report from the run database")
    p.add_argument("run", type=run_number)
    p.add_argument("--db", default="runs.sqlite")
    p.add_argument("--output", "-o", metavar="DIR", help="report folder (default report-DB-run-RUN beside the "
                   "database, DB its file name without .sqlite)")
    p.add_argument("--operator", metavar="NAME", help="the operator the report names (default: the one "
                   "recorded with the run, else [cell] operator)")
    p.set_defaults(func="station.ui.cli.commands_cell:cmd_report")

    p = sub.add_parser("export-dcc", help="a finished calibration as a Digital Calibration Certificate (XML)")
    p.add_argument("run", type=run_number)
    p.add_argument("--db", default="runs.sqlite")
    p.add_argument("--issuer", required=True, metavar="FILE", help="laboratory, customer, robot manufacturer and "
                   "approver (TOML, docs/exports.md)")
    p.add_argument("--output", "-o", required=True, metavar="FILE.xml")
    p.add_argument("--operator", metavar="NAME", help="the operator (default: the one recorded with the run)")
    p.set_defaults(func="station.ui.cli.commands_dcc:cmd_export_dcc")

    p = sub.add_parser("export", help="export a run's measurements to CSV")
    p.add_argument("--db", default="runs.sqlite")
    p.add_argument("--run", type=run_number)
    p.add_argument("--tool", metavar="NAME", help="instead: the correction of the [[tool]] NAME (JSON, for its controller)")
    p.add_argument("--force", action="store_true", help="with --tool: write a table beyond its max_interpolation_um "
                   "(the warning is written into the file)")
    p.add_argument("--format", choices=["record", "identify"], default="record",
                   help="record: every measurement with its status (default); identify: the valid identification "
                        "measurements as a pose file that 'station identify' reads")
    p.add_argument("output")
    p.set_defaults(func="station.ui.cli.commands_cell:cmd_export")

    p = sub.add_parser("tui", help="terminal UI for the operator")
    p.add_argument("config", nargs="?")
    p.add_argument("--simulated", action="store_true", help="a simulated cell: CONFIG's, or the built-in one")
    p.add_argument("--seed", type=seed, default=None, help="simulated cell seed (default [simulation].seed, else 1)")
    p.add_argument("--db", default="runs.sqlite")
    p.add_argument("--recheck", action="store_true", help="run a recheck against the last calibration (drift)")
    p.add_argument("--baseline", type=run_number, metavar="RUN", help="with --recheck: the calibration run to compare with")
    p.add_argument("--poses", type=int, metavar="N", help="with --recheck: poses to measure (default [recheck].poses)")
    p.set_defaults(func="station.ui.cli.commands_cell:cmd_tui")


def _add_fleet(sub) -> None:
    """``sync``, ``fleet``, ``serve``: the plant's fleet store (issue 31; station/ui/cli/commands_fleet.py)."""
    url_help = "the fleet store (postgresql://host/db or service=NAME; default STATION_FLEET_URL, else CONFIG's [fleet] url)"
    p = sub.add_parser("sync", help="send the runs queued for the fleet store (store and forward)")
    p.add_argument("config", nargs="?", help="cell configuration whose [fleet] url names the store")
    p.add_argument("--db", default="runs.sqlite", help="run database (default runs.sqlite)")
    p.add_argument("--url", help=url_help)
    p.add_argument("--all", action="store_true", help="first queue every finished run of the database not yet "
                   "queued (a station joining the fleet with its history)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func="station.ui.cli.commands_fleet:cmd_sync")

    p = sub.add_parser("fleet", help="every robot of the fleet store: last calibration, recheck, drift, due date")
    p.add_argument("config", nargs="?", help="cell configuration whose [fleet] url names the store")
    p.add_argument("--url", help=url_help)
    p.add_argument("--json", action="store_true")
    p.add_argument("--overdue", action="store_true", help="exit 12 when a robot is overdue, drifted or uncalibrated")
    p.add_argument("--interval-days", type=count(3650), default=30,
                   help="days between rechecks for runs that name none (default 30)")
    p.add_argument("--migrate", action="store_true", help="the store's administrator: create or update its schema")
    p.add_argument("--include-simulated", action="store_true", help="count simulated runs (rehearsals) as the "
                   "robots' calibrations and rechecks (by default they are marked and never counted)")
    p.add_argument("--as-of", metavar="DATE", help="the states as of this UTC date or ISO 8601 time instead of now "
                   "(which robots will be due by a planned stop)")
    p.set_defaults(func="station.ui.cli.commands_fleet:cmd_fleet")

    p = sub.add_parser("serve", help="the read-only QA dashboard over the fleet store (localhost by default); "
                                      "with --opcua CONFIG the station as a secure OPC UA server (docs/opcua.md)")
    p.add_argument("--fleet", dest="url", metavar="URL", help=url_help)
    p.add_argument("--host", default=None, help="address to bind (dashboard: default 127.0.0.1, another needs auth; "
                                                "--opcua: default 0.0.0.0, every interface)")
    p.add_argument("--port", type=count(65535), default=None, help="port (dashboard: default 8031; --opcua: 4840)")
    p.add_argument("--token-file", metavar="FILE", help="a file holding the bearer token remote readers send")
    p.add_argument("--basic-auth-file", metavar="FILE", help="a file holding USER:PASSWORD (HTTP basic auth)")
    p.add_argument("--tls-cert", metavar="PEM", help="serve HTTPS with this certificate")
    p.add_argument("--tls-key", metavar="PEM", help="and this key")
    p.add_argument("--behind-proxy", action="store_true", help="a reverse proxy on this host terminates TLS")
    p.add_argument("--interval-days", type=count(3650), default=30,
                   help="days between rechecks for runs that name none (default 30)")
    _add_opcua(p)
    p.set_defaults(func="station.ui.cli.commands_fleet:cmd_serve")


def _add_opcua(p) -> None:
    """``station serve --opcua CONFIG``: the station as an OPC UA server for the line (issue 32,
    station/ui/opcua/); ``--init-pki`` and ``--add-user`` prepare it."""
    g = p.add_argument_group("OPC UA server (docs/opcua.md)")
    g.add_argument("--opcua", metavar="CONFIG", help="serve this cell's station over OPC UA (secured; no anonymous access)")
    g.add_argument("--simulated", action="store_true", help="with --opcua: runs on the simulated cell of CONFIG")
    g.add_argument("--seed", type=seed, default=None, help="simulated cell seed (default [simulation].seed, else 1)")
    g.add_argument("--time-scale", type=time_scale, default=0.0, help="simulated motion: 0 instant, 1 real time")
    g.add_argument("--db", default="runs.sqlite", help="run database (default runs.sqlite)")
    g.add_argument("--users", metavar="FILE", help="users and roles (password hashes or user certificates)")
    g.add_argument("--pki", metavar="DIR", help="the server's certificate, key and trust list (made by --init-pki)")
    g.add_argument("--cert", metavar="DER", help="the server's application certificate, if not in --pki")
    g.add_argument("--key", metavar="PEM", help="and its private key")
    g.add_argument("--trust", metavar="DIR", help="folder of trusted client certificates (default PKI/trusted)")
    g.add_argument("--init-pki", metavar="DIR", help="write the server's key and certificate and an empty trust list, then exit")
    g.add_argument("--add-user", metavar="NAME", help="add a user to --users (password from the terminal or stdin), then exit")
    g.add_argument("--role", choices=("observer", "operator"), default="observer", help="with --add-user")


def main(argv: Sequence[str] | None = None) -> int:
    words = list(sys.argv[1:] if argv is None else argv)
    # the handlers first: a SIGTERM while the modules load is an ABORTED run, not a death by signal;
    # the process itself (argv None: the station script) keeps them ignored after the outcome is
    # decided, until it has exited, so that its exit code is the outcome's (README, "Signals")
    session = words[:1] != [] and words[0] in SESSION_COMMANDS
    with catch_stop_signals(enabled=session, hold=session and argv is None):
        if words[:1] == ["tui"]:  # the full-screen UI owns the terminal: its streams stay as they are
            return _main(words)
        with guarded_streams():  # a closed stdout or stderr (| head) never stops or fails a command
            return _main(words)


def _main(words: list[str]) -> int:
    try:
        args = build_parser().parse_args(words)
    except UsageError as exc:
        print(exc, file=sys.stderr)
        if "--json" in words:
            print(json.dumps(_usage_json(str(exc), words)), flush=True)
        return int(Outcome.CONFIG_ERROR)
    route_library_logs()  # pymodbus' own log lines: the station's log, not the terminal
    try:
        with station_warnings():  # numpy's and scipy's warnings: the station's policy, not their two lines
            return int(_command(args.func)(args) or 0)
    except StationError as exc:
        print(f"station: error: {exc}", file=sys.stderr)
        if getattr(args, "json", False):  # a script still gets one JSON object with the reason
            # the mapping knows the drivers' errors: imported only when there is an error to map
            from station.cell.pipeline.outcomes import failure_summary

            print(json.dumps(failure_summary(exc, run_id=None, log_dir=".", db=getattr(args, "db", None)).to_json()))
        return exc.exit_code
    except OSError as exc:
        if exc.errno in DISK_ERRNOS:  # a full disk (also one of a report's files): not a bug
            text = (f"{exc.strerror or exc}{f': {exc.filename}' if exc.filename else ''}; free space "
                    f"on the disk (or make it writable) and repeat the command")
            print(f"station: error: {text}", file=sys.stderr)
            return _config_error_json(text, args)
        if exc.filename is not None:
            # A file the user named cannot be read or written: a usage error, not a bug.
            text = f"{exc.strerror or exc}: {exc.filename}; check the path"
            print(f"station: error: {text}", file=sys.stderr)
            return _config_error_json(text, args)
        return _internal_error(exc, args)
    except KeyboardInterrupt:
        print("station: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # a bug: keep the traceback for the report, not on the screen
        return _internal_error(exc, args)


def _config_error_json(message: str, args: argparse.Namespace) -> int:
    """CONFIG_ERROR's exit code, and with ``--json`` its one JSON object (a file the user named)."""
    if getattr(args, "json", False):
        from station.cell.pipeline.outcomes import failure_summary

        print(json.dumps(failure_summary(ConfigError(message), run_id=None, log_dir=".",
                                         db=getattr(args, "db", None)).to_json()))
    return int(Outcome.CONFIG_ERROR)


def _usage_json(message: str, words: Sequence[str] = ()) -> dict:
    """The one JSON object of a command line argparse refused; ``db``: the ``--db`` given, as in
    every other object (None when none was)."""
    from station.cell.pipeline.outcomes import failure_summary

    db = next((w.split("=", 1)[1] for w in words if w.startswith("--db=")), None)
    if db is None and "--db" in words[:-1]:
        db = words[list(words).index("--db") + 1]
    out: dict = failure_summary(ConfigError(message), run_id=None, log_dir=".", db=db).to_json()
    out.setdefault("db", db)
    return out


def _internal_error(exc: Exception, args: argparse.Namespace) -> int:
    from station.cell.pipeline.outcomes import failure_summary

    summary = failure_summary(exc, run_id=None, log_dir=".")
    failure = summary.failure
    if summary.outcome is not Outcome.INTERNAL_ERROR:  # a device's typed error (a driver's): its outcome
        hint = f"\n  what to do: {failure.hint}" if failure is not None and failure.hint else ""
        print(f"station: error: {failure.message if failure else exc}{hint}", file=sys.stderr)
    else:
        print(f"station: internal error {type(exc).__name__}: {exc}\n  the traceback is in "
              f"{failure.log_file if failure else '?'}; please report it with that file", file=sys.stderr)
    if getattr(args, "json", False):
        print(json.dumps(summary.to_json()))
    return int(summary.outcome)


if __name__ == "__main__":
    sys.exit(main())
