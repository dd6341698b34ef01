"""Every piece of a correction refusal's advice is checked before it is printed (issue 37 §2).

The cell of the issue, rebuilt from files written here (a SCARA of 350 + 300 mm arms used by no
example, a 6-probe head and six 40 mm cubes low on the plate), set up by ``station init`` and then
placed where the robot really stands (x −350, z −60 mm): ``station plan`` refuses before any
motion, its first suggestion applied verbatim to the file passes ``plan`` and ``calibrate
--simulated`` ends SUCCESS. Before the fix the same refusal offered a bound that did not pass and a
smaller region that left verification targets outside the table."""

from __future__ import annotations

import json
import math
import re
import tomllib
from pathlib import Path

import pytest

from station.cell.correction.advice import Change, apply_changes
from station.errors import Outcome
from station.ui.cli.main import main

ROBOT = """[robot]
name = "scara650-advice"
angle_unit = "deg"
length_unit = "mm"
prefer = ["K.x", "K.y", "K.z", "K.roll", "K.pitch", "K.yaw", "A2.x", "A3.x", "A2.yaw", "A3.yaw",
          "A2.roll", "A2.pitch", "A3.roll", "A3.pitch", "A4.roll", "A4.pitch",
          "R.x", "R.y", "R.z", "R.roll", "R.pitch", "R.yaw"]

[[transform]]
name = "R"

[[transform]]
name = "A1"
joint = "revolute"
z = 400.0
limits = [-135.0, 135.0]
max_speed = 375.0

[[transform]]
name = "A2"
joint = "revolute"
x = 350.0
limits = [-145.0, 145.0]
max_speed = 600.0

[[transform]]
name = "A3"
joint = "prismatic"
x = 300.0
z = -80.0
limits = [-150.0, 0.0]
max_speed = 1000.0

[[transform]]
name = "A4"
joint = "revolute"
limits = [-360.0, 360.0]
max_speed = 2000.0

[[transform]]
name = "K"
z = -120.0
"""

HEAD = """[head]
name = "six-probe test head"
frame_in_flange = [-3.5, -4.5, -126.0, 0.0, 0.0, 0.0]
nominal_contact = [0.0, 0.0, -60.0, 0.0, 0.0, 0.0]
reading_sigma_um = 0.5
""" + "".join(f"""
[[probe]]
id = "{i}"
channel = {i}
mount_mm = {mount}
direction = {d}
face = "{face}"
stroke_mm = 10.0
tip_radius_mm = 1.0
""" for i, (mount, d, face) in enumerate([
    ([6.0, 6.0, -59.0], [0.0, 0.0, -1.0], "top"), ([34.0, 6.0, -59.0], [0.0, 0.0, -1.0], "top"),
    ([18.0, 33.0, -59.0], [0.0, 0.0, -1.0], "top"), ([-1.0, 9.0, -74.0], [1.0, 0.0, 0.0], "x"),
    ([-1.0, 31.0, -74.0], [1.0, 0.0, 0.0], "x"), ([21.0, -1.0, -74.0], [0.0, 1.0, 0.0], "y")], 1))

#: six 40 mm cubes: (radius [mm], angle [deg]) from the robot's axis 1, top z in the body frame
CUBES = [(330, -55, 0), (470, -30, 15), (560, 5, 30), (420, 15, 0), (300, 45, 15), (500, 50, 30)]


def _body() -> str:
    """The four top corners of each cube, in a body frame whose origin lies 350 mm in front of
    the robot and 60 mm above its base (the cube in x ≥ 0, y ≥ 0 of each corner frame)."""
    rows = ["id,x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg,sigma_position_um,sigma_angle_arcsec"]
    for i, (r, a, z) in enumerate(CUBES, 1):
        cx, cy = r * math.cos(math.radians(a)) - 350.0, r * math.sin(math.radians(a))
        th = math.radians(a + 7.0 * i)
        for k, (lx, ly, turn) in enumerate([(-1, -1, 0), (1, -1, 90), (1, 1, 180), (-1, 1, -90)]):
            x = cx + 20.0 * (lx * math.cos(th) - ly * math.sin(th))
            y = cy + 20.0 * (lx * math.sin(th) + ly * math.cos(th))
            yaw = (math.degrees(th) + turn + 180.0) % 360.0 - 180.0
            rows.append(f"K{i}.{'abcd'[k]},{x:.4f},{y:.4f},{z:.1f},0,0,{yaw:.3f},2.0,3.0")
    return "\n".join(rows) + "\n"


def test_apply_changes_replaces_removes_and_adds_keys_in_their_section():
    text = ("[plan]\nelbows = [1, -1]  # both\n[correction]\nx_mm = [\n  1, 2,  # \"x]\"\n  3]\n"
            "max_interpolation_um = 15.0   # bound\n[[tool]]\nname = \"g\"\nmax_interpolation_um = 7\n")
    out = apply_changes(text, [Change("correction", "x_mm", None), Change("correction", "max_interpolation_um", "19"),
                               Change("plan", "elbows", "[1]"), Change("verification", "max_ap_um", "5")])
    data = tomllib.loads(out)
    assert data["plan"]["elbows"] == [1] and data["correction"] == {"max_interpolation_um": 19}
    assert data["tool"] == [{"name": "g", "max_interpolation_um": 7}]  # another section's key is left alone
    assert data["verification"] == {"max_ap_um": 5}


def _apply_verbatim(path: Path, suggestion: str) -> None:
    """The suggestion as a user applies it: '[section] key = value' lines replaced in the file."""
    text = path.read_text(encoding="utf-8")
    for section, key, value in re.findall(r"\[(\w+)\] (\w+) = (\S+)", suggestion):
        head = text.index(f"[{section}]\n")
        line = re.compile(rf"^{key} = .*$", re.MULTILINE)
        m = line.search(text, head)
        assert m is not None, (section, key)
        text = text[:m.start()] + f"{key} = {value}" + text[m.end():]
    path.write_text(text, encoding="utf-8")


@pytest.mark.slow
def test_the_refusals_first_suggestion_applied_verbatim_plans_and_calibrates(tmp_path, capsys, monkeypatch):
    (tmp_path / "robot.toml").write_text(ROBOT, encoding="utf-8")
    (tmp_path / "head.toml").write_text(HEAD, encoding="utf-8")
    (tmp_path / "body.csv").write_text(_body(), encoding="utf-8")
    monkeypatch.chdir(tmp_path)
    assert main(["init", "cell.toml", "--robot", "robot.toml", "--head", "head.toml", "--body", "body.csv"]) == 0
    capsys.readouterr()
    cell = tmp_path / "cell.toml"
    text = cell.read_text(encoding="utf-8")
    cell.write_text(re.sub(r"^setup = \[.*\]$", "setup = [-350.0, 0.0, -60.0, 0.0, 0.0, 0.0]", text, count=1,
                           flags=re.MULTILINE), encoding="utf-8")  # where the robot really stands
    code = main(["plan", "cell.toml"])
    said = capsys.readouterr().err
    if code == 0:  # the design found a table by itself: nothing to advise (the first goal)
        suggestion = ""
    else:
        assert code == int(Outcome.CONFIG_ERROR) and "before the first motion" in said, said
        m = re.search(r"1\) (.*?) \(checked: .*? against ([0-9.]+) µm\)", said)
        assert m, said
        suggestion = m.group(1)
        bound = re.search(r"max_interpolation_um = (\d+)", suggestion)
        assert bound is None or int(bound.group(1)) > 15  # never the loop of 11 against a refused 15
        assert "correction.region = {" not in said  # no region that leaves verification targets outside
        _apply_verbatim(cell, suggestion)
        assert main(["plan", "cell.toml"]) == 0, capsys.readouterr().err
        capsys.readouterr()
    code = main(["calibrate", "--simulated", "cell.toml", "--seed", "1", "--db", "runs.sqlite", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and out["outcome"] == "SUCCESS", (suggestion, out.get("failure") or out.get("notes"))
