"""First contact with wrong or missing hardware: a typed device fault (exit 7) with a message that
says what to check, never a traceback — over the real transports (pty, TCP)."""

from __future__ import annotations

import socket
import threading
from contextlib import closing

import pytest

from drivers.controller_map import REG
from simulators import start_simulated_cell
from simulators.probe_head_sim import FaultKind
from simulators.reference_cell import cell_config_text
from station.cell.config.cell_config import parse_text
from station.cell.session.calibrate import CellRequest, check_cell, run_calibration_session
from station.errors import Outcome


@pytest.fixture()
def sim():
    with start_simulated_cell(seed=5) as servers:
        yield servers


def _cfg(sim, **replace):
    text = cell_config_text(sim, 5)
    for old, new in replace.items():
        text = text.replace(old, new)
    return parse_text(text)


def _free_port() -> int:
    with closing(socket.socket()) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_closed_controller_port(sim):
    report = check_cell(_cfg(sim, **{f":{sim.controller_port}": f":{_free_port()}"}))
    assert report.outcome is Outcome.DEVICE_FAULT
    text = "\n".join(report.lines)
    assert "controller" in text and "FAILED" in text and "what to do" in text


def test_a_peer_that_does_not_speak_modbus(sim):
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen()
    port = server.getsockname()[1]

    def answer_http():
        while True:
            try:
                conn, _ = server.accept()
            except OSError:
                return
            with conn:
                conn.settimeout(2.0)
                try:
                    conn.recv(256)
                    conn.sendall(b"HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\n\r\n")
                except OSError:  # the station already hung up on the non-Modbus answer: that is the test
                    pass

    t = threading.Thread(target=answer_http, daemon=True)
    t.start()
    try:
        report = check_cell(_cfg(sim, **{f":{sim.controller_port}": f":{port}"}))
    finally:
        server.close()
    assert report.outcome is Outcome.DEVICE_FAULT, report.lines
    assert "Traceback" not in "\n".join(report.lines)


def test_modbus_exception_on_the_first_read(sim, tmp_path):
    first = min(entry.address for entry in REG.values())
    sim.controller_server.inject_modbus_exception(first, code=2, times=50)
    cfg_file = tmp_path / "cell.toml"
    cfg_file.write_text(cell_config_text(sim, 5))
    summary = run_calibration_session(CellRequest(config=str(cfg_file), db=str(tmp_path / "r.sqlite")),
                                      lambda e: None)
    assert summary.outcome is Outcome.DEVICE_FAULT and summary.exit_code == 7, summary.failure
    assert "Modbus exception" in summary.failure.message
    assert "map version" in summary.failure.message or "map version" in summary.failure.hint


def test_garbage_frames_from_the_probe_interface(sim):
    # a wrong baud rate shows as garbled frames on every reply
    sim.probe_server.faults.inject(FaultKind.GARBLE, count=50)
    report = check_cell(_cfg(sim))
    assert report.outcome is Outcome.DEVICE_FAULT
    text = "\n".join(report.lines)
    assert "probe head" in text and "FAILED" in text and "baud" in text


def test_a_directory_instead_of_a_serial_port(sim, tmp_path):
    report = check_cell(_cfg(sim, **{f'"{sim.probe_port}"': f'"{tmp_path}"'}))
    assert report.outcome is Outcome.DEVICE_FAULT
    assert "cannot open probe unit" in "\n".join(report.lines)
