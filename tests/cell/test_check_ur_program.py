"""``station check`` names the controller software the UR program needs (issue 37, "smaller
finds"): robot-programs/ur/station_link.script uses ``make_list`` (Script Directory §16.10),
which came with PolyScope 5.15; the report reads the version from the program's own header, so
the two never disagree, and says it only for the UR program's cell (a six-axis arm whose map
window is the program's, UR's general-purpose registers 128..255)."""

from __future__ import annotations

import re
import socket

import pytest

from simulators.six_axis_cell import six_axis_config_text, start_six_axis_cell
from station.cell.config.cell_config import parse_text
from station.cell.session import calibrate as session
from station.io import robot_program
from station.io.robot_program import UR_PROGRAM, ur_program_needs
from tests.cell.test_conformance import config_text


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def six_axis_text() -> str:
    with start_six_axis_cell(seed=1) as srv:
        text = six_axis_config_text(srv, 1)
    # the devices are gone: check reports them failed, and the program's needs all the same
    return re.sub(r'(?m)^controller = "[^"]*"', f'controller = "127.0.0.1:{_closed_port()}"', text)


def test_the_header_states_the_version_and_the_window():
    needs = ur_program_needs()
    assert needs is not None and (needs.software, needs.version, needs.register_base) == ("PolyScope", "5.15", 128)
    assert "make_list" in needs.why
    assert "make_list(" in UR_PROGRAM.read_text(encoding="utf-8")  # the reason is still in the program


def test_check_states_the_minimum_polyscope_for_the_ur_window(six_axis_text):
    ur = parse_text(six_axis_text.replace("controller_register_base = 0", "controller_register_base = 128"))
    lines = "\n".join(session.check_cell(ur).lines)
    assert "robot program (UR, window at register 128): robot-programs/ur/station_link.script needs PolyScope " \
           "5.15 or later (make_list, §16.10" in lines
    # another window, or a SCARA's program at 128: not the UR program
    assert "PolyScope" not in "\n".join(session.check_cell(parse_text(six_axis_text)).lines)
    assert "PolyScope" not in "\n".join(session.check_cell(parse_text(config_text(_closed_port(), base=128))).lines)


def test_the_version_comes_from_the_program_not_from_the_station(six_axis_text, tmp_path, monkeypatch):
    copy = tmp_path / "station_link.script"
    copy.write_text(UR_PROGRAM.read_text(encoding="utf-8").replace("PolyScope 5.15+", "PolyScope 5.16+"),
                    encoding="utf-8")
    monkeypatch.setattr(robot_program, "UR_PROGRAM", copy)
    monkeypatch.setattr(session, "ur_program_needs", lambda: ur_program_needs(copy))
    ur = parse_text(six_axis_text.replace("controller_register_base = 0", "controller_register_base = 128"))
    assert "needs PolyScope 5.16 or later" in "\n".join(session.check_cell(ur).lines)
    assert ur_program_needs(tmp_path / "absent.script") is None  # an installed station without robot-programs/
