"""A TOML robot file that marks its tool point unknown (``[tool] unknown = true``, issue 18 §3):
``identify`` fits the marker offset as ``--tool unknown`` does, ``--tool file`` still holds it,
the identified file no longer carries the mark, and a malformed ``[tool]`` is refused (exit 2).
The data: the six-axis robot measured by a tracker through a reflector 62–91 mm off the file's
tool point, made as tests/core/test_tracker_data_forms.py makes its data."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from station.core.kinematics.forward import forward
from station.core.kinematics.model import robot_to_toml
from station.core.kinematics.poses import spread_joints
from station.core.measurement.measurements import synthetic_set
from station.core.units import DEG
from station.io.datafile import write_csv
from station.io.robot.files import load_mapped_robot, load_robot, tool_marked_unknown
from station.ui.cli.main import main

IRB = load_robot("irb2600")
TRACKER = np.array([2100.0, -1500.0, 600.0, 3 * DEG, -2 * DEG, 120 * DEG])  # robot base in the tracker frame
MARKER = np.array([62.0, -40.0, 75.0])  # a reflector on an adapter, unknown to the robot file [mm]
MARK = "\n[tool]\nunknown = true\n"


def _joints(n: int, seed: int) -> np.ndarray:
    q = spread_joints(IRB, n, np.random.default_rng(seed))
    q[:, 4] = np.sign(q[:, 4]) * np.maximum(np.abs(q[:, 4]), 0.3)  # away from the wrist singularity
    return q


def _position_file(path: Path, q: np.ndarray, true: np.ndarray, seed: int) -> Path:
    pos = synthetic_set(IRB, "position", q, true, sigma=np.full(3, 0.015), rng=np.random.default_rng(seed)).measured
    write_csv(path, [f"q{j + 1} [rad]" for j in range(IRB.n_joints)] + ["x [mm]", "y [mm]", "z [mm]"],
              np.column_stack([q, pos]))
    return path


@pytest.fixture(scope="module")
def mocap(tmp_path_factory):
    d = tmp_path_factory.mktemp("mocap")
    rng = np.random.default_rng(3)
    true = IRB.nominal + rng.standard_normal(IRB.n_params) * np.where(IRB.is_angle(), 3e-4, 0.2)
    true[:6] = TRACKER
    true[-6:-3] += MARKER
    q_val = _joints(30, 6)
    cal = _position_file(d / "cal.csv", _joints(40, 5), true, 31)
    val = _position_file(d / "val.csv", q_val, true, 32)
    plain = d / "arm.toml"
    plain.write_text(robot_to_toml(IRB, IRB.nominal))
    marked = d / "arm_marker.toml"
    marked.write_text(robot_to_toml(IRB, IRB.nominal) + MARK)
    return d, true, q_val, cal, val, plain, marked


def run(capsys, *argv):
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def test_the_mark_is_read_only_from_the_file_that_has_it(mocap):
    _, _, _, _, _, plain, marked = mocap
    assert tool_marked_unknown(marked) and not tool_marked_unknown(plain)
    assert not tool_marked_unknown("irb2600")
    m_marked, _ = load_mapped_robot(marked)
    np.testing.assert_array_equal(m_marked.nominal, load_robot(plain).nominal)  # K is the start, as written


def test_a_tool_marked_unknown_is_fitted_without_the_flag(capsys, mocap):
    d, true, q_val, cal, _, plain, marked = mocap
    rc, _, err = run(capsys, "identify", cal, "--robot", plain)
    assert rc == 2 and "--tool unknown" in err, err  # the same data, the file's tool held: refused
    out = d / "fitted.toml"
    rc, text, err = run(capsys, "identify", cal, "--robot", marked, "-o", out, "--json")
    assert rc == 0, err
    rep = json.loads(text)
    assert rep["outcome"] == "SUCCESS" and rep["exit_code"] == 0
    assert any("[tool] unknown = true: the tool point is fitted" in n for n in rep["notes"]), rep["notes"]
    np.testing.assert_allclose(np.array(rep["registration"]["tool_offset_mm"]) - IRB.nominal[-6:-3], MARKER, atol=2.0)
    # the identified file's tool is known now: it carries no mark, and it predicts the robot
    assert not tool_marked_unknown(out)
    ident = load_robot(out)
    err_mm = forward(IRB, q_val, ident.nominal)[:, :3, 3] - forward(IRB, q_val, true)[:, :3, 3]
    assert np.sqrt(np.mean(np.sum(err_mm**2, axis=1))) < 0.05


def test_tool_file_on_the_command_line_holds_a_tool_the_file_marks_unknown(capsys, mocap):
    _, _, _, cal, _, _, marked = mocap
    rc, _, err = run(capsys, "identify", cal, "--robot", marked, "--tool", "file")
    assert rc == 2 and "--tool unknown" in err and "internal error" not in err, err


@pytest.mark.parametrize("head, tail, pattern", [
    ("", "\n[tool]\nunknown = \"yes\"\n", "[tool].unknown must be true or false, got 'yes'"),
    ("", "\n[tool]\nunknown = true\noffset = [62, -40, 75]\n", "[tool]: unknown key 'offset'; allowed: unknown (the tool itself is the last [[transform]])"),
    ("tool = 1\n", "", "tool must be a table, e.g. [tool] with unknown = true"),  # a top-level key: before [robot]
])
def test_a_malformed_tool_table_is_refused_by_every_command(capsys, tmp_path, head, tail, pattern):
    f = tmp_path / "bad.toml"
    f.write_text(head + robot_to_toml(IRB, IRB.nominal) + tail)
    for argv in (["analyze", "--robot", f, "--poses", "5"], ["predict", f, tmp_path / "none.csv"]):
        rc, _, err = run(capsys, *argv)
        assert rc == 2 and pattern in err and "internal error" not in err, (argv, err)
