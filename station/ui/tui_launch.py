"""``station tui``: the operator UI over the same pipeline as ``station calibrate``.

The UI only receives a ``start_run(emit, control)`` callable; device handling stays here, in
the worker thread the UI runs it in.
"""

from __future__ import annotations

from contextlib import ExitStack

from station.errors import ConfigError


def make_start_run(args):
    """The blocking calibration the UI runs in its worker thread."""

    def start_run(emit, control) -> dict:
        from station.cell.pipeline import Options, run_calibration
        from station.ui.commands_cell import HINTS, open_devices, outcome_for, simulated_config_text
        from station.cell.config import load_config, parse_text
        from station.cell.events import RunFailed
        from station.cell.rundb import RunDB

        with ExitStack() as stack:
            truth = None
            if args.simulated:
                from simulators import start_simulated_cell

                servers = start_simulated_cell(seed=args.seed)
                stack.callback(servers.stop)
                cfg = parse_text(simulated_config_text(servers, args.seed), "<simulated cell>")
                truth = servers.cell.truth
            else:
                if not args.config:
                    raise ConfigError("give a configuration file, or --simulated")
                cfg = load_config(args.config)
            db = stack.enter_context(RunDB(args.db))
            probe, ctrl = open_devices(cfg, stack)
            try:
                summary = run_calibration(cfg, probe, ctrl, db, emit, control,
                                          Options(oracle_truth=truth))
            except Exception as exc:
                emit(RunFailed(type(exc).__name__, str(exc), HINTS.get(type(exc).__name__, "")))
                summary = {"outcome": type(exc).__name__, "exit_code": int(outcome_for(exc))}
                return summary
            from station.cell.pipeline import Outcome

            summary["exit_code"] = int(Outcome[summary["outcome"]])
            return summary

    return start_run


def launch(args) -> int:
    from station.ui.tui import StationApp

    title = "Calibration station — " + ("simulated cell" if args.simulated else str(args.config))
    app = StationApp(make_start_run(args), title=title)
    app.run()
    return int(app.return_code or 0)
