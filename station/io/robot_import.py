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
        # refused before the trigonometry: a NaN or inf would become a NaN model (and a warning)
        bad = [n for n, v in zip(("theta", "d", "a", "alpha", "lower", "upper"), (theta, d, a, alpha, lo, hi))
               if not math.isfinite(v)]
        if bad:
            raise ConfigError(f"DH row {i}: {', '.join(bad)} must be {'a finite number' if len(bad) == 1 else 'finite numbers'}"
                              "; give the values from the robot's data sheet")
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
            if not math.isfinite(vals[n]):
                raise ConfigError(f"{path}, line {k}: {n} must be a finite number, got {rec[n]!r}") from None
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


def _names_of(joints: Sequence[ET.Element]) -> str:
    return ", ".join(repr(_joint_name(j)) for j in joints)


def _urdf_loop(path: Path, edges: list[tuple[ET.Element, str, str]]) -> None:
    """Refuse a closed kinematic loop, naming its joints: a joint whose child is an ancestor
    of its parent (a directed cycle), or a link that two joints lead to."""
    out: dict[str, list[tuple[ET.Element, str]]] = {}
    into: dict[str, list[tuple[ET.Element, str]]] = {}
    for j, parent, child in edges:
        out.setdefault(parent, []).append((j, child))
        into.setdefault(child, []).append((j, parent))
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    for start in out:
        if state.get(start):
            continue
        path_links: list[str] = [start]
        path_joints: list[ET.Element] = []
        stack = [iter(out.get(start, []))]
        state[start] = 1
        while stack:  # iterative depth-first search (a long chain must not hit the recursion limit)
            step = next(stack[-1], None)
            if step is None:
                state[path_links.pop()] = 2
                stack.pop()
                if path_joints:
                    path_joints.pop()
                continue
            j, child = step
            if state.get(child) == 1:
                k = path_links.index(child)
                cycle = [*path_joints[k:], j]
                links = " -> ".join([*path_links[k:], child])
                raise ConfigError(f"{path}: joints {_names_of(cycle)} form a closed loop ({links}): a URDF for "
                                  "the station is one serial chain; remove the joint that closes the loop")
            if not state.get(child):
                state[child] = 1
                path_links.append(child)
                path_joints.append(j)
                stack.append(iter(out.get(child, [])))
    for link, parents in into.items():
        if len(parents) > 1:
            (j1, p1), (j2, p2) = parents[:2]
            up1, up2 = _ancestors(p1, into), _ancestors(p2, into)
            common = next((a for a in up1 if a in up2), None)
            loop = [j1] + (up1[common] + up2[common] if common is not None else []) + [j2]
            raise ConfigError(f"{path}: link {link!r} has two parents (joints {_names_of([j for j, _ in parents])}): joints "
                              f"{_names_of(list(dict.fromkeys(loop)))} close a loop; a URDF for the station is one "
                              "serial chain: remove the joints of the loop that are not in it")


def _ancestors(link: str, into: dict[str, list[tuple[ET.Element, str]]]) -> dict[str, list[ET.Element]]:
    """Each ancestor of ``link`` (itself first) with the joints leading down from it, nearest first
    (breadth first over every parent; called only once no directed cycle is left)."""
    found: dict[str, list[ET.Element]] = {link: []}
    queue = [link]
    while queue:
        here = queue.pop(0)
        for j, parent in into.get(here, []):
            if parent not in found:
                found[parent] = [*found[here], j]
                queue.append(parent)
    return found


def _urdf_chain(path: Path, root: ET.Element) -> tuple[str, dict[str, ET.Element]]:
    """The root link and each link's joint towards the tip; refuses a loop, several roots and a
    branch (a chain is never flattened: a dropped branch would drop its joints)."""
    elements = root.findall("joint")
    edges = [(j, _urdf_link(path, j, "parent"), _urdf_link(path, j, "child")) for j in elements]
    _urdf_loop(path, edges)
    children = {c for _, _, c in edges}
    roots = [link.get("name") for link in root.findall("link") if link.get("name") not in children]
    if len(roots) != 1:
        raise ConfigError(f"{path}: expected one root link, found {roots}")
    out: dict[str, list[ET.Element]] = {}
    child_of = {}
    for j, parent, child in edges:
        out.setdefault(parent, []).append(j)
        child_of[id(j)] = child
    for link, js in out.items():
        if len(js) > 1:
            tips = []
            for j in js:  # the tip each branch ends at (the first, where it branches again)
                here = child_of[id(j)]
                while len(out.get(here, [])) == 1:
                    here = child_of[id(out[here][0])]
                tips.append(f"{here!r} (joint {_joint_name(j)!r})")
            raise ConfigError(f"{path}: the chain branches at link {link!r} into joints {_names_of(js)}, towards "
                              f"{' and '.join(tips)}; the station calibrates one serial chain from {roots[0]!r} to "
                              "the flange: keep the branch that ends at the flange and delete the other "
                              "branches' joints and links")
    return str(roots[0]), {link: js[0] for link, js in out.items()}


def robot_from_urdf(path: Path) -> RobotModel:
    """Model of the serial chain in a URDF file: one chain from the root link to the tip
    (a loop or a branch is refused, naming the joints).

    Every joint needs ``<parent link>`` and ``<child link>``; ``<origin>`` (xyz, rpy) and
    ``<axis>`` are optional with the URDF defaults (identity, x axis). A revolute or prismatic
    joint without ``<limit>`` gets ±2π rad / ±1000 mm.
    """
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise ConfigError(f"{path}: not valid XML ({exc})") from None
    base, joints = _urdf_chain(path, root)
    link, carry = base, np.eye(4)
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
