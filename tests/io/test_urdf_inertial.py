"""A URDF's <inertial> masses as the compliance term's gravity model (issue 30), checked against
the potential energy of the same masses through the URDF's own kinematics."""

from __future__ import annotations

import re

import numpy as np
from scipy.spatial.transform import Rotation

from station.core.terms.error_model import gravity_torques
from station.io.robot.formats import robot_from_urdf
from station.io.robot.urdf_inertial import urdf_gravity

URDF = """<robot name="three">
  <link name="base"><inertial><mass value="50"/><origin xyz="0 0 0.1"/></inertial></link>
  <link name="l1"><inertial><mass value="20"/><origin xyz="0.05 0 0.2"/></inertial></link>
  <link name="l2"><inertial><mass value="12"/><origin xyz="0.3 0.02 0"/></inertial></link>
  <link name="l3"><inertial><mass value="6"/><origin xyz="0.2 0 0.01"/></inertial></link>
  <link name="flange"><inertial><mass value="3"/><origin xyz="0 0 0.05"/></inertial></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <origin xyz="0 0 0.4"/><axis xyz="0 0 1"/><limit lower="-3" upper="3"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0.1 0 0.3" rpy="0.1 0 0"/><axis xyz="0 1 0"/><limit lower="-3" upper="3"/></joint>
  <joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/>
    <origin xyz="0.6 0 0"/><axis xyz="0 -1 0"/><limit lower="-3" upper="3"/></joint>
  <joint name="fl" type="fixed"><parent link="l3"/><child link="flange"/><origin xyz="0.4 0 0" rpy="0 1.5708 0"/></joint>
</robot>
"""

JOINTS = {  # the URDF's own chain, written out: (origin xyz [m], rpy, axis, child)
    "j1": ((0, 0, 0.4), (0, 0, 0), (0, 0, 1)), "j2": ((0.1, 0, 0.3), (0.1, 0, 0), (0, 1, 0)),
    "j3": ((0.6, 0, 0), (0, 0, 0), (0, -1, 0))}
INERTIAL = {"l1": (20, (0.05, 0, 0.2)), "l2": (12, (0.3, 0.02, 0)), "l3": (6, (0.2, 0, 0.01))}


def _frame(xyz, rpy):
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("xyz", rpy).as_matrix()
    T[:3, 3] = xyz
    return T


def _potential(q):
    """V = Σ m g z of every moving mass, by the URDF's kinematics (fixed flange on l3)."""
    T = np.eye(4)
    v = 0.0
    for (xyz, rpy, axis), child, qi in zip(JOINTS.values(), ("l1", "l2", "l3"), q):
        R = np.eye(4)
        R[:3, :3] = Rotation.from_rotvec(np.asarray(axis, float) * qi).as_matrix()
        T = T @ _frame(xyz, rpy) @ R
        m, c = INERTIAL[child]
        v += m * 9.80665 * (T @ np.array([*c, 1.0]))[2]
    F = T @ _frame((0.4, 0, 0), (0, 1.5708, 0))
    v += 3 * 9.80665 * (F @ np.array([0, 0, 0.05, 1.0]))[2]
    return v


def test_urdf_masses_give_the_gravity_torques_of_the_urdfs_own_kinematics(tmp_path):
    f = tmp_path / "three.urdf"
    f.write_text(URDF)
    model = robot_from_urdf(f)
    gm = urdf_gravity(f)
    assert gm is not None and gm.masses == (20.0, 12.0, 9.0)  # the flange counts with l3; the base not
    q = np.random.default_rng(1).uniform(-1.5, 1.5, (6, 3))
    tau = gravity_torques(model, q, gm)
    h = 1e-6
    for i, qi in enumerate(q):
        for j in range(3):
            d = np.zeros(3)
            d[j] = h
            assert abs(tau[i, j] + (_potential(qi + d) - _potential(qi - d)) / (2 * h)) < 1e-4


def test_a_urdf_without_inertials_has_no_gravity_model(tmp_path):
    f = tmp_path / "bare.urdf"
    f.write_text(re.sub(r"<inertial>.*?</inertial>", "", URDF))
    assert "inertial" not in f.read_text() and robot_from_urdf(f).n_joints == 3
    assert urdf_gravity(f) is None
