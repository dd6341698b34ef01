"""``station serve --opcua CONFIG``, ``--init-pki DIR`` and ``--add-user NAME``: the command
line's arguments to the OPC UA server (the parser is station/ui/cli/main.py's)."""

from __future__ import annotations

import argparse
import getpass
import socket
import sys

from station.errors import ConfigError

#: the station's application URI: the server certificate names it (subjectAltName), the server announces it
URI_PREFIX = "urn:robot-calibration-station:"


def cmd_serve_opcua(args: argparse.Namespace) -> int:
    from station.ui.opcua import security

    if args.init_pki:
        host = args.host if args.host not in (None, "0.0.0.0", "::") else socket.gethostname()
        cert = security.init_pki(args.init_pki, URI_PREFIX + host, host)
        print(f"server certificate {cert} (application URI {URI_PREFIX + host}); copy it to each client's trust list.\n"
              f"Trusted client certificates go in {args.init_pki}/trusted/. Then: station serve --opcua CONFIG "
              f"--pki {args.init_pki} --users USERS.toml", file=sys.stderr)
        return 0
    if args.add_user:
        if not args.users:
            raise ConfigError("--add-user needs --users FILE: the file the user is added to")
        password = _password(args.add_user)
        security.add_user(args.users, args.add_user, args.role, password)
        print(f"{args.users}: user {args.add_user!r} ({args.role}) added (scrypt hash)", file=sys.stderr)
        return 0
    if not args.users:
        raise ConfigError("--opcua needs --users FILE: anonymous access is off (docs/opcua.md, 'Security set-up')")
    from station.ui.opcua.server import DEFAULT_PORT, ServeOptions, run

    opts = ServeOptions(config=args.opcua, users=args.users, pki=args.pki, cert=args.cert, key=args.key,
                        trust=args.trust, host=args.host or "0.0.0.0", port=args.port or DEFAULT_PORT,
                        simulated=args.simulated, seed=args.seed, time_scale=args.time_scale, db=args.db)
    return run(opts)


def _password(name: str) -> str:
    """From the terminal (asked twice), or the first line of stdin (a script)."""
    if sys.stdin.isatty():
        first = getpass.getpass(f"password for {name}: ")
        if getpass.getpass("again: ") != first:
            raise ConfigError("the two passwords differ; nothing was written")
        return first
    line = sys.stdin.readline().rstrip("\r\n")
    if not line:
        raise ConfigError("no password on stdin: give it as the first line (or run at a terminal)")
    return line
