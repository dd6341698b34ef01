"""Robot files as strict as cell files (issue 33): unknown tables and keys are refused with the
nearest known name, a URDF's duplicate names and undeclared links are refused naming the element,
and values beyond physical plausibility are refused with the bound."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

import pytest

from station.errors import ConfigError
from station.io.robot.files import load_mapped_robot, load_robot
from station.ui.cli.main import main

SR800 = resources.files("station.io.robots").joinpath("sr800.toml").read_text()


def _toml(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "r.toml"
    p.write_text(text)
    return p


def _refused(path: Path, *expected: str) -> str:
    try:
        load_mapped_robot(path)
    except ConfigError as exc:
        msg = str(exc)
    else:
        pytest.fail(f"{path.name} was accepted")
    for e in expected:
        assert e in msg, msg
    return msg


@pytest.mark.parametrize("edit, expected", [
    (lambda t: t.replace('length_unit = "mm"', 'lenght_unit = "m"'),
     ("[robot]: unknown key 'lenght_unit' (did you mean 'length_unit'?)", "allowed: name, description, angle_unit")),
    (lambda t: t + '\n[joint_mapp.A2]\nsign = -1\n',
     ("unknown table [joint_mapp] (did you mean 'joint_map'?)", "[[transform]], [joint_map], [tool]")),
    (lambda t: t.replace("limits = [-130.0, 130.0]", "limits = [-130.0, 130.0]\nlimts = [0, 1]", 1),
     ("[[transform]] 'A1': unknown key 'limts' (did you mean 'limits'?)",)),
    (lambda t: t.replace("z = 800.0", "zz = 800.0", 1), ("[[transform]] 'A1': unknown key 'zz'",)),
    (lambda t: t + '\n[joint_map.A2]\nofset = 1\n', ("[joint_map.A2]: unknown key 'ofset' (did you mean 'offset'?)",)),
    (lambda t: t + '\n[tool]\nunknwn = true\n', ("[tool]: unknown key 'unknwn' (did you mean 'unknown'?)",)),
    (lambda t: 'colour = "red"\n' + t, ("unknown table [colour]",)),
])
def test_an_unknown_table_or_key_is_refused_with_the_nearest_name(tmp_path, edit, expected):
    _refused(_toml(tmp_path, edit(SR800)), *expected)


@pytest.mark.parametrize("edit, expected", [
    (lambda t: t.replace("x = 445.0", "x = 1e300", 1),
     "parameter A2.x = 1e+300 mm is beyond physical plausibility (at most ±100 m)"),
    (lambda t: t.replace("x = 445.0", "x = 100001e3", 1), "A2.x"),
    (lambda t: t.replace("limits = [-130.0, 130.0]", "limits = [-1e6, 130.0]", 1),
     "joint 1's limits [-1e+06 deg, 130 deg] are beyond physical plausibility (at most ±3600 deg = 2π·10 rad)"),
    (lambda t: t + '\n[joint_map.A2]\noffset = 1e300\n', "the joint map's offset of A2"),
    (lambda t: t + '\n[joint_map.A3]\ncoupled_to = "A2"\nk = 1e300\n', "coupling factor of A3"),
])
def test_a_physically_implausible_value_is_refused_with_the_bound(tmp_path, edit, expected):
    _refused(_toml(tmp_path, edit(SR800)), expected)


def test_the_built_in_and_exported_robots_still_load(tmp_path, capsys):
    load_robot("sr800")
    for fmt in ("toml", "urdf-new", "dh", "mdh"):
        out = tmp_path / {"toml": "m.toml", "urdf-new": "m.urdf"}.get(fmt, f"m.{fmt}.csv")
        assert main(["export-model", "sr800", "--format", fmt, "-o", str(out)]) == 0
        load_robot(out)


_URDF = """<robot name="r">{links}
<joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><limit lower="-1" upper="1"/></joint>
<joint name="{j2}" type="revolute"><parent link="l1"/><child link="{child}"/><limit lower="-1" upper="1"/></joint>
</robot>"""


@pytest.mark.parametrize("links, j2, child, expected", [
    ('<link name="base"/><link name="l1"/><link name="l1"/><link name="l2"/>', "j2", "l2",
     "two <link> elements are named 'l1'"),
    ('<link name="base"/><link name="l1"/><link name="l2"/>', "j1", "l2", "two <joint> elements are named 'j1'"),
    ('<link name="base"/><link name="l1"/><link name="l2"/>', "j2", "l3",
     "joint 'j2': its child link 'l3' is not declared"),
    ('<link name="base"/><link name="l1"/><link/>', "j2", "l1", "a <link> without a name"),
])
def test_a_urdf_with_duplicate_or_undeclared_names_is_refused(tmp_path, links, j2, child, expected):
    p = tmp_path / "r.urdf"
    p.write_text(_URDF.format(links=links, j2=j2, child=child))
    _refused(p, expected)


def test_a_well_formed_urdf_still_loads(tmp_path):
    p = tmp_path / "r.urdf"
    p.write_text(_URDF.format(links='<link name="base"/><link name="l1"/><link name="l2"/>', j2="j2", child="l2"))
    assert load_robot(p).n_joints == 2


def test_an_unknown_dh_column_is_refused_with_the_nearest_name(tmp_path):
    p = tmp_path / "r.dh.csv"
    p.write_text("type,theta [deg],d [mm],a [mm],alpha [deg],lower [deg|mm],upper [deg|mm],ofset [deg|mm]\n"
                 "revolute,0,0,100,0,-90,90,0\nrevolute,0,0,100,0,-90,90,0\n")
    _refused(p, "unknown column 'ofset' (did you mean 'offset'?)")


def test_the_cli_says_it_with_exit_2(tmp_path, capsys):
    p = _toml(tmp_path, SR800.replace('length_unit = "mm"', 'lenght_unit = "m"'))
    rc = main(["analyze", "--robot", str(p), "--poses", "5"])
    err = capsys.readouterr().err
    assert rc == 2 and "did you mean 'length_unit'?" in err and "Traceback" not in err, err
