"""Robot models: the built-in SR 800, robot-file round trip and errors, DH / MDH / URDF import.

Every import is checked against an independent reference forward kinematics written here from
the format's own definition (plain products of elementary 4x4 matrices), not against the
station's converter.
"""

from __future__ import annotations

import math
import tomllib

import numpy as np
import pytest

from station.core.kinematics.forward import forward
from station.core.kinematics.model import robot_from_dict, robot_to_toml
from station.errors import ConfigError
from station.io.robot.files import load_robot
from station.io.robot.formats import robot_from_dh, robot_from_urdf

DEG = math.pi / 180


# --- independent elementary transforms ----------------------------------------------------------

def Rz(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def Ry(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1.0]])


def Rx(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def Tr(x=0.0, y=0.0, z=0.0):
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


def Rot_axis(axis, a):
    """Rotation by ``a`` about the unit ``axis`` (Rodrigues, written out)."""
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    T = np.eye(4)
    T[:3, :3] = np.eye(3) + math.sin(a) * K + (1 - math.cos(a)) * K @ K
    return T


SR800 = load_robot("sr800")


# --- the built-in SR 800 --------------------------------------------------------------------------

def test_sr800_structure():
    m = SR800
    assert m.n_params == 36
    assert len(m.param_names) == 36 and len(set(m.param_names)) == 36
    assert m.param_names[:6] == ("R.x", "R.y", "R.z", "R.roll", "R.pitch", "R.yaw")
    assert "A2.x" in m.param_names and "A1.yaw" in m.param_names and "K.z" in m.param_names
    assert m.joint_types == ("revolute", "revolute", "prismatic", "revolute")
    assert (m.n_revolute, m.n_prismatic) == (3, 1)
    assert m.minimal_param_count == 4 * 3 + 2 * 1 + 6 == 20
    # Table 7.1 values (mm), all angles zero
    assert m.nominal[m.param_index("A1.z")] == 800.0
    assert m.nominal[m.param_index("A2.x")] == 445.0
    assert m.nominal[m.param_index("A3.x")] == 355.0
    assert m.nominal[m.param_index("A3.z")] == -240.0
    assert m.nominal[m.param_index("K.z")] == pytest.approx(-128.478)
    assert np.all(m.nominal[m.is_angle()] == 0.0)
    assert m.joint_limits[0] == pytest.approx([-130 * DEG, 130 * DEG])
    assert m.joint_limits[2] == pytest.approx([-200.0, 0.0])  # prismatic limits stay mm
    assert m.param_index("A1.yaw") == 11


def test_sr800_forward_matches_table():
    """Ideal SCARA: x,y from two arm lengths, z from the heights, yaw = q1+q2+q4."""
    q1, q2, h3, q4 = 0.3, -0.7, -55.0, 1.1
    T = forward(SR800, np.array([[q1, q2, h3, q4]]))[0]
    kx, ky = -4.607, -4.147
    psi = q1 + q2 + q4
    x = 445 * math.cos(q1) + 355 * math.cos(q1 + q2) + kx * math.cos(psi) - ky * math.sin(psi)
    y = 445 * math.sin(q1) + 355 * math.sin(q1 + q2) + kx * math.sin(psi) + ky * math.cos(psi)
    z = 800 - 240 + h3 - 128.478
    assert T[:3, 3] == pytest.approx([x, y, z], abs=1e-10)
    assert T[:3, :3] == pytest.approx(Rz(psi)[:3, :3], abs=1e-14)


def test_unknown_parameter_name_message():
    with pytest.raises(ConfigError, match="unknown parameter 'A9.x'.*R, A1, A2, A3, A4, K"):
        SR800.param_index("A9.x")


# --- robot file round trip ------------------------------------------------------------------------

@pytest.mark.parametrize("angle_unit", ["deg", "rad"])
def test_robot_file_round_trip(angle_unit):
    rng = np.random.default_rng(7)
    err = np.where(SR800.is_angle(), 1e-3, 0.3)
    params = SR800.nominal + rng.standard_normal(36) * err
    text = robot_to_toml(SR800, params, angle_unit=angle_unit)
    back = robot_from_dict(tomllib.loads(text), source="round trip")
    assert back.name == SR800.name
    assert back.param_names == SR800.param_names
    assert back.joint_types == SR800.joint_types
    assert back.prefer == SR800.prefer
    assert back.description == SR800.description
    np.testing.assert_allclose(back.nominal, params, rtol=0, atol=1e-12)
    if angle_unit == "rad":
        assert np.array_equal(back.nominal, params)  # repr round trip is exact
    np.testing.assert_allclose(back.joint_limits, SR800.joint_limits, rtol=0, atol=1e-12)
    q = np.random.default_rng(8).uniform(SR800.joint_limits[:, 0], SR800.joint_limits[:, 1], (50, 4))
    np.testing.assert_allclose(forward(back, q), forward(SR800, q, params), rtol=0, atol=1e-12)


def test_robot_file_round_trip_via_load_robot(tmp_path):
    params = np.array(SR800.nominal)
    params[SR800.param_index("A2.x")] += 0.123
    f = tmp_path / "identified.toml"
    f.write_text(robot_to_toml(SR800, params))
    back = load_robot(f)
    np.testing.assert_allclose(back.nominal, params, rtol=0, atol=1e-12)


def test_length_unit_metres():
    d = tomllib.loads(robot_to_toml(SR800, angle_unit="rad"))
    d["robot"]["length_unit"] = "m"
    for t in d["transform"]:
        for k in ("x", "y", "z"):
            t[k] = t[k] / 1000.0
        if t.get("joint") == "prismatic":
            t["limits"] = [v / 1000.0 for v in t["limits"]]
    m = robot_from_dict(d)
    np.testing.assert_allclose(m.nominal, SR800.nominal, atol=1e-12)
    np.testing.assert_allclose(m.joint_limits, SR800.joint_limits, atol=1e-12)


# --- bad robot files ------------------------------------------------------------------------------

def _good() -> dict:
    return tomllib.loads(robot_to_toml(SR800))


def _bad(mutate):
    d = _good()
    mutate(d)
    return d


BAD_FILES = {
    "missing name": (lambda d: d["robot"].pop("name"), r"missing \[robot\] table with a 'name'"),
    "no robot table": (lambda d: d.pop("robot"), r"missing \[robot\] table"),
    "unknown key": (lambda d: d["transform"][2].update(lenght=3.0), r"unknown keys \['lenght'\].*allowed"),
    "non-finite number": (lambda d: d["transform"][2].update(x=math.inf), r"A2\.x must be a finite number"),
    "nan number": (lambda d: d["transform"][3].update(roll=math.nan), r"A3\.roll must be a finite number"),
    "string number": (lambda d: d["transform"][1].update(z="800"), r"A1\.z must be a finite number"),
    "bad joint type": (lambda d: d["transform"][1].update(joint="rotary"),
                       r"A1.*joint must be 'revolute' or 'prismatic'"),
    "missing limits": (lambda d: d["transform"][2].pop("limits"), r"'A2' needs limits = \[lower, upper\]"),
    "limits on a fixed transform": (lambda d: d["transform"][5].update(limits=[0, 1]), r"'K' has no joint"),
    "lower >= upper": (lambda d: d["transform"][2].update(limits=[10.0, 10.0]), r"lower < upper"),
    "unknown prefer": (lambda d: d["robot"].update(prefer=["K.x", "A7.yaw"]), r"unknown parameter 'A7.yaw'"),
    "bad angle unit": (lambda d: d["robot"].update(angle_unit="grad"), r"angle_unit must be 'deg' or 'rad'"),
    "too few transforms": (lambda d: d.update(transform=d["transform"][:2]), r"need \[\[transform\]\]"),
    "transform without name": (lambda d: d["transform"][3].pop("name"), r"number 4 needs a 'name'"),
    "duplicate names": (lambda d: d["transform"][2].update(name="A1"), r"transform names must be unique"),
    "joint on set-up": (lambda d: d["transform"][0].update(joint="revolute", limits=[-1, 1]),
                        r"carry no joint"),
}


@pytest.mark.parametrize("case", sorted(BAD_FILES))
def test_bad_robot_dict(case):
    mutate, pattern = BAD_FILES[case]
    with pytest.raises(ConfigError, match=pattern):
        robot_from_dict(_bad(mutate), source="bad.toml")


def test_bad_robot_message_names_the_source():
    with pytest.raises(ConfigError, match=r"^my/robot\.toml: "):
        robot_from_dict(_bad(lambda d: d["robot"].pop("name")), source="my/robot.toml")


def test_invalid_toml_file(tmp_path):
    f = tmp_path / "broken.toml"
    f.write_text('[robot]\nname = "x\n[[transform]]\n')
    with pytest.raises(ConfigError, match=r"broken\.toml: not valid TOML.*line"):
        load_robot(f)


def test_unknown_robot_name():
    with pytest.raises(ConfigError, match=r"'sr900' is neither a built-in robot \(.*sr800.*\) nor an existing file"):
        load_robot("sr900")


@pytest.mark.parametrize("limits", [[math.nan, 1.0], ["a", 1.0]])
def test_bad_limit_values(limits):
    with pytest.raises(ConfigError, match=r"A2.*limits"):
        robot_from_dict(_bad(lambda d: d["transform"][2].update(limits=limits)))


# --- DH / MDH import --------------------------------------------------------------------------------

PUMA_DH = [  # type, theta, d, a, alpha (rad, mm); a PUMA-560-like table with nonzero offsets
    ("revolute", 0.1, 0.0, 0.0, math.pi / 2),
    ("revolute", -0.2, 0.0, 431.8, 0.0),
    ("revolute", 0.05, 150.05, 20.32, -math.pi / 2),
    ("revolute", 0.0, 431.8, 0.0, math.pi / 2),
    ("prismatic", 0.3, 20.0, 5.0, -math.pi / 2),
    ("revolute", -0.4, 56.25, 1.5, 0.2),
]


def _rows(table):
    return [(k, th, d, a, al, -2.0 if k == "revolute" else -100.0, 2.0 if k == "revolute" else 100.0)
            for k, th, d, a, al in table]


def dh_reference(table, q):
    T = np.eye(4)
    for (kind, th, d, a, al), qi in zip(table, q):
        if kind == "revolute":
            T = T @ Rz(th + qi) @ Tr(z=d) @ Tr(x=a) @ Rx(al)
        else:
            T = T @ Rz(th) @ Tr(z=d + qi) @ Tr(x=a) @ Rx(al)
    return T


def mdh_reference(table, q):
    T = np.eye(4)
    for (kind, th, d, a, al), qi in zip(table, q):
        if kind == "revolute":
            T = T @ Rx(al) @ Tr(x=a) @ Rz(th + qi) @ Tr(z=d)
        else:
            T = T @ Rx(al) @ Tr(x=a) @ Rz(th) @ Tr(z=d + qi)
    return T


@pytest.mark.parametrize("convention,reference", [("dh", dh_reference), ("mdh", mdh_reference)])
def test_dh_import_matches_reference(convention, reference):
    m = robot_from_dh(_rows(PUMA_DH), convention)
    assert m.n_joints == 6 and m.n_params == 48
    assert m.joint_types == tuple(r[0] for r in PUMA_DH)
    rng = np.random.default_rng(3)
    q = rng.uniform(-1.5, 1.5, size=(40, 6))
    q[:, 4] *= 30  # prismatic, mm
    T = forward(m, q)
    for Ti, qi in zip(T, q):
        np.testing.assert_allclose(Ti, reference(PUMA_DH, qi), rtol=0, atol=1e-9)


def test_dh_import_with_tool():
    tool = Tr(1.0, 2.0, 30.0) @ Ry(0.3)
    m = robot_from_dh(_rows(PUMA_DH), "dh", tool=tool)
    q = np.random.default_rng(4).uniform(-1, 1, size=(5, 6))
    for Ti, qi in zip(forward(m, q), q):
        np.testing.assert_allclose(Ti, dh_reference(PUMA_DH, qi) @ tool, atol=1e-9)


def test_dh_bad_type_and_convention():
    with pytest.raises(ConfigError, match="type must be revolute, prismatic or fixed"):
        robot_from_dh([("spherical", 0, 0, 0, 0, -1, 1)])
    with pytest.raises(ConfigError, match="convention"):
        robot_from_dh(_rows(PUMA_DH), "craig")


DH_CSV = """# SR 800 as a DH table, mixed units
type,theta [deg],d [m],a [mm],alpha [deg],lower [deg|mm],upper [deg|mm]
revolute,0,0.8,445,0,-130,130
revolute,0,0,355,0,-145,145
prismatic,0,-0.24,0,0,-200,0
revolute,10,0,0,180,-360,360
"""


def test_dh_csv_file_with_units(tmp_path):
    f = tmp_path / "scara.dh.csv"
    f.write_text(DH_CSV)
    m = load_robot(f)
    assert m.name == "scara"
    assert m.joint_types == ("revolute", "revolute", "prismatic", "revolute")
    np.testing.assert_allclose(m.joint_limits, [[-130 * DEG, 130 * DEG], [-145 * DEG, 145 * DEG],
                                                [-200, 0], [-360 * DEG, 360 * DEG]], atol=1e-12)
    table = [("revolute", 0, 800.0, 445.0, 0), ("revolute", 0, 0, 355.0, 0),
             ("prismatic", 0, -240.0, 0, 0), ("revolute", 10 * DEG, 0, 0, math.pi)]
    q = np.random.default_rng(5).uniform(m.joint_limits[:, 0], m.joint_limits[:, 1], (20, 4))
    for Ti, qi in zip(forward(m, q), q):
        np.testing.assert_allclose(Ti, dh_reference(table, qi), atol=1e-9)


def test_mdh_csv_file(tmp_path):
    f = tmp_path / "arm.mdh.csv"
    f.write_text("type,theta [rad],d [mm],a [mm],alpha [rad],lower [rad|mm],upper [rad|mm]\n"
                 "revolute,0.1,100,0,0,-3,3\nrevolute,0,0,200,1.5707963267948966,-3,3\n"
                 "prismatic,0,50,300,0,-10,90\n")
    m = load_robot(f)
    table = [("revolute", 0.1, 100.0, 0.0, 0.0), ("revolute", 0.0, 0.0, 200.0, math.pi / 2),
             ("prismatic", 0.0, 50.0, 300.0, 0.0)]
    q = np.array([[0.2, -0.4, 30.0], [1.0, 2.0, -5.0]])
    for Ti, qi in zip(forward(m, q), q):
        np.testing.assert_allclose(Ti, mdh_reference(table, qi), atol=1e-9)
    assert m.joint_limits[2] == pytest.approx([-10, 90])


@pytest.mark.parametrize("text,pattern", [
    ("type,theta,d [mm],a [mm],alpha [deg],lower [deg|mm],upper [deg|mm]\nrevolute,0,0,0,0,-1,1\n",
     r"'theta' has no unit"),
    ("type,theta [deg],d [mm],a [mm],alpha [deg],lower [deg|mm]\nrevolute,0,0,0,0,-1\n",
     r"missing columns \['upper'\]"),
    ("type,theta [deg],d [in],a [mm],alpha [deg],lower [deg|mm],upper [deg|mm]\nrevolute,0,0,0,0,-1,1\n",
     r"unknown unit 'in'"),
    ("type,theta [deg],d [mm],a [mm],alpha [deg],lower [deg|mm],upper [deg|mm]\nrevolute,0,x,0,0,-1,1\n",
     r"line 2: d must be a number"),
    ("type,theta [deg],d [mm],a [mm],alpha [deg],lower [deg|mm],upper [deg|mm]\n",
     r"needs a header and one row per joint"),
])
def test_dh_csv_errors(tmp_path, text, pattern):
    f = tmp_path / "bad.dh.csv"
    f.write_text(text)
    with pytest.raises(ConfigError, match=pattern):
        load_robot(f)


# --- URDF import ------------------------------------------------------------------------------------

URDF = """<?xml version="1.0"?>
<robot name="tri">
  <link name="base"/>
  <link name="l1"/>
  <link name="l2"/>
  <link name="l2b"/>
  <link name="l3"/>
  <joint name="j1" type="revolute">
    <parent link="base"/><child link="l1"/>
    <origin xyz="0.01 0.02 0.3" rpy="0.05 -0.02 0.3"/>
    <axis xyz="0 0 1"/>
    <limit lower="-2.5" upper="2.5" effort="1" velocity="1"/>
  </joint>
  <joint name="j2" type="revolute">
    <parent link="l1"/><child link="l2"/>
    <origin xyz="0.25 0 0.05" rpy="0 0.1 0"/>
    <axis xyz="0 1 0"/>
    <limit lower="-1.5" upper="1.5" effort="1" velocity="1"/>
  </joint>
  <joint name="flange" type="fixed">
    <parent link="l2"/><child link="l2b"/>
    <origin xyz="0.1 0.0 -0.02" rpy="0.2 0 -0.1"/>
  </joint>
  <joint name="j3" type="prismatic">
    <parent link="l2b"/><child link="l3"/>
    <origin xyz="0.05 0.01 0" rpy="0 0 0.4"/>
    <axis xyz="0.6 0 0.8"/>
    <limit lower="0" upper="0.2" effort="1" velocity="1"/>
  </joint>
</robot>
"""

# URDF semantics: child frame = parent · origin(xyz [m], rpy: Rz·Ry·Rx) · motion along/about axis
_JOINTS = [
    ("revolute", (0.01, 0.02, 0.3), (0.05, -0.02, 0.3), (0, 0, 1)),
    ("revolute", (0.25, 0, 0.05), (0, 0.1, 0), (0, 1, 0)),
    ("fixed", (0.1, 0.0, -0.02), (0.2, 0, -0.1), None),
    ("prismatic", (0.05, 0.01, 0), (0, 0, 0.4), (0.6, 0, 0.8)),
]


def urdf_reference(q):
    T = np.eye(4)
    qi = iter(q)
    for kind, xyz, rpy, axis in _JOINTS:
        T = T @ Tr(*(1000.0 * np.array(xyz))) @ Rz(rpy[2]) @ Ry(rpy[1]) @ Rx(rpy[0])
        if kind == "revolute":
            T = T @ Rot_axis(axis, next(qi))
        elif kind == "prismatic":
            T = T @ Tr(*(np.array(axis) * next(qi)))
    return T


def test_urdf_import_matches_reference(tmp_path):
    f = tmp_path / "tri.urdf"
    f.write_text(URDF)
    m = load_robot(f)
    assert m.name == "tri"
    assert m.joint_types == ("revolute", "revolute", "prismatic")
    assert m.transform_names == ("R", "A1", "A2", "A3", "K")
    np.testing.assert_allclose(m.joint_limits, [[-2.5, 2.5], [-1.5, 1.5], [0, 200]])
    rng = np.random.default_rng(9)
    q = np.column_stack([rng.uniform(-2, 2, 30), rng.uniform(-1.4, 1.4, 30), rng.uniform(0, 200, 30)])
    for Ti, qi in zip(forward(m, q), q):
        np.testing.assert_allclose(Ti, urdf_reference(qi), rtol=0, atol=1e-9)


def test_urdf_errors(tmp_path):
    f = tmp_path / "bad.urdf"
    f.write_text("<robot name='x'><link name='a'/>")
    with pytest.raises(ConfigError, match="not valid XML"):
        robot_from_urdf(f)
    f.write_text("<robot name='x'><link name='a'/><link name='b'/>"
                 "<joint name='j' type='floating'><parent link='a'/><child link='b'/></joint></robot>")
    with pytest.raises(ConfigError, match="'floating' is not supported"):
        robot_from_urdf(f)
    f.write_text("<robot name='x'><link name='a'/><link name='b'/>"
                 "<joint name='j' type='fixed'><parent link='a'/><child link='b'/></joint></robot>")
    with pytest.raises(ConfigError, match="no moving joints"):
        robot_from_urdf(f)


_TWO_LINKS = "<robot name='x'><link name='a'/><link name='b'/>{}</robot>"


@pytest.mark.parametrize("joint, pattern", [
    ("<joint name='j1' type='revolute'><child link='b'/></joint>", r"joint 'j1' has no <parent> element"),
    ("<joint name='j1' type='revolute'><parent link='a'/></joint>", r"joint 'j1' has no <child> element"),
    ("<joint name='j1' type='revolute'><parent/><child link='b'/></joint>", r"joint 'j1': <parent> has no 'link'"),
    ("<joint name='j1' type='revolute'><parent link='a'/><child link='b'/><origin xyz='0 0'/></joint>",
     r"joint 'j1': <origin xyz> must be 3 numbers, got '0 0'"),
    ("<joint name='j1' type='revolute'><parent link='a'/><child link='b'/><origin rpy='0 x 0'/></joint>",
     r"joint 'j1': <origin rpy> must be 3 numbers"),
    ("<joint name='j1' type='revolute'><parent link='a'/><child link='b'/><axis/></joint>",
     r"joint 'j1': <axis> has no 'xyz' attribute"),
    ("<joint name='j1' type='revolute'><parent link='a'/><child link='b'/><limit upper='1'/></joint>",
     r"joint 'j1': <limit> has no 'lower' attribute"),
])
def test_urdf_missing_elements_name_the_joint(tmp_path, joint, pattern):
    f = tmp_path / "bad.urdf"
    f.write_text(_TWO_LINKS.format(joint))
    with pytest.raises(ConfigError, match=pattern):
        robot_from_urdf(f)


def test_urdf_origin_and_axis_default(tmp_path):
    # URDF: <origin> and its xyz / rpy default to zero, <axis> to x, a joint without <limit> to ±2π
    f = tmp_path / "min.urdf"
    f.write_text(_TWO_LINKS.format(
        "<joint name='j1' type='revolute'><parent link='a'/><child link='b'/><origin rpy='0 0 0.5'/></joint>"))
    m = robot_from_urdf(f)
    np.testing.assert_allclose(m.joint_limits, [[-2 * math.pi, 2 * math.pi]])
    np.testing.assert_allclose(forward(m, [[0.3]]), [Rz(0.5) @ Rx(0.3)], atol=1e-12)


def test_urdf_zero_axis_is_refused_naming_the_joint(tmp_path):
    p = tmp_path / "zero.urdf"
    p.write_text('<robot name="z"><link name="base"/><link name="l1"/>'
                 '<joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>'
                 '<axis xyz="0 0 0"/><limit lower="-1" upper="1"/></joint></robot>')
    with pytest.raises(ConfigError, match="j1.*no direction"):
        load_robot(str(p))
