"""Real devices at first contact (issue 17's "done when"): the example cell with a Keyence DL-RS1A
at its factory line settings (9600 8N1) and a robot program in a UR-style window of 128 registers
(128 … 255) rehearses end to end with every Modbus request inside the window; 'station check'
passes against a unit that answers only its manual's commands; the second vendor's dialect
(Mitutoyo) rehearses end to end; and what does not match - another dialect, another baud rate,
another register base, a line setting the unit does not offer - is refused before any motion
with what to set."""

from __future__ import annotations

import json
import subprocess
import sys
from contextlib import ExitStack
from pathlib import Path

import pytest

from simulators.judge import CellJudge
from station.cell.config.cell_config import load_config
from station.ui.cli.main import main
from tests.short_plan import example_short

ROOT = Path(__file__).resolve().parents[1]
CELL = ROOT / "examples" / "scara600" / "cell.toml"


def test_the_example_cell_is_a_dl_rs1a_at_9600_8n1_and_a_window_at_128():
    d = load_config(CELL).devices
    assert (d.probe_protocol, d.baudrate, d.probe_bytesize, d.probe_parity) == ("keyence-dl-rs1a", 9600, 8, "none")
    assert d.controller_register_base == 128


def test_a_rehearsal_of_the_example_cell_stays_inside_registers_128_to_255(tmp_path):
    from simulators.from_config import simulate_config
    from station.cell.pipeline.calibration import Options, run_calibration
    from station.cell.records.rundb import RunDB
    from station.cell.session.calibrate import open_cell
    from station.errors import Outcome

    # the example with one visit per identification pose and one verification cycle: every kind of
    # request (moves, joint reads, the table's upload and read back) is made on the shorter run (42)
    cell = example_short(CELL, tmp_path)
    with ExitStack() as stack:
        rehearsal = stack.enter_context(simulate_config(load_config(cell), seed=1, source=cell))
        server = rehearsal.servers.controller_server
        assert (server.register_base, server.register_count) == (128, 128)  # [simulation] controller_register_count
        db = stack.enter_context(RunDB(tmp_path / "runs.sqlite"))
        devices = open_cell(rehearsal.cfg, stack)
        summary = run_calibration(rehearsal.cfg, devices.probe, devices.controller, db, lambda e: None,
                                  options=Options(judge=CellJudge(rehearsal.servers.cell.truth)))
        log = list(server.requests_log)
    assert summary.outcome is Outcome.SUCCESS and summary.gain >= 20.0
    assert len(log) > 1000
    outside = [(f, a, n) for f, a, n in log if not (128 <= a and a + n <= 256)]
    assert not outside, outside[:5]
    assert {f for f, _a, _n in log} <= {3, 4, 6, 16}


def test_station_check_passes_against_a_dl_rs1a_that_answers_only_its_manual(tmp_path):
    out = tmp_path / "sim.toml"
    sim = subprocess.Popen([sys.executable, "-m", "simulators", "--config", str(CELL), "--write-config", str(out)],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        line = json.loads(sim.stdout.readline())  # printed once both endpoints accept traffic
        assert line["probe_protocol"] == "keyence-dl-rs1a" and line["probe_line"] == "9600 8N1"
        assert line["register_base"] == 128
        check = subprocess.run([sys.executable, "-m", "station.ui.cli.main", "check", str(out)], capture_output=True,
                               text=True, cwd=ROOT, timeout=120)
    finally:
        sim.terminate()
        sim.wait(timeout=30)
    assert check.returncode == 0, check.stdout + check.stderr
    text = check.stdout + check.stderr
    assert "DL-RS1A" in text and "base 128" in text


@pytest.mark.slow  # an end-to-end session: the slow tier (README), run by CI
def test_the_mitutoyo_dialect_rehearses_end_to_end(tmp_path, capsys):
    cell = tmp_path / "cell.toml"
    for f in CELL.parent.iterdir():  # the example cell's files, its probe interface a Mitutoyo one
        (tmp_path / f.name).write_bytes(f.read_bytes())
    cell.write_text(CELL.read_text(encoding="utf-8").replace('probe_protocol = "keyence-dl-rs1a"',
                                                             'probe_protocol = "mitutoyo-ga"'), encoding="utf-8")
    code = main(["calibrate", "--simulated", str(cell), "--json", "--db", str(tmp_path / "runs.sqlite")])
    out = json.loads(capsys.readouterr().out)
    assert code == 0, out.get("failure")
    assert out["gain"] >= 20.0 and 0.7 <= out["after_vs_oracle"] <= 1.2, out["after_vs_oracle"]


@pytest.fixture(scope="module")
def builtin_sim():
    """The built-in simulated cell: a DL-RS1A at 9600 8N1, the robot program at base 0."""
    from simulators import start_simulated_cell
    from simulators.reference_cell import cell_config_text

    with start_simulated_cell(seed=1) as srv:
        yield cell_config_text(srv, 1)


@pytest.mark.parametrize("change, code, says", [
    ('probe_protocol = "keyence-dl-rs1a"', 7, "probe_protocol"),      # another dialect's unit answers
    ("baudrate = 9600", 7, "baud"),                                    # the unit runs at another rate
    ("controller_register_base = 0", 7, "controller_register_base"),  # the window is elsewhere
    ("baudrate = 9600", 2, "offers"),                                  # the DL-RS1A has no 57600
], ids=["dialect", "baud", "register-base", "line-not-offered"])
def test_what_does_not_match_is_refused_before_any_motion(builtin_sim, tmp_path, capsys, change, code, says):
    replacement = {"probe_protocol": 'probe_protocol = "station-ascii"', "baud": "baudrate = 19200",
                   "controller_register_base": "controller_register_base = 256", "offers": "baudrate = 57600"}[says]
    assert change in builtin_sim
    path = tmp_path / "cell.toml"
    path.write_text(builtin_sim.replace(change, replacement), encoding="utf-8")
    assert main(["check", str(path)]) == code
    captured = capsys.readouterr()
    assert says in (captured.out + captured.err)


def test_simulated_cells_allow_for_a_loaded_machine_and_a_real_cell_keeps_its_deadlines(builtin_sim):
    """The simulators share the CPU with the station: their cells widen the station's device
    deadlines (and the session says so); a real cell's configuration keeps what it gives."""
    from simulators.from_config import SIMULATOR_CONTROLLER_DEADLINE_S, station_config_text
    from station.cell.config.cell_config import parse_text

    sim = parse_text(builtin_sim).devices
    assert sim.controller_timeout_s >= SIMULATOR_CONTROLLER_DEADLINE_S
    assert sim.controller_link_timeout_s >= SIMULATOR_CONTROLLER_DEADLINE_S
    real = load_config(CELL)
    assert (real.devices.controller_timeout_s, real.devices.controller_link_timeout_s) == (1.0, 1.0)

    class Servers:  # what station_config_text reads of running simulators
        probe_port, controller_host, controller_port, probe_refresh_s = "/dev/null", "127.0.0.1", 1502, None

    import tomllib
    text = station_config_text(real, Servers(), 1)
    devices = tomllib.loads(text)["devices"]
    assert devices["controller_link_timeout_s"] >= SIMULATOR_CONTROLLER_DEADLINE_S
