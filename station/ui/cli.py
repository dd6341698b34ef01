"""``station`` command line: the one parser. Readable output by default, ``--json`` for scripts.

Every error ends the program with its message and the exit code of its
:class:`~station.errors.Outcome`, never with a traceback; an unexpected error (a bug) writes its
traceback to a log file the message names and exits 1.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from station.cell.outcomes import write_traceback
from station.errors import Outcome, StationError
from station.ui.commands_cell import add_cell_commands
from station.ui.commands_core import _add_prefs, _add_robot, cmd_analyze, cmd_identify, cmd_predict, cmd_study


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="station", description="Robot calibration station")
    sub = ap.add_subparsers(dest="command", required=True)

    p = sub.add_parser("analyze", help="identifiability of a robot's parameters")
    _add_robot(p)
    p.add_argument("--kind", choices=["pose", "position", "distance"], default="pose")
    p.add_argument("--planar", action="store_true", help="all poses in one plane normal to z")
    p.add_argument("--poses", type=int, default=30)
    p.add_argument("--distances", type=int, default=200)
    p.add_argument("--joints", help="joint file (CSV with units) instead of random poses")
    p.add_argument("--seed", type=int, default=0)
    _add_prefs(p)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_analyze)

    p = sub.add_parser("identify", help="identify a robot from a measurement file")
    p.add_argument("data", help="measurement CSV (docs/data-files.md)")
    _add_robot(p)
    p.add_argument("--objective", choices=["pose", "position", "distance"])
    p.add_argument("--sigma-position", type=float, default=15.0, help="µm (default 15)")
    p.add_argument("--sigma-angle", type=float, default=20.0, help="arc seconds (default 20)")
    p.add_argument("--output", "-o", help="write the identified robot file here")
    _add_prefs(p)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_identify)

    p = sub.add_parser("predict", help="poses of a model for given joint values")
    p.add_argument("model", help="built-in robot name or robot file")
    p.add_argument("joints", help="joint CSV with units")
    p.add_argument("--base", action="store_true", help="robot base frame (leave out the set-up R)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_predict)

    p = sub.add_parser("study", help="re-run the chapter's simulation studies (§7.5)")
    _add_robot(p)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--sets", type=int, default=1000, help="Monte Carlo data sets for pose studies")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_study)

    add_cell_commands(sub)
    return ap


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except StationError as exc:
        print(f"station: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except OSError as exc:
        if exc.filename is not None:
            # A file the user named cannot be read or written: a usage error, not a bug.
            print(f"station: error: {exc.strerror or exc}: {exc.filename}; check the path", file=sys.stderr)
            return int(Outcome.CONFIG_ERROR)
        return _internal_error(exc)
    except KeyboardInterrupt:
        print("station: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # a bug: keep the traceback for the report, not on the screen
        return _internal_error(exc)


def _internal_error(exc: Exception) -> int:
    log = write_traceback(exc)
    print(f"station: internal error {type(exc).__name__}: {exc}\n  the traceback is in {log}; "
          f"please report it with that file", file=sys.stderr)
    return int(Outcome.INTERNAL_ERROR)


if __name__ == "__main__":
    sys.exit(main())
