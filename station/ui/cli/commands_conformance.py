"""``station conformance CONFIG [--json]``: check the robot program against the register map and
the handshake (``docs/robot-program.md``). The kit is :mod:`station.cell.conformance.suite`; the
parser is :mod:`station.ui.cli.main`. The exit code is 0 when every requirement passed, 7 otherwise
(or the outcome of what stopped it: 2 for the configuration, 7 for an unreachable controller).
"""

from __future__ import annotations

import argparse
import json
import sys

from station.cell.config.cell_config import load_config
from station.cell.conformance.suite import run_conformance
from station.cell.pipeline.outcomes import failure_summary, hint_for
from station.errors import StationError


def cmd_conformance(args: argparse.Namespace) -> int:
    cfg = load_config(args.config)

    def progress(message: str) -> None:
        print(f"[conformance] {message}", file=sys.stderr, flush=True)

    try:
        report = run_conformance(cfg, progress)
    except StationError:
        raise
    except Exception as exc:  # the controller cannot be reached or answers nonsense: its outcome, no traceback
        summary = failure_summary(exc, run_id=None, log_dir=".")
        print(f"station: error: {exc}", file=sys.stderr)
        if hint := hint_for(exc):
            print(f"  what to do: {hint}", file=sys.stderr)
        if args.json:
            print(json.dumps(summary.to_json()))
        return summary.exit_code
    if args.json:
        print(json.dumps(report.to_json()))
    else:
        print("\n".join(report.describe()))
    return int(report.outcome)
