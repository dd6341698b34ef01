"""The OPC UA tests' fixtures: one PKI per test session (made by ``station serve --init-pki``),
and ``station serve --opcua examples/scara600/cell.toml --simulated`` as a real process."""

from __future__ import annotations

import shutil
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import pytest

from station.ui.cli.main import main
from station.ui.opcua.security import add_user, make_certificate
from tests.opcua.clients import CLIENT_URI, CONFIG, PASSWORDS


@dataclass(frozen=True)
class Pki:
    root: Path
    users: Path
    client_cert: Path  # trusted
    client_key: Path
    stranger_cert: Path  # a client certificate the station does not trust
    stranger_key: Path
    user_cert: Path  # an X.509 user (role observer)
    user_key: Path


@pytest.fixture(scope="session")
def pki(tmp_path_factory) -> Pki:
    """The server's key and certificate through the command line's --init-pki, a trusted and an
    untrusted client, and the users file: an operator, an observer, an X.509 observer."""
    root = tmp_path_factory.mktemp("pki")
    assert main(["serve", "--init-pki", str(root / "server"), "--host", socket.gethostname()]) == 0
    host = socket.gethostname()
    make_certificate(root / "client" / "cert.der", root / "client" / "key.pem", CLIENT_URI, host, server=False)
    make_certificate(root / "stranger" / "cert.der", root / "stranger" / "key.pem", CLIENT_URI, host, server=False)
    make_certificate(root / "user" / "cert.der", root / "user" / "key.pem", "urn:station-test:user", host,
                     server=False, common_name="plc-observer")
    shutil.copy(root / "client" / "cert.der", root / "server" / "trusted" / "line-client.der")
    users = root / "users.toml"
    add_user(users, "line", "operator", PASSWORDS["line"])
    add_user(users, "watch", "observer", PASSWORDS["watch"])
    with users.open("a", encoding="utf-8") as f:
        f.write(f'\n[[user]]\nname = "plc-observer"\nrole = "observer"\ncertificate = "{root / "user" / "cert.der"}"\n')
    return Pki(root, users, root / "client" / "cert.der", root / "client" / "key.pem", root / "stranger" / "cert.der",
               root / "stranger" / "key.pem", root / "user" / "cert.der", root / "user" / "key.pem")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@dataclass(frozen=True)
class Served:
    url: str
    process: subprocess.Popen
    log: Path
    db: Path


@contextmanager
def serving(pki: Pki, work: Path, db: Path, config: Path = CONFIG) -> Iterator[Served]:
    """``station serve --opcua CONFIG --simulated`` on run database ``db`` in its own process
    (working in ``work``), until the block ends; ``config``: another cell file than CONFIG."""
    port = free_port()
    log = work / "serve.log"
    cmd = [sys.executable, "-m", "station.ui.cli.main", "serve", "--opcua", str(config), "--simulated",
           "--pki", str(pki.root / "server"), "--users", str(pki.users), "--host", "127.0.0.1", "--port", str(port),
           "--db", str(db)]
    with log.open("w") as out:
        proc = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, cwd=work)
    try:
        deadline = time.monotonic() + 90
        while "OPC UA server on" not in log.read_text():
            if proc.poll() is not None:
                pytest.fail(f"station serve --opcua ended with {proc.returncode}:\n{log.read_text()}")
            if time.monotonic() > deadline:
                pytest.fail(f"station serve --opcua did not come up:\n{log.read_text()}")
            time.sleep(0.1)
        yield Served(f"opc.tcp://127.0.0.1:{port}/station/", proc, log, db)
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


@pytest.fixture(scope="module")
def served(pki: Pki, tmp_path_factory) -> Iterator[Served]:
    """``station serve --opcua CONFIG --simulated`` in its own process, until the module's end."""
    work = tmp_path_factory.mktemp("serve")
    with serving(pki, work, work / "runs.sqlite") as s:
        yield s
