"""``python -m simulators`` as a subprocess: serving never depends on its stderr being read."""

from __future__ import annotations

import json
import os
import signal
import socket
import struct
import subprocess
import sys
from pathlib import Path

import pytest

from drivers.controller import ModbusController
from drivers.controller_errors import MapVersionError

ROOT = Path(__file__).resolve().parents[2]


def _start(*args: str) -> tuple[subprocess.Popen, str, int]:
    p = subprocess.Popen([sys.executable, "-m", "simulators", *args], cwd=ROOT,
                         stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         env={**os.environ, "PYTHONUNBUFFERED": "1"})
    line = p.stdout.readline()  # readiness: printed once both endpoints accept traffic
    if not line:
        p.kill()
        raise AssertionError(f"simulator did not start: {p.stderr.read().decode()[-2000:]}")
    host, port = json.loads(line)["controller"].rsplit(":", 1)
    return p, host, int(port)


def _stop(p: subprocess.Popen) -> int:
    p.send_signal(signal.SIGTERM)
    try:
        return p.wait(timeout=20)
    except subprocess.TimeoutExpired:
        p.kill()
        raise AssertionError("simulator process did not stop on SIGTERM") from None


def test_serves_on_while_its_stderr_pipe_is_never_read():
    p, host, port = _start()
    try:
        # FC 8 (diagnostics) with an unknown sub-function: pymodbus answers exception 4 and logs
        # an ERROR with a traceback (about 0.6 KB) for each; 400 of them are several times a
        # pipe's 64 KiB.
        with socket.create_connection((host, port), timeout=10) as s:
            for tid in range(1, 401):
                pdu = b"\x08\x00\x99\x00\x00"
                s.sendall(struct.pack(">HHHB", tid, 0, len(pdu) + 1, 1) + pdu)
                reply = s.recv(260)
                assert reply[7] == 0x88  # exception response: the server answered
        c = ModbusController(host, port, heartbeat_period=None, timeout=2.0)
        c.connect()
        assert c.status().ready
        c.close()
    finally:
        assert _stop(p) == 0


def test_map_version_option_is_refused_by_the_driver():
    p, host, port = _start("--map-version", "7")
    try:
        c = ModbusController(host, port, heartbeat_period=None, timeout=2.0)
        with pytest.raises(MapVersionError) as info:
            c.connect()
        assert (info.value.found, info.value.supported) == (7, (3,))
        c.close()
    finally:
        assert _stop(p) == 0
