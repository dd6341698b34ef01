"""Opening a cell from its configuration (station.cell.session.calibrate): word order, device protocols,
and every failure returned as a typed outcome."""

from __future__ import annotations

from contextlib import ExitStack
from pathlib import Path

import numpy as np
import pytest

from drivers.controller_map import WordOrder
from simulators import start_simulated_cell
from simulators.reference_cell import cell_config_text
from station.cell.config.cell_config import parse_text
from station.cell.config.template import TEMPLATE
from station.cell.run import devices
from station.cell.run.facts.events import RunFailed
from station.cell.session.calibrate import CellRequest, check_cell, open_cell, run_calibration_session
from station.errors import Outcome

# the template's example controller is on a private network: tests never reach out to it
LOOPBACK_CONTROLLER = '"127.0.0.1:9"'


@pytest.fixture(scope="module")
def little_sim():
    with start_simulated_cell(seed=3, word_order=WordOrder.LITTLE) as servers:
        yield servers


def test_check_with_little_word_order_reads_the_true_joints(little_sim):
    cfg = parse_text(cell_config_text(little_sim, 3, word_order="little"))
    assert cfg.devices.word_order == "little"
    report = check_cell(cfg)
    assert report.outcome is Outcome.SUCCESS, report.lines
    text = "\n".join(report.lines)
    assert "warning" not in text  # a wrong word order reads garbage limits and warns falsely
    with ExitStack() as stack:
        q = open_cell(cfg, stack).controller.read_joints()
    np.testing.assert_allclose(q, little_sim.controller_server.joints, atol=1e-5)


def test_the_drivers_satisfy_the_station_protocols_at_run_time(little_sim):
    cfg = parse_text(cell_config_text(little_sim, 3, word_order="little"))
    with ExitStack() as stack:
        cell = open_cell(cfg, stack)
        assert isinstance(cell.probe, devices.ProbeHead)
        assert isinstance(cell.controller, devices.RobotController)
        assert isinstance(cell.controller, devices.TableController)
        assert isinstance(cell.controller, devices.CellController)
        assert isinstance(cell.controller.status(), devices.ControllerState)
        assert isinstance(cell.probe.read_all(), devices.Snapshot)
        motion = cell.controller.move_joints(cell.controller.read_joints())
        assert isinstance(motion, devices.MotionStatus)
        motion.wait(timeout=10.0)


def _template_with_probe(tmp_path: Path, port: str) -> Path:
    path = tmp_path / "cell.toml"
    path.write_text(TEMPLATE.replace('"192.168.0.10:502"', LOOPBACK_CONTROLLER).replace('probe_head = "/dev/ttyUSB0"', f'probe_head = "{port}"'))
    return path


def test_missing_probe_interface_is_a_device_fault_not_a_traceback(tmp_path):
    cfg = _template_with_probe(tmp_path, str(tmp_path / "no-such-tty"))
    events = []
    summary = run_calibration_session(CellRequest(config=str(cfg), db=str(tmp_path / "runs.sqlite")),
                                      events.append)
    assert summary.outcome is Outcome.DEVICE_FAULT and summary.exit_code == 7
    assert summary.failure is not None and "no-such-tty" in summary.failure.message
    assert "probe" in summary.failure.hint
    assert isinstance(events[-1], RunFailed) and events[-1].summary == summary
    assert summary.to_json()["exit_code"] == 7


def test_an_internal_error_is_logged_with_its_traceback(tmp_path, monkeypatch):
    import station.cell.session.calibrate as session

    def broken(*args, **kwargs):
        raise ZeroDivisionError("a bug")

    monkeypatch.setattr(session, "load_cell", broken)
    summary = run_calibration_session(CellRequest(config="x.toml", db=str(tmp_path / "runs.sqlite")),
                                      lambda e: None)
    assert summary.outcome is Outcome.INTERNAL_ERROR and summary.exit_code == 1
    log = Path(summary.failure.log_file)
    assert log.parent == tmp_path and str(log) in summary.failure.message
    text = log.read_text()
    assert "Traceback" in text and "ZeroDivisionError: a bug" in text and "def broken" not in text
    assert "broken" in text  # the frame that raised is named
