"""Issue 19, inputs: bad inputs that gave exit 1 (or were silently accepted) are refused with the
exit code of their outcome and a message that says what to change; no numpy or scipy warning
reaches stderr on the way. Each case calls ``station.ui.cli.main.main`` in-process."""

from __future__ import annotations

import contextlib
import io
import re
import shutil
import socket
import warnings
from pathlib import Path

import pytest

from station.ui.cli.main import main

ROOT = Path(__file__).resolve().parents[1]


def run(argv: list[str]) -> tuple[int, str, str, list[warnings.WarningMessage]]:
    """Exit code, stdout, stderr and every warning emitted while ``station ARGV`` ran."""
    out, err = io.StringIO(), io.StringIO()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            rc = main(argv)
    return rc, out.getvalue(), err.getvalue(), list(caught)


def no_warnings(caught: list[warnings.WarningMessage]) -> None:
    assert not caught, [f"{w.category.__name__}: {w.message} ({w.filename}:{w.lineno})" for w in caught]


# --- a head with every probe on one face ------------------------------------------------------

def _cell_with_head_faces(tmp_path: Path, face: str) -> Path:
    cell = tmp_path / "cell"
    shutil.copytree(ROOT / "examples" / "scara600", cell)
    head = cell / "head.toml"
    head.write_text(re.sub(r'(?m)^face = "\w+"', f'face = "{face}"', head.read_text(encoding="utf-8")),
                    encoding="utf-8")
    return cell / "cell.toml"


@pytest.mark.parametrize("face, free, add", [
    ("top", "x translation, y translation and yaw", "add probes on the x face and the y face"),
    ("x", "y translation", "add probes on the top face and the y face"),
    ("y", "x translation", "add probes on the top face and the x face"),
])
def test_a_head_with_every_probe_on_one_face_is_refused_naming_free_motions_and_faces(tmp_path, face, free, add):
    cfg = _cell_with_head_faces(tmp_path, face)
    rc, _, err, caught = run(["plan", str(cfg)])
    assert rc == 2, err
    assert "head.toml: [[probe]]: the probe arrangement does not fix" in err
    assert free in err and add in err
    assert "do not point into their face" in err  # the probes whose face was changed under them
    assert "SVD" not in err and "internal error" not in err
    no_warnings(caught)


def test_the_example_head_still_loads_without_warnings(tmp_path):
    from station.io.head_file import load_head

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        head = load_head(ROOT / "examples" / "scara600" / "head.toml")
    assert head.report.rank == 6
    no_warnings(caught)


# --- station analyze --poses ----------------------------------------------------------------

@pytest.mark.parametrize("argv, pattern", [
    (["--poses", "-5"], r"--poses -5: the number of poses must be 1 … 10000"),
    (["--poses", "0"], r"--poses 0: the number of poses must be 1 … 10000"),
    (["--poses", "10001"], r"--poses 10001: the number of poses must be 1 … 10000"),
    (["--objective", "distance", "--poses", "1"], r"--poses 1: the number of poses must be 2 … 10000"),
    (["--objective", "distance", "--distances", "0"], r"--distances 0: .*at least 1"),
])
def test_analyze_refuses_pose_counts_outside_the_range(argv, pattern):
    rc, out, err, caught = run(["analyze", *argv])
    assert rc == 2, err
    assert re.search(pattern, err), err
    assert "rank" not in out  # no analysis of nothing
    no_warnings(caught)


def test_analyze_json_refusal_is_one_config_error_object():
    import json

    rc, out, err, caught = run(["analyze", "--poses", "0", "--json"])
    assert rc == 2
    assert json.loads(out)["outcome"] == "CONFIG_ERROR"
    no_warnings(caught)


def test_analyze_at_the_smallest_valid_count_still_runs():
    rc, out, err, caught = run(["analyze", "--poses", "1"])
    assert rc == 0, err
    assert "identifiable parameters (rank):" in out
    no_warnings(caught)


# --- URDF loops and branches -----------------------------------------------------------------

def _urdf(tmp_path: Path, joints: list[tuple[str, str, str, str]], links=("base", "a", "b", "c", "d")) -> Path:
    body = "".join(f'<link name="{n}"/>' for n in links)
    for name, kind, parent, child in joints:
        body += (f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
                 f'<origin xyz="0.1 0 0.2" rpy="0 0 0"/><axis xyz="0 0 1"/></joint>')
    p = tmp_path / "robot.urdf"
    p.write_text(f'<?xml version="1.0"?><robot name="arm">{body}</robot>', encoding="utf-8")
    return p


@pytest.mark.parametrize("joints, pattern", [
    # a joint whose child is an ancestor, under a root: this walked the chain for ever
    ([("j1", "revolute", "base", "a"), ("j2", "revolute", "a", "b"), ("j3", "fixed", "b", "a")],
     r"joints 'j2', 'j3' form a closed loop \(a -> b -> a\)"),
    # every link a child (the fuzz campaign's "cycle"): was "no moving joints"
    ([("j1", "revolute", "base", "a"), ("j2", "revolute", "a", "b"), ("j3", "revolute", "b", "base")],
     r"joints 'j1', 'j2', 'j3' form a closed loop \(base -> a -> b -> base\)"),
    # two parents without a directed cycle
    ([("j1", "revolute", "base", "a"), ("j2", "revolute", "base", "b"), ("j3", "revolute", "a", "c"),
      ("j4", "revolute", "b", "c")],
     r"link 'c' has two parents \(joints 'j3', 'j4'\): joints 'j3', 'j1', 'j2', 'j4' close a loop"),
])
def test_a_urdf_loop_is_refused_naming_its_joints(tmp_path, joints, pattern):
    rc, _, err, caught = run(["analyze", "--robot", str(_urdf(tmp_path, joints)), "--poses", "5"])
    assert rc == 2, err
    assert re.search(pattern, err), err
    assert "no moving joints" not in err and "one serial chain" in err
    no_warnings(caught)


def test_a_branched_urdf_is_refused_naming_the_branches_and_their_tips(tmp_path):
    joints = [("j1", "revolute", "base", "a"), ("j2", "revolute", "a", "b"), ("j3", "revolute", "a", "c"),
              ("j4", "fixed", "c", "d")]
    rc, _, err, caught = run(["analyze", "--robot", str(_urdf(tmp_path, joints)), "--poses", "5"])
    assert rc == 2, err
    assert "branches at link 'a' into joints 'j2', 'j3'" in err
    assert "'b' (joint 'j2') and 'd' (joint 'j3')" in err  # the tips, followed through fixed joints
    assert "delete the other branches' joints" in err
    no_warnings(caught)


def test_an_unbranched_urdf_still_imports(tmp_path):
    joints = [("j1", "revolute", "base", "a"), ("j2", "revolute", "a", "b"), ("j3", "fixed", "b", "c")]
    urdf = _urdf(tmp_path, joints, links=("base", "a", "b", "c"))
    rc, out, err, caught = run(["analyze", "--robot", str(urdf), "--poses", "5"])
    assert rc == 0, err
    assert "robot arm: " in out
    no_warnings(caught)


# --- station reset without a controller -------------------------------------------------------

def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_reset_without_a_reachable_controller_exits_7_saying_what_to_check(tmp_path, monkeypatch):
    cell = tmp_path / "cell"
    shutil.copytree(ROOT / "examples" / "scara600", cell)
    cfg = cell / "cell.toml"
    port = _free_port()  # nothing listens there: the connection is refused
    text = cfg.read_text(encoding="utf-8")
    cfg.write_text(re.sub(r'(?m)^controller = "[^"]*"', f'controller = "127.0.0.1:{port}"', text), encoding="utf-8")
    monkeypatch.chdir(tmp_path)
    rc, _, err, caught = run(["reset", str(cfg), "--yes"])
    assert rc == 7, err
    assert f"the controller at 127.0.0.1:{port} cannot be used" in err
    assert "nothing was sent to it" in err
    assert "[devices].controller" in err and "robot program is running" in err
    assert "internal error" not in err and "traceback" not in err
    assert not list(tmp_path.glob("station-error-*.log"))
    no_warnings(caught)


# --- numpy warnings: the input is refused before the arithmetic ------------------------------

def test_a_dh_file_with_an_infinite_angle_is_refused_without_a_numpy_warning(tmp_path):
    # the fuzz campaign's case: -inf reached cos/sin in station/core/kinematics/transforms.py
    p = tmp_path / "r.dh.csv"
    p.write_text("type,theta [deg],d [mm],a [mm],alpha [deg],lower [deg|mm],upper [deg|mm]\n"
                 "revolute,0,0,445,0,-130,130\nrevolute,0,0,355,-inf,-140,140\n"
                 "prismatic,0,0,0,180,-195,-5\nrevolute,0,0,0,0,-355,355\n", encoding="utf-8")
    rc, _, err, caught = run(["analyze", "--robot", str(p)])
    assert rc == 2, err
    assert "line 3: alpha must be a finite number, got '-inf'" in err
    no_warnings(caught)


def test_dh_rows_with_nan_are_refused_by_the_importer_itself():
    import math

    from station.errors import ConfigError
    from station.io.robot.formats import robot_from_dh

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with pytest.raises(ConfigError, match=r"DH row 1: theta, a must be finite numbers"):
            robot_from_dh([("revolute", math.nan, 0.0, math.inf, 0.0, -1.0, 1.0)])
    no_warnings(caught)
