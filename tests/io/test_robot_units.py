"""A unit slip in a robot file is caught where it is made (issue 37 §3): on the numbers as written,
before any conversion or wrapping, naming the column (or key), the line and the likely unit.

Before: a DH α of 90 under [rad] wrapped to another robot and loaded; metres under [mm] loaded
as a robot a thousand times too small; radians under [deg] loaded and failed in the plan, blaming
[robot].setup and [limits]."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from station.errors import ConfigError
from station.io.robot.files import load_robot

HEAD = "type,theta [{a}],d [{u}],a [{u}],alpha [{a}],lower [{a}|{u}],upper [{a}|{u}]\n"
#: a six-axis arm of 25 / 400 / 455 / 35 / 420 / 80 mm (a KR 6 R900-like data sheet, written here)
ROWS_DEG_MM = [(0, 400, 25, -90, -170, 170), (-90, 0, 455, 0, -190, 45), (0, 0, 35, -90, -120, 156),
               (0, 420, 0, 90, -185, 185), (0, 0, 0, -90, -120, 120), (0, 80, 0, 0, -350, 350)]


def _dh(tmp_path, a="deg", u="mm", angle=lambda v: v, length=lambda v: v, limit=lambda v: v, head=None):
    text = (head or HEAD).format(a=a, u=u) + "".join(
        f"revolute,{angle(t):.12g},{length(d):.12g},{length(ln):.12g},{angle(al):.12g},{limit(lo):.12g},{limit(hi):.12g}\n"
        for t, d, ln, al, lo, hi in ROWS_DEG_MM)
    p = tmp_path / "arm.dh.csv"
    p.write_text(text, encoding="utf-8")
    return p


def test_the_file_in_its_own_units_loads_and_the_same_robot_in_rad_and_m(tmp_path):
    m = load_robot(_dh(tmp_path))
    d = tmp_path / "si"
    d.mkdir()
    m2 = load_robot(_dh(d, "rad", "m", angle=math.radians, length=lambda v: v / 1000.0, limit=math.radians,
                        head="type,theta [{a}],d [{u}],a [{u}],alpha [{a}],lower [{a}|mm],upper [{a}|mm]\n"))
    assert np.max(np.abs(m.nominal - m2.nominal)) < 1e-6, np.max(np.abs(m.nominal - m2.nominal))


def test_degrees_under_rad_are_named_by_column_line_and_likely_unit(tmp_path):
    # the angles in degrees, the header says rad (the limits' header too, as a whole file in degrees)
    path = _dh(tmp_path, a="rad")
    with pytest.raises(ConfigError) as exc:
        load_robot(path)
    msg = str(exc.value)
    assert re.search(r"alpha \[rad\] = -90 \(line 2\) is more than a turn .*reads like degrees, not rad", msg), msg


def test_dh_twists_of_90_under_rad_with_limits_in_deg_are_refused(tmp_path):
    # the issue's file: only theta and alpha in degrees under [rad]; the limits' header right
    head = "type,theta [rad],d [mm],a [mm],alpha [rad],lower [deg|mm],upper [deg|mm]\n"
    path = _dh(tmp_path, head=head)
    with pytest.raises(ConfigError) as exc:
        load_robot(path)
    assert "reads like degrees" in str(exc.value) and "[rad]" in str(exc.value)


def test_link_lengths_in_metres_under_mm_are_named(tmp_path):
    path = _dh(tmp_path, length=lambda v: v / 1000.0)
    with pytest.raises(ConfigError) as exc:
        load_robot(path)
    msg = str(exc.value)
    assert re.search(r"a \[mm\] = 0\.455 \(line 3\) and the whole arm's lengths add up to 1\.415 mm: it reads "
                     r"like metres, not mm", msg), msg


def test_radians_under_deg_blame_the_column_not_the_setup_or_limits(tmp_path):
    path = _dh(tmp_path, angle=math.radians, limit=math.radians)
    with pytest.raises(ConfigError) as exc:
        load_robot(path)
    msg = str(exc.value)
    assert "reads like radians, not deg" in msg and "[robot].setup" not in msg and "[limits]" not in msg
    assert re.search(r"(theta|alpha) \[deg\] = -?1\.5708 \(line \d\)", msg), msg


def test_limits_in_radians_under_deg_are_named(tmp_path):
    path = _dh(tmp_path, limit=math.radians)
    with pytest.raises(ConfigError) as exc:
        load_robot(path)
    assert re.search(r"(lower|upper) \[deg\|mm\] = -?6\.10865\d* \(line 7\) and every revolute joint's range is "
                     r"narrower than 12\.6°: it reads like radians", str(exc.value)), str(exc.value)


TOML = """[robot]
name = "unit-test scara"
angle_unit = "{a}"
length_unit = "{u}"

[[transform]]
name = "R"
x = -350.0

[[transform]]
name = "A1"
joint = "revolute"
z = {z1}
limits = [{lo}, {hi}]

[[transform]]
name = "A2"
joint = "revolute"
x = {x2}
yaw = {yaw}
limits = [{lo}, {hi}]

[[transform]]
name = "K"
z = {zk}
"""


def _toml(tmp_path, a="deg", u="mm", z1=420.0, x2=330.0, yaw=30.0, lo=-140.0, hi=140.0, zk=-90.0):
    p = tmp_path / "robot.toml"
    p.write_text(TOML.format(a=a, u=u, z1=z1, x2=x2, yaw=yaw, lo=lo, hi=hi, zk=zk), encoding="utf-8")
    return p


def test_toml_in_its_units_loads_and_its_slips_are_named_by_key(tmp_path):
    load_robot(_toml(tmp_path))
    with pytest.raises(ConfigError, match=r"A2\.yaw = 30 \(transform A2\) is more than a turn .*degrees.*"
                                          r'angle_unit = "deg"'):
        load_robot(_toml(tmp_path, a="rad", lo=-2.4, hi=2.4))
    with pytest.raises(ConfigError, match=r"reads like metres, not mm.*length_unit = \"m\""):
        load_robot(_toml(tmp_path, z1=0.42, x2=0.33, zk=-0.09))
    with pytest.raises(ConfigError, match=r"A2\.yaw = 1\.5708 .*reads like radians"):
        load_robot(_toml(tmp_path, yaw=1.5708))
