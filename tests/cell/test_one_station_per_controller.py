"""One station per controller (issue 33, item 4): two stations with separate run databases against
one simulated controller. The second is refused at the controller's claim - before it sends a
single command, before it opens the probe head - with the holder named (host, PID, since); the
first run goes on undisturbed and ends SUCCESS."""

from __future__ import annotations

import os
import re

import pytest

from simulators import start_simulated_cell
from simulators.reference_cell import cell_config_text
from station.cell.run.events import MeasurementRecorded
from station.cell.session.calibrate import CellRequest, run_calibration_session
from station.errors import Outcome


@pytest.mark.slow
def test_a_second_station_is_refused_before_any_command_and_the_first_ends_success(tmp_path):
    with start_simulated_cell(seed=1) as sim:
        cfg = tmp_path / "cell.toml"
        cfg.write_text(cell_config_text(sim, 1).replace("repeats = 4", "repeats = 1"))
        ctrl = sim.controller_server
        second: dict = {}

        def first_station(event):
            # in the middle of the first run (its 4th measurement recorded, its heartbeat thread
            # holding the claim), the second station starts: its own database, the same cell
            if isinstance(event, MeasurementRecorded) and event.index == 3 and not second:
                owner = ctrl.register("claim_owner")
                commands, requests = len(ctrl.command_log), ctrl.requests
                events: list = []
                summary = run_calibration_session(CellRequest(config=str(cfg), db=str(tmp_path / "second.sqlite")),
                                                  events.append)
                second.update(summary=summary, owner=owner, events=events,
                              commands=ctrl.command_log[commands:], requests=ctrl.requests - requests)

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
    assert second["commands"] == [] and second["requests"] == 3
    assert b.failure.message.startswith(f"controller {sim.controller_host}:{sim.controller_port}: ")
    # every command of the whole session carried the first station's token; it gave the controller
    # back at its orderly end
    assert second["owner"] != 0 and {token for _code, _seq, token in log} == {second["owner"]}
    assert owner_after == 0
