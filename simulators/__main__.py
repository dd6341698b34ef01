"""``python -m simulators``: run the simulated cell until SIGINT/SIGTERM.

Prints one JSON line ``{"controller": "127.0.0.1:PORT", "probe_head": "/dev/pts/N", "seed": N}``
once both endpoints accept traffic.

``--probe-protocol NAME`` picks the dialect the simulated probe unit speaks (keyence-dl-rs1a, the
default; station-ascii; mitutoyo-ga: :mod:`drivers.probe_dialects`), ``--baud``,
``--probe-bytesize`` and ``--probe-parity`` its own line settings (default: the dialect's factory
setting, e.g. 9600 8N1 for the DL-RS1A); a station at other settings gets garbled replies.
``--register-base N`` / ``--register-count N``: the simulated robot program hosts the register
window there and refuses every other address with exception 2 (default 0 and 128).

``--config CONFIG`` simulates the cell that configuration describes (its robot file and set-up,
body, head, limits and word order; the true errors from its ``[simulation]``:
:mod:`simulators.from_config`); ``--seed`` then overrides ``[simulation].seed`` (default 1).
``--write-config OUT.toml`` writes the station's configuration of the simulated cell (CONFIG with
``[devices]`` pointing at the simulators) before the JSON line, which then also names it as
``"config"``: ``station check OUT.toml``, ``station calibrate OUT.toml`` run against it. Log records (warnings and errors, e.g. pymodbus on malformed
frames) go to stderr without ever blocking: when nobody reads the pipe they are dropped and
counted (:mod:`simulators.stderr_log`), so the simulators keep serving.
"""

from __future__ import annotations

import argparse
import json
import logging
import signal
import sys
import threading
from pathlib import Path

from drivers.controller_map import MAP_VERSION, WordOrder
from drivers.probe_dialects import DIALECTS, check_line_settings
from drivers.probe_protocol import ProbeConfigError
from simulators import SimulatedCellServers, start_simulated_cell
from simulators.stderr_log import install as install_stderr_log


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m simulators", description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=None,
                    help="seed of the cell's true errors and noise (default 0; with --config: its "
                         "[simulation].seed, else 1)")
    ap.add_argument("--config", metavar="CONFIG", help="simulate the cell this configuration describes")
    ap.add_argument("--write-config", metavar="OUT", help="with --config: write the station's configuration of "
                    "the simulated cell here (CONFIG with [devices] pointing at the simulators)")
    ap.add_argument("--time-scale", type=float, default=0.0,
                    help="motion-time scale of the controller (0 = instant moves, 1 = real time)")
    ap.add_argument("--baud", type=int, default=None, help="the probe unit's baud rate (pacing; default: the dialect's factory setting, 9600 for "
                    "the DL-RS1A; with --config: its [devices].baudrate)")
    ap.add_argument("--probe-protocol", default=None, choices=sorted(DIALECTS),
                    help="dialect of the simulated probe unit (default keyence-dl-rs1a; with --config: its "
                         "[devices].probe_protocol)")
    ap.add_argument("--probe-bytesize", type=int, choices=(7, 8), default=None,
                    help="the probe unit's data bits (default: the dialect's factory setting)")
    ap.add_argument("--probe-parity", choices=("none", "even", "odd"), default=None,
                    help="the probe unit's parity (default: the dialect's factory setting)")
    ap.add_argument("--pace", action="store_true", help="hold probe replies for their serial transfer time")
    ap.add_argument("--host", default="127.0.0.1")
    ap.add_argument("--port", type=int, default=0, help="controller TCP port (0 = ephemeral)")
    ap.add_argument("--word-order", choices=[o.value for o in WordOrder], default=None,
                    help="word order of the controller's 32-bit values (default big; with --config: its "
                         "[devices].word_order)")
    ap.add_argument("--map-version", type=int, default=None,
                    help="register-map version the controller reports (another one plays a "
                         "robot program the driver does not know; not with --config)")
    ap.add_argument("--register-base", type=int, default=None,
                    help="first holding register of the robot program's window (default 0; 128 plays a UR "
                         "controller; with --config: its [devices].controller_register_base)")
    ap.add_argument("--register-count", type=int, default=None,
                    help="holding registers the controller hosts from the base; every other address is refused "
                         "with exception 2 (default 128; with --config: its [simulation].controller_register_count)")
    args = ap.parse_args(argv)
    if args.write_config and not args.config:
        ap.error("--write-config goes with --config")
    if args.config and (args.word_order or args.baud is not None or args.map_version is not None
                        or args.register_base is not None or args.register_count is not None):
        ap.error("with --config the word order, the baud rate and the register window are CONFIG's [devices] "
                 "(and [simulation].controller_register_count); leave out "
                 "--word-order, --baud, --map-version, --register-base and --register-count")
    if args.register_base is not None and not 0 <= args.register_base <= 65536 - 128:
        ap.error(f"--register-base {args.register_base}: the 128-register window must fit below 65536")
    if args.register_count is not None and not 1 <= args.register_count <= 65536:
        ap.error(f"--register-count {args.register_count}: 1 … 65536")
    probe_args = (args.probe_protocol, args.probe_bytesize, args.probe_parity)
    if args.config and any(a is not None for a in probe_args):
        ap.error("with --config the probe unit's dialect and line settings are CONFIG's [devices]; leave out "
                 "--probe-protocol, --probe-bytesize and --probe-parity")
    protocol = args.probe_protocol or "keyence-dl-rs1a"
    try:
        probe_line = check_line_settings(protocol, args.baud, args.probe_bytesize, args.probe_parity)
    except ProbeConfigError as exc:
        ap.error(str(exc))
    install_stderr_log(logging.WARNING)
    stop = threading.Event()

    def _on_signal(signum, _frame) -> None:
        stop.set()

    signal.signal(signal.SIGINT, _on_signal)
    signal.signal(signal.SIGTERM, _on_signal)
    extra: dict[str, str] = {}
    if args.config:
        servers = _start_from_config(args)
        if args.write_config:
            extra["config"] = args.write_config
    else:
        servers = start_simulated_cell(seed=0 if args.seed is None else args.seed, time_scale=args.time_scale,
                                       pace=args.pace, baudrate=probe_line.baudrate, probe_protocol=protocol,
                                       probe_bytesize=probe_line.bytesize, probe_parity=probe_line.parity,
                                       host=args.host, port=args.port, word_order=WordOrder(args.word_order or "big"),
                                       map_version=MAP_VERSION if args.map_version is None else args.map_version,
                                       register_base=args.register_base or 0,
                                       register_count=128 if args.register_count is None else args.register_count)
    try:
        extra["probe_protocol"] = servers.probe_server.dialect.name
        extra["probe_line"] = servers.probe_server.line.describe()
        extra["register_base"] = servers.controller_server.register_base
        print(json.dumps({**servers.endpoints(), **extra}), flush=True)
        while not stop.wait(0.5):
            pass
    finally:
        servers.stop()
    return 0


def _start_from_config(args: argparse.Namespace) -> SimulatedCellServers:
    """The simulators on the cell of ``--config`` (an invalid configuration: exit 2 with the
    station's message); ``--write-config`` written once they run."""
    from simulators.from_config import simulate_config
    from station.cell.config.cell_config import load_config  # the station's own reading of the file
    from station.errors import StationError

    try:
        cfg = load_config(args.config)
    except StationError as exc:
        print(f"python -m simulators: error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None
    try:
        rehearsal = simulate_config(cfg, seed=args.seed, source=args.config, time_scale=args.time_scale,
                                    pace=args.pace, host=args.host, port=args.port)
    except ValueError as exc:  # a [simulation] the cell cannot take (e.g. a step on a prismatic joint)
        print(f"python -m simulators: error: {args.config}: [simulation]: {exc}", file=sys.stderr)
        raise SystemExit(2) from None
    if args.write_config:
        try:
            Path(args.write_config).write_text(rehearsal.text, encoding="utf-8")
        except OSError as exc:
            rehearsal.stop()
            print(f"python -m simulators: error: --write-config {args.write_config}: {exc.strerror or exc}",
                  file=sys.stderr)
            raise SystemExit(2) from None
    return rehearsal.servers


if __name__ == "__main__":
    sys.exit(main())
