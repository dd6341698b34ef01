"""``station recheck``: a short accuracy check against the last calibration (issue 13).

Progress on stderr, one JSON object on stdout with ``--json``; the exit code is the recheck's
:class:`~station.errors.Outcome`: 0 within tolerance, 12 drifted (recalibrate), 13 the
measurement is not trustworthy, or the failure's outcome.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import TextIO

from station.cell.recheck.measure import RecheckOptions, RecheckSummary
from station.cell.recheck.session import run_recheck_session
from station.cell.records.summary import RunSummary
from station.cell.run.runcontrol import RunControl
from station.cell.session.calibrate import CellRequest
from station.errors import ConfigError
from station.ui.cli.commands_cell import (
    as_stopped,
    print_summary,
    progress_printer,
    result_stream,
    safe_stop_on_signals,
    stopped_before_start,
)
from station.ui.simulated_cell import load_cell


def print_recheck(s: RecheckSummary, stream: TextIO) -> None:
    """The human-readable end of a recheck."""
    b, r = s.baseline, s.result
    print(f"\nrun {s.run_id}: recheck against run {b.run_id} ({b.created_utc[:19]} UTC): {s.outcome.name} "
          f"(exit code {s.exit_code})", file=stream)
    if r is None:
        return
    base = f"baseline accuracy {b.accuracy_um:.1f} µm"
    if b.after_rms_um is not None:
        base += f" (its verification after correction: RMS {b.after_rms_um:.1f} µm)"
    print(f"  {base}", file=stream)
    if r.rms_um is not None:
        print(f"  drift over {r.n_valid}/{r.n_planned} poses: RMS {r.rms_um:.1f} µm (tolerance {r.tolerances.position_um:.1f}), "
              f"max {r.max_um:.1f} µm; RMS {r.rms_arcsec:.1f}″, max {r.max_arcsec:.1f}″", file=stream)
    for p in r.poses:
        print(f"    {p.point_id:8s} elbow {p.elbow:+d}  {p.position_um:8.1f} µm  {p.angle_arcsec:7.1f}″", file=stream)
    if r.repeat_um is not None:
        print(f"  repeated first pose: {r.repeat_um:.1f} µm (at most {r.tolerances.repeat_um:.1f})", file=stream)
    if r.parameters:
        print("  drift of the parameters since the baseline (Δ ± σ):", file=stream)
        for q in r.parameters:
            flag = "  MOVED" if q.moved else ""
            print(f"    {q.label:28s} {q.delta:+9.1f} ± {q.sigma:6.1f} {q.unit}  (tolerance {q.tolerance:.1f}){flag}",
                  file=stream)
    if s.warmup:
        w = s.warmup
        print(f"  warm-up: {w.get('cycles')} cycles, {'converged' if w.get('converged') else 'NOT converged'}",
              file=stream)
    for reason in r.reasons:
        print(f"  {reason}", file=stream)
    if s.outcome.name == "DRIFTED":
        print("  what to do: recalibrate ('station calibrate CONFIG')", file=stream)
    elif s.outcome.name == "RECHECK_UNTRUSTED":
        print("  what to do: check the probe head and the body, warm the robot up ([warmup]), and recheck", file=stream)


def cmd_recheck(args: argparse.Namespace) -> int:
    request = CellRequest(config=args.config, simulated=args.simulated, seed=args.seed,
                          time_scale=args.time_scale, db=args.db,
                          resume=args.resume)
    if not request.simulated and not request.config:
        raise ConfigError("give a configuration file, or --simulated for the built-in simulated cell")
    if args.poses is not None and not 3 <= args.poses <= 100:
        raise ConfigError(f"--poses {args.poses}: give 3 … 100 poses")
    control = RunControl()
    summary: RunSummary | RecheckSummary | None = stopped_before_start(request)
    if summary is None:
        with safe_stop_on_signals(control):
            summary = run_recheck_session(request, progress_printer(sys.stderr), control,
                                          RecheckOptions(baseline=args.baseline, poses=args.poses), load=load_cell)
    if isinstance(summary, RunSummary):
        summary = as_stopped(summary, args, verb="recheck")  # a signal as a signal, the real resume command
        print_summary(summary, result_stream(args))
        out = summary.to_json()
        if summary.failure is not None and summary.run_id is not None:
            out["kind"] = "recheck"
    else:
        print_recheck(summary, result_stream(args))
        out = summary.to_json()
    if args.json:
        print(json.dumps(out), flush=True)
    return summary.exit_code


__all__ = ["cmd_recheck", "print_recheck"]
