"""Import of the robot descriptions users actually hold: DH, modified DH (Craig), URDF.

Every format is converted exactly into the six-parameter chain of :mod:`station.core.model`:

* DH link i: ``Rz(θ_i + q_i) · Tz(d_i) · Tx(a_i) · Rx(α_i)``. The joint moves about z *before*
  the link's constants, so the constants of link i become the origin of the station's
  transform i+1, and those of the last link become the tool K.
* Modified DH link i: ``Rx(α_{i-1}) · Tx(a_{i-1}) · Rz(θ_i) · Tz(d_i)`` then the joint — the same
  order as the station's form, so each link maps onto one transform.
* URDF: each moving joint's origin, then a rotation that takes the joint axis onto z (undone at
  the start of the next transform); fixed joints fold into their neighbours.

DH table files are CSV (``*.dh.csv`` or ``*.mdh.csv``) with units in the header, e.g.::

    type,theta [deg],d [mm],a [mm],alpha [deg],lower [deg|mm],upper [deg|mm]
    revolute,0,800,445,0,-130,130

A row of type ``fixed`` (limits left empty) is a constant link without a joint: the exporter
writes a set-up in front of axis 1 or a tool after the last axis that way.
"""

from __future__ import annotations

import csv
import math
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from station.core.model import RobotModel, TransformSpec
from station.core.transforms import invert, matrix_to_pose, pose_to_matrix, rot_x, rot_z, rotation_exp
from station.errors import ConfigError


def _T(R: np.ndarray | None = None, t: Sequence[float] = (0.0, 0.0, 0.0)) -> np.ndarray:
    """Homogeneous ``(4, 4)`` transform from a rotation ``(3, 3)`` (default identity) and a
    translation ``(3,)``."""
    T = np.eye(4)
    if R is not None:
        T[:3, :3] = R
    T[:3, 3] = t
    return T


def robot_from_dh(rows, convention: str = "dh", name: str = "imported", tool=None) -> RobotModel:
    """Model from DH rows ``(type, theta, d, a, alpha, lower, upper)`` [rad, mm].

    ``convention``: ``"dh"`` (standard) or ``"mdh"`` (modified, Craig). ``tool``: optional
    (4, 4) flange→tool transform appended to K.
    """
    if convention not in ("dh", "mdh"):
        raise ConfigError("convention must be 'dh' or 'mdh'")
    # A row of type "fixed" carries no joint (a set-up, tool or offset link written as DH).
    # dh: per link (Rz(θ)·Tz(d), Tx(a)·Rx(α)), the parts before and after the joint; mdh: the
    # whole (4, 4) constant transform of each link.
    specs = [TransformSpec("R")]
    limits = []
    poses = [np.zeros(6)]
    carry = np.eye(4)  # constant transform not yet placed in front of a joint
    n_joint = 0
    for i, (kind, theta, d, a, alpha, lo, hi) in enumerate(rows, start=1):
        if kind not in ("revolute", "prismatic", "fixed"):
            raise ConfigError(f"DH row {i}: type must be revolute, prismatic or fixed, got {kind!r}")
        if convention == "dh":
            pre, post = _T(rot_z(theta)) @ _T(t=(0, 0, d)), _T(t=(a, 0, 0)) @ _T(rot_x(alpha))
        else:
            pre, post = _T(rot_x(alpha)) @ _T(t=(a, 0, 0)) @ _T(rot_z(theta)) @ _T(t=(0, 0, d)), np.eye(4)
        if kind == "fixed":
            carry = carry @ pre @ post
            continue
        # θ and d (dh) commute with the joint motion about/along z, so they stay with the joint
        # and Tx(a)·Rx(α) moves to the front of the next transform.
        n_joint += 1
        specs.append(TransformSpec(f"A{n_joint}", kind))
        limits.append((lo, hi))
        poses.append(matrix_to_pose(carry @ pre))
        carry = post
    if n_joint == 0:
        raise ConfigError("DH rows: no revolute or prismatic joint")
    specs.append(TransformSpec("K"))
    tail = carry
    if tool is not None:
        tail = tail @ np.asarray(tool, dtype=float)
    poses.append(matrix_to_pose(tail))
    return RobotModel(name, tuple(specs), np.concatenate(poses), np.array(limits, dtype=float))


def _unit(header: str) -> str:
    if "[" not in header or not header.strip().endswith("]"):
        raise ConfigError(f"column {header.strip()!r} has no unit; write it like 'theta [deg]'")
    return header[header.index("[") + 1: -1].strip()


def robot_from_dh_file(path: Path) -> RobotModel:
    conv = "mdh" if path.name.endswith(".mdh.csv") else "dh"
    with open(path, newline="", encoding="utf-8-sig") as f:
        rows = [r for r in csv.reader(line for line in f if not line.lstrip().startswith("#")) if r]
    if len(rows) < 2:
        raise ConfigError(f"{path}: needs a header and one row per joint")
    head = [h.strip() for h in rows[0]]
    names = [h.split("[")[0].strip() for h in head]
    need = ["type", "theta", "d", "a", "alpha", "lower", "upper"]
    missing = [n for n in need if n not in names]
    if missing:
        raise ConfigError(f"{path}: missing columns {missing}; expected {need} with units")
    units = {n: (_unit(h) if n != "type" else "") for n, h in zip(names, head)}
    scale = {"deg": math.pi / 180, "rad": 1.0, "mm": 1.0, "m": 1000.0}
    out = []
    for k, r in enumerate(rows[1:], start=2):
        rec = dict(zip(names, (c.strip() for c in r)))
        kind = rec["type"]
        vals = {}
        for n in need[1:]:
            u = units[n]
            if kind == "fixed" and n in ("lower", "upper"):
                vals[n] = 0.0
                continue
            if n in ("lower", "upper"):
                u = u.split("|")[0 if kind == "revolute" else -1]
            if u not in scale:
                raise ConfigError(f"{path}: unknown unit {u!r} in column {n!r}; use deg, rad, mm or m")
            try:
                vals[n] = float(rec[n]) * scale[u]
            except (KeyError, ValueError):
                raise ConfigError(f"{path}, line {k}: {n} must be a number, got {rec.get(n)!r}") from None
        out.append((kind, vals["theta"], vals["d"], vals["a"], vals["alpha"], vals["lower"], vals["upper"]))
    return robot_from_dh(out, conv, name=path.name.split(".")[0])


def _axis_to_z(axis: np.ndarray) -> np.ndarray:
    """Rotation whose z column is ``axis``."""
    z = np.array([0.0, 0.0, 1.0])
    a = axis / np.linalg.norm(axis)
    c = np.cross(z, a)
    s, cos = np.linalg.norm(c), float(z @ a)
    if s < 1e-12:
        return np.eye(3) if cos > 0 else rot_x(np.pi)
    return rotation_exp(c / s * math.atan2(s, cos))


def _joint_name(j: ET.Element) -> str:
    return j.get("name", "<unnamed>")


def _urdf_link(path: Path, j: ET.Element, tag: str) -> str:
    """The ``link`` attribute of joint ``j``'s ``<parent>`` or ``<child>`` (both required)."""
    el = j.find(tag)
    if el is None:
        raise ConfigError(f"{path}: joint {_joint_name(j)!r} has no <{tag}> element; "
                          f"add <{tag} link=\"...\"/>")
    link = el.get("link")
    if link is None:
        raise ConfigError(f"{path}: joint {_joint_name(j)!r}: <{tag}> has no 'link' attribute")
    return link


def _urdf_numbers(path: Path, j: ET.Element, tag: str, attr: str, text: str, n: int) -> list[float]:
    """``n`` numbers from the attribute ``attr`` (value ``text``) of joint ``j``'s ``<tag>``."""
    try:
        vals = [float(v) for v in text.split()]
    except ValueError:
        vals = []
    if len(vals) != n:
        raise ConfigError(f"{path}: joint {_joint_name(j)!r}: <{tag} {attr}> must be {n} numbers, got {text!r}")
    return vals


def _urdf_limit(path: Path, j: ET.Element, lim: ET.Element, attr: str) -> float:
    """The ``lower`` or ``upper`` attribute of joint ``j``'s ``<limit>`` element."""
    text = lim.get(attr)
    if text is None:
        raise ConfigError(f"{path}: joint {_joint_name(j)!r}: <limit> has no '{attr}' attribute; "
                          f"give lower and upper, or make the joint continuous")
    return _urdf_numbers(path, j, "limit", attr, text, 1)[0]


def robot_from_urdf(path: Path) -> RobotModel:
    """Model of the serial chain in a URDF file (the first chain from the root link).

    Every joint needs ``<parent link>`` and ``<child link>``; ``<origin>`` (xyz, rpy) and
    ``<axis>`` are optional with the URDF defaults (identity, x axis). A revolute or prismatic
    joint without ``<limit>`` gets ±2π rad / ±1000 mm.
    """
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise ConfigError(f"{path}: not valid XML ({exc})") from None
    joints = {_urdf_link(path, j, "parent"): j for j in root.findall("joint")}
    children = {_urdf_link(path, j, "child") for j in root.findall("joint")}
    roots = [link.get("name") for link in root.findall("link") if link.get("name") not in children]
    if len(roots) != 1:
        raise ConfigError(f"{path}: expected one root link, found {roots}")
    link, carry = roots[0], np.eye(4)
    specs, poses, limits = [TransformSpec("R")], [np.zeros(6)], []
    while link in joints:
        j = joints[link]
        origin = j.find("origin")
        xyz, rpy = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
        if origin is not None:
            xyz = [v * 1000.0 for v in _urdf_numbers(path, j, "origin", "xyz", origin.get("xyz", "0 0 0"), 3)]
            rpy = _urdf_numbers(path, j, "origin", "rpy", origin.get("rpy", "0 0 0"), 3)
        T = carry @ pose_to_matrix(np.array(xyz + rpy))
        kind = j.get("type")
        if kind == "fixed":
            carry = T
        elif kind in ("revolute", "continuous", "prismatic"):
            ax = j.find("axis")
            axis_text = "1 0 0"
            if ax is not None:
                ax_xyz = ax.get("xyz")
                if ax_xyz is None:
                    raise ConfigError(f"{path}: joint {_joint_name(j)!r}: <axis> has no 'xyz' attribute")
                axis_text = ax_xyz
            axis = np.array(_urdf_numbers(path, j, "axis", "xyz", axis_text, 3))
            if not np.linalg.norm(axis) > 1e-9:
                raise ConfigError(f"{path}: joint {_joint_name(j)!r}: <axis xyz=\"{axis_text}\"> has no direction; "
                                  f"give the joint axis as a non-zero vector")
            A = _T(_axis_to_z(axis))
            specs.append(TransformSpec(f"A{len(specs)}", "prismatic" if kind == "prismatic" else "revolute"))
            poses.append(matrix_to_pose(T @ A))
            lim = j.find("limit")
            s = 1000.0 if kind == "prismatic" else 1.0
            if kind == "continuous" or lim is None:
                limits.append((-2 * math.pi, 2 * math.pi) if kind != "prismatic" else (-1e3, 1e3))
            else:
                limits.append((_urdf_limit(path, j, lim, "lower") * s, _urdf_limit(path, j, lim, "upper") * s))
            carry = invert(A)
        else:
            raise ConfigError(f"{path}: joint {j.get('name')!r} of type {kind!r} is not supported")
        link = _urdf_link(path, j, "child")
    if len(specs) == 1:
        raise ConfigError(f"{path}: no moving joints found")
    specs.append(TransformSpec("K"))
    poses.append(matrix_to_pose(carry))
    return RobotModel(root.get("name", path.stem), tuple(specs), np.concatenate(poses), np.array(limits))
