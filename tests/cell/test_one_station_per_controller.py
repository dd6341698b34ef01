"""One station per controller (issue 33, item 4): two stations with separate run databases against
one simulated controller. The second is refused at the controller's claim - before it sends a
single command, before it opens the probe head - with the holder named (host, PID, since); the
first run goes on undisturbed and ends SUCCESS."""

from __future__ import annotations

import os
import re
import socket
import struct
import threading

import pytest

from simulators import start_simulated_cell
from simulators.reference_cell import cell_config_text
from station.cell.run.facts.events import MeasurementRecorded
from station.cell.session.calibrate import CellRequest, run_calibration_session
from station.errors import Outcome


class ModbusTcpRelay:
    """A loopback relay in front of the simulated controller that records the Modbus TCP requests
    (function code, address, count) of the one station that connects through it: the controller
    serves both stations, and only the relay can tell whose request a request was (the first
    station's heartbeat thread keeps writing while the second station tries)."""

    def __init__(self, host: str, port: int) -> None:
        self.target = (host, port)
        self.requests: list[tuple[int, int, int]] = []
        self._listener = socket.create_server(("127.0.0.1", 0))
        self.port = self._listener.getsockname()[1]
        self._threads: list[threading.Thread] = []
        self._sockets: list[socket.socket] = []  # the relay's ends of the connection, shut down by close()
        self._spawn(self._accept)

    def _spawn(self, target, *args) -> None:
        t = threading.Thread(target=target, args=args, daemon=True)
        t.start()
        self._threads.append(t)

    def _accept(self) -> None:
        try:
            client, _ = self._listener.accept()
        except OSError:
            return  # closed before anyone connected
        server = socket.create_connection(self.target)
        self._sockets += [client, server]
        self._spawn(self._pump, client, server, True)
        self._spawn(self._pump, server, client, False)

    def _pump(self, src: socket.socket, dst: socket.socket, requests: bool) -> None:
        pending = b""
        try:
            while data := src.recv(4096):
                dst.sendall(data)
                if not requests:
                    continue
                pending += data
                # MBAP header (Modbus Messaging on TCP/IP Implementation Guide V1.0b, section 3.1.3):
                # transaction id, protocol id, length (of unit id + PDU), unit id; then the PDU
                while len(pending) >= 7 and len(pending) >= 6 + struct.unpack(">H", pending[4:6])[0]:
                    size = 6 + struct.unpack(">H", pending[4:6])[0]
                    pdu, pending = pending[7:size], pending[size:]
                    address, count = struct.unpack(">HH", pdu[1:5]) if len(pdu) >= 5 else (-1, -1)
                    self.requests.append((pdu[0], address, count))
        except OSError:
            pass  # one side closed the connection (the station's close, or the relay's): the pump ends
        finally:
            for s in (src, dst):
                try:
                    s.shutdown(socket.SHUT_RDWR)
                except OSError:
                    pass  # already shut down by the other pump

    def close(self) -> None:
        """End the relay once the station's session has returned: every request it sent was answered,
        so the pumps have forwarded it. The relay shuts its own ends down (the station may close its
        connection later, or leave that to its client's clean-up: CI once saw the pumps still waiting on
        it after 60 s), then waits for the pumps, which append a request after forwarding it, so the
        list read next is whole."""
        for s in (self._listener, *self._sockets):
            try:
                s.shutdown(socket.SHUT_RDWR)  # wakes a blocked accept() or recv(); close() alone does not
            except OSError:
                pass  # not connected, or already shut down by a pump
        self._listener.close()
        for t in self._threads:
            t.join(timeout=60)  # a hang guard only: the shutdown ends every pump at once
        assert not any(t.is_alive() for t in self._threads), "the relay's pumps did not end"
        for s in self._sockets:
            s.close()


@pytest.mark.slow
def test_a_second_station_is_refused_before_any_command_and_the_first_ends_success(tmp_path):
    with start_simulated_cell(seed=1) as sim:
        cfg = tmp_path / "cell.toml"
        # one verification cycle: the claim and the first run's outcome are compared, not its accuracy (42)
        cfg.write_text(cell_config_text(sim, 1).replace("repeats = 4", "repeats = 1")
                       .replace("verification_cycles = 5", "verification_cycles = 1"))
        ctrl = sim.controller_server
        second: dict = {}

        def first_station(event):
            # in the middle of the first run (its 4th measurement recorded, its heartbeat thread
            # holding the claim), the second station starts: its own database, the same cell
            if isinstance(event, MeasurementRecorded) and event.index == 3 and not second:
                owner = ctrl.register("claim_owner")
                commands = len(ctrl.command_log)
                events: list = []
                relay = ModbusTcpRelay(sim.controller_host, sim.controller_port)
                cfg2 = tmp_path / "cell-second.toml"
                cfg2.write_text(cfg.read_text().replace(f":{sim.controller_port}\"", f":{relay.port}\""))
                try:
                    summary = run_calibration_session(CellRequest(config=str(cfg2), db=str(tmp_path / "second.sqlite")),
                                                      events.append)
                finally:
                    relay.close()
                second.update(summary=summary, owner=owner, events=events, relay_port=relay.port,
                              commands=ctrl.command_log[commands:], requests=list(relay.requests))

        first = run_calibration_session(CellRequest(config=str(cfg), db=str(tmp_path / "first.sqlite")),
                                        first_station)
        log = list(ctrl.command_log)
        owner_after = ctrl.register("claim_owner")

    assert first.outcome is Outcome.SUCCESS, first.failure  # the first run, undisturbed
    b = second["summary"]
    assert b.outcome is Outcome.DEVICE_FAULT and b.exit_code == 7
    assert b.failure.error_type == "ControllerHeld" and b.failure.device == "controller" and not b.failure.link
    # the holder named in the message and in the hint: this process, on the loopback interface
    since = r"since 20\d\d-\d\d-\d\d \d\d:\d\d:\d\d UTC"
    for text in (b.failure.message, b.failure.hint):
        assert re.search(rf"host 127\.0\.0\.1, PID {os.getpid()}, {since}", text), text
    assert "watchdog" in b.failure.hint and "nothing to clear by hand" in b.failure.hint
    # nothing of the second station reached the controller's command block: it read the window and
    # the holder's name (3 reads) and wrote nothing, not even a heartbeat; the controller is
    # claimed before the probe head is opened, so it never opened the probe head the first run reads
    assert second["commands"] == [] and len(second["requests"]) == 3, second["requests"]
    assert {fc for fc, _address, _count in second["requests"]} == {3}  # read holding registers only
    assert b.failure.message.startswith(f"controller {sim.controller_host}:{second['relay_port']}: ")
    # every command of the whole session carried the first station's token; it gave the controller
    # back at its orderly end
    assert second["owner"] != 0 and {token for _code, _seq, token in log} == {second["owner"]}
    assert owner_after == 0
