"""``station init`` for a six-axis robot (issue 37 §3): a usable set-up, ``park_joints`` and
template words of an arm, joint speeds a DH table can carry, and the plan saying where to put
them when it cannot estimate the motion time.

The cell is written here from a KR 6 R900-like arm's data sheet (standard DH, 25 / 455 / 35 /
420 / 80 mm, the flange at 525 / 0 / 890 mm at q = 0 as the data sheet's home, its axis ranges
and speeds), the seven-probe head and 24 corners of eight 60 mm cubes; no example shares it.
Before: init wrote the SCARA template's set-up (no point reachable: 'station plan' exit 2), a
commented SCARA park pose, and the plan asked for "max_speed per joint" with no such DH column."""

from __future__ import annotations

import json
import math
import shutil
import tomllib
from pathlib import Path

import numpy as np
import pytest

from station.errors import ConfigError
from station.io.robot.files import load_robot
from station.ui.cli.main import main

ROOT = Path(__file__).resolve().parents[2]

#: axis ranges of the data sheet with axis 2 and 3 counted from the DH zero (arm up, forearm level)
KR6 = """# KR 6 R900-like arm from its data sheet, standard DH; q = 0: upper arm up, forearm level
type,theta [deg],d [mm],a [mm],alpha [deg],lower [deg|mm],upper [deg|mm]{speed_head}
revolute,0,400,25,-90,-170,170{s1}
revolute,-90,0,455,0,-100,135{s2}
revolute,0,0,35,-90,-120,156{s3}
revolute,0,420,0,90,-185,185{s4}
revolute,0,0,0,-90,-120,120{s5}
revolute,0,80,0,0,-350,350{s6}
"""
#: the data sheet's maximum speeds [deg/s], axes 1 … 6
SPEEDS = (360, 300, 360, 381, 388, 615)


def _robot(path: Path, speeds=SPEEDS) -> Path:
    if speeds is None:
        path.write_text(KR6.format(speed_head="", **{f"s{i}": "" for i in range(1, 7)}))
    else:
        path.write_text(KR6.format(speed_head=",max_speed [deg/s|mm/s]",
                                   **{f"s{i + 1}": f",{v}" for i, v in enumerate(speeds)}))
    return path


def _body(path: Path, edge: float = 60.0) -> Path:
    """Three top corners of each of eight cubes (ids K<n>.a … c), the corner frames turned 90° apart."""
    rows = ["id,x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg,sigma_position_um,sigma_angle_arcsec"]
    cubes = [(-150, -250, 0), (50, -250, 30), (-150, -50, 60), (50, -50, 0), (-150, 150, 30), (50, 150, 60),
             (250, -150, 0), (250, 50, 30)]
    for i, (x, y, z) in enumerate(cubes, 1):
        p = [float(x), float(y)]
        for k, c in enumerate("abc"):
            yaw = 10.0 + 90.0 * k
            rows.append(f"K{i}.{c},{p[0]:.3f},{p[1]:.3f},{z + edge:.1f},0,0,{yaw:g},2.0,3.0")
            p = [p[0] + edge * math.cos(math.radians(yaw)), p[1] + edge * math.sin(math.radians(yaw))]
    path.write_text("\n".join(rows) + "\n")
    return path


def test_a_dh_table_carries_the_joint_speeds(tmp_path):
    m = load_robot(str(_robot(tmp_path / "kr6.dh.csv")))
    assert m.max_speed is not None
    assert np.allclose(m.max_speed, np.radians(SPEEDS))
    assert load_robot(str(_robot(tmp_path / "none.dh.csv", speeds=None))).max_speed is None


def test_a_speed_missing_on_one_joint_row_is_refused_with_its_line(tmp_path):
    path = _robot(tmp_path / "kr6.dh.csv")
    lines = path.read_text().splitlines()
    lines[4] = lines[4].rsplit(",", 1)[0] + ","  # axis 3's speed left empty
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(ConfigError, match=r"line 4: max_speed must be a number > 0 on every joint row"):
        load_robot(str(path))


def test_plan_without_speeds_says_where_to_put_them(tmp_path, capsys, monkeypatch):
    """The plan of the example arm without speeds names the DH column to add (its file is a DH table)."""
    for name in ("cell.toml", "head.toml", "body.csv", "puma560.mdh.csv"):
        shutil.copy(ROOT / "examples" / "puma560" / name, tmp_path / name)
    monkeypatch.chdir(tmp_path)
    assert main(["plan", "cell.toml"]) == 0
    said = capsys.readouterr()
    out = said.out + said.err
    assert "motion time is not estimated" in out
    assert "a column 'max_speed [deg/s|mm/s]' with one value per joint row" in out


@pytest.mark.slow
@pytest.mark.timeout(600)  # a hang guard: init, plan and an 826-step simulated run, 3 min on a loaded 2-core machine
@pytest.mark.xfail(strict=True, reason="issue 40: 'station init' scores its placements by the collision-free "
                   "candidates now, and none of them (distances 0.2-0.8 of the reach, heights 0-1.0) reaches more "
                   "than 18 of this KR 6 cell's 24 points: configuration +1 has joint 4 at 180°, past init's soft "
                   "limits of ±177.6°, and +3 reaches the far cubes K7, K8 only with the upper arm through K3's")
def test_init_plan_and_calibrate_a_six_axis_cell_at_the_first_try(tmp_path, capsys, monkeypatch):
    """init → plan (exit 0, every point measured, a motion time) → calibrate --simulated SUCCESS."""
    monkeypatch.chdir(tmp_path)
    _robot(tmp_path / "kr6.dh.csv")
    _body(tmp_path / "body.csv")
    shutil.copy(ROOT / "examples" / "heads" / "seven-probe.toml", tmp_path / "head.toml")
    assert main(["init", "cell.toml", "--robot", "kr6.dh.csv", "--head", "head.toml", "--body", "body.csv"]) == 0
    said = capsys.readouterr().out
    text = (tmp_path / "cell.toml").read_text()
    cfg = tomllib.loads(text)
    # a usable park pose (the config reader checks it lies inside [limits]) and an arm's words
    assert len(cfg["conformance"]["park_joints"]) == 6
    assert "quill" not in text and "elbows = [" not in text.replace("# elbows = [", "")
    assert "24 of 24 points reached" in said
    assert cfg["robot"]["setup"] != [-450.0, 0.0, -170.0, 0.0, 0.0, 0.0]  # not the SCARA template's

    assert main(["plan", "cell.toml"]) == 0
    said = capsys.readouterr()
    plan = said.out + said.err
    assert "measured in no pose" not in plan
    assert "estimated duration" in plan

    assert main(["calibrate", "--simulated", "cell.toml", "--seed", "1", "--db", "runs.sqlite", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["outcome"] == "SUCCESS"
    assert out["before"]["rms_um"] / out["after"]["rms_um"] >= 20.0
