"""Import of the robot descriptions users actually hold: DH, modified DH (Craig), URDF.

Every format is converted exactly into the six-parameter chain of :mod:`station.core.kinematics.model`:

* DH link i: ``Rz(θ_i + q_i) · Tz(d_i) · Tx(a_i) · Rx(α_i)``. The joint moves about z *before*
  the link's constants, so the constants of link i become the origin of the station's
  transform i+1, and those of the last link become the tool K.
* Modified DH link i: ``Rx(α_{i-1}) · Tx(a_{i-1}) · Rz(θ_i) · Tz(d_i)`` then the joint — the same
  order as the station's form, so each link maps onto one transform.
* URDF: each moving joint's origin, then a rotation that takes the joint axis onto z (undone at
  the start of the next transform); fixed joints fold into their neighbours. The chain runs
  from the root (or ``base``) link to ``tip``; a branch without ``tip`` is refused.

DH table files are CSV (``*.dh.csv`` or ``*.mdh.csv``) with units in the header, e.g.::

    type,theta [deg],d [mm],a [mm],alpha [deg],lower [deg|mm],upper [deg|mm]
    revolute,0,800,445,0,-130,130

A row of type ``fixed`` (limits left empty) is a constant link without a joint: the exporter
writes a set-up in front of axis 1 or a tool after the last axis that way. Optional columns
``sign``, ``offset [deg|mm]``, ``coupled_to``, ``k`` give the joint map (docs/robot-file.md).
"""

from __future__ import annotations

import csv
import math
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from station.core.kinematics.joint_map import JointMap, joint_map_from_file_units
from station.core.kinematics.model import RobotModel, TransformSpec
from station.core.kinematics.transforms import invert, matrix_to_pose, pose_to_matrix, rot_x, rot_z, rotation_exp
from station.errors import ConfigError
from station.io.robot.bounds import nearest
from station.io.robot.units import RawValue, check_raw_units

#: cos(pitch) below which a frame in front of a joint is turned off the gimbal lock: sin 5°, the
#: reach of the structural snap (station.core.identification.identifiability.structural_params), which would put
#: a pitch within 5° of ±90° onto the lock for the rank analysis
GIMBAL_COS = math.sin(math.radians(5.0))


def _off_gimbal_lock(M: np.ndarray) -> np.ndarray:
    """A quarter turn about z when the frame ``M`` ``(4, 4)`` in front of a joint sits at (or within
    5° of) pitch ±90°, else the identity. There roll and yaw turn about one axis and the third
    rotation has no parameter, which can cost the identification an axis tilt (station analyze,
    rank one short). A turn about the joint's own axis commutes with its motion, so the caller
    puts its inverse at the front of the next transform: the same kinematics, the same joints;
    the turned frame's pitch is the old roll's share, |pitch| ≤ 5°, and the next pitch is unchanged."""
    if math.hypot(M[0, 0], M[1, 0]) < GIMBAL_COS:
        return _T(rot_z(math.pi / 2))
    return np.eye(4)


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
        turn = _off_gimbal_lock(carry @ pre)
        poses.append(matrix_to_pose(carry @ pre @ turn))
        carry = invert(turn) @ post
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
    """The model of a DH or MDH table file (its joint map, if any, is :func:`read_dh_file`'s)."""
    return read_dh_file(path)[0]


#: the optional columns of a DH table that map the controller's joints onto the model's
#: (``offset`` has a unit like the limits; ``sign``, ``coupled_to`` and ``k`` have none)
MAP_COLUMNS = ("sign", "offset", "coupled_to", "k")
#: the optional column of each joint's maximum speed from the data sheet (``station plan``'s motion
#: time; issue 37 §3: a DH table had nowhere to put what the plan asked for)
SPEED_COLUMN = "max_speed"
#: where a robot file takes its joint speeds, whatever its format (docs/robot-file.md)
SPEED_HINT = ("add each joint's maximum speed from the robot's data sheet: in a DH table (*.dh.csv, *.mdh.csv) a "
              "column 'max_speed [deg/s|mm/s]' with one value per joint row; in a TOML robot file max_speed = … in "
              "every joint's [[transform]] (docs/robot-file.md)")
_UNITLESS = ("type", "sign", "coupled_to", "k")


def read_dh_file(path: Path) -> tuple[RobotModel, JointMap]:
    """The model of a ``*.dh.csv`` or ``*.mdh.csv`` file and its joint map (docs/robot-file.md)."""
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
    for n in names:  # an unknown column (a typo of 'offset') would otherwise be ignored
        if n not in need and n not in MAP_COLUMNS and n != SPEED_COLUMN:
            raise ConfigError(f"{path}: unknown column {n!r}{nearest(n, (*need, *MAP_COLUMNS, SPEED_COLUMN))}; the "
                              f"columns are {', '.join(need)} and optionally {', '.join(MAP_COLUMNS)}, {SPEED_COLUMN}")
    if len(set(names)) != len(names):
        raise ConfigError(f"{path}: a column appears twice ({', '.join(sorted({n for n in names if names.count(n) > 1}))}); "
                          f"keep one")
    units = {n: (_unit(h) if n not in _UNITLESS else "") for n, h in zip(names, head)}
    scale = {"deg": math.pi / 180, "rad": 1.0, "mm": 1.0, "m": 1000.0}
    out = []
    raw: list[RawValue] = []  # every number as written, for the unit plausibility before conversion
    map_rows: list[tuple[int, dict[str, str]]] = []  # (line, the map cells) of each joint row
    for k, r in enumerate(rows[1:], start=2):
        rec = dict(zip(names, (c.strip() for c in r)))
        kind = rec["type"]
        cells = {n: rec[n] for n in MAP_COLUMNS if rec.get(n)}
        if kind == "fixed" and cells:
            raise ConfigError(f"{path}, line {k}: a fixed row has no joint; leave {', '.join(cells)} empty")
        if kind != "fixed":
            map_rows.append((k, cells))
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
            role = ("angle" if n in ("theta", "alpha") else "length" if n in ("d", "a") else
                    "limit-angle" if kind == "revolute" else "limit-length")
            raw.append(RawValue(f"line {k}", f"{n} [{units[n]}]", role, u, float(rec[n])))
        out.append((kind, vals["theta"], vals["d"], vals["a"], vals["alpha"], vals["lower"], vals["upper"]))
    check_raw_units(raw, str(path), "if so, write [{unit}] for the angles in that column's header",
                    "if so, write [{unit}] for the lengths in the d and a columns' headers")
    model = robot_from_dh(out, conv, name=path.name.split(".")[0])
    if SPEED_COLUMN in names:
        model = _with_speeds(path, model, rows[1:], names, units[SPEED_COLUMN])
    return model, _dh_joint_map(path, model, map_rows, units.get("offset") or "deg|mm", scale)


def _with_speeds(path: Path, model: RobotModel, rows: list[list[str]], names: list[str], unit: str) -> RobotModel:
    """``model`` with the ``max_speed`` column's speeds [rad/s | mm/s], one per joint row (a fixed
    row leaves it empty); the unit ``deg/s|mm/s`` reads like the limits' ``deg|mm``."""
    import dataclasses

    scale = {"deg/s": math.pi / 180, "rad/s": 1.0, "mm/s": 1.0, "m/s": 1000.0}
    parts = unit.split("|")
    if any(u not in scale for u in parts):
        raise ConfigError(f"{path}: unknown unit {unit!r} in column 'max_speed'; use deg/s|mm/s (or rad/s, m/s)")
    speeds = []
    for k, r in enumerate(rows, start=2):
        rec = dict(zip(names, (c.strip() for c in r)))
        if rec["type"] == "fixed":
            continue
        u = parts[0 if rec["type"] == "revolute" else -1]
        try:
            v = float(rec.get(SPEED_COLUMN) or "nan") * scale[u]
        except ValueError:
            v = math.nan
        if not (math.isfinite(v) and v > 0):
            raise ConfigError(f"{path}, line {k}: max_speed must be a number > 0 on every joint row (the joint's "
                              f"maximum speed from the data sheet, in {u}), got {rec.get(SPEED_COLUMN)!r}")
        speeds.append(v)
    return dataclasses.replace(model, max_speed=np.array(speeds))


def _dh_joint_map(path: Path, model: RobotModel, map_rows: list[tuple[int, dict[str, str]]], offset_unit: str,
                  scale: dict[str, float]) -> JointMap:
    """The joint map of a DH table's ``sign``, ``offset``, ``coupled_to``, ``k`` columns;
    ``coupled_to`` names a joint by its number among the joint rows (``2``, ``J2`` or ``A2``)."""
    names = tuple(model.transforms[i].name for i in model.joint_transforms)
    a_unit, l_unit = offset_unit.split("|")[0], offset_unit.split("|")[-1]
    for u in (a_unit, l_unit):
        if u not in scale:
            raise ConfigError(f"{path}: unknown unit {u!r} in column 'offset'; use deg|mm, rad|mm, deg|m ...")
    entries: dict[int, dict] = {}
    for j, (line, cells) in enumerate(map_rows):
        e: dict = {}
        for n in ("sign", "offset", "k"):
            if n in cells:
                try:
                    e[n] = float(cells[n])
                except ValueError:
                    raise ConfigError(f"{path}, line {line}: {n} must be a number, got {cells[n]!r}") from None
                if not math.isfinite(e[n]):
                    raise ConfigError(f"{path}, line {line}: {n} must be a finite number, got {cells[n]!r}")
        if "coupled_to" in cells:
            text = cells["coupled_to"]
            digits = text[1:] if text[:1] in "AJaj" else text
            if not digits.isdigit() or not 1 <= int(digits) <= len(names) or int(digits) == j + 1:
                raise ConfigError(f"{path}, line {line}: coupled_to = {text!r}: give the number of another joint "
                                  f"row, 1 … {len(names)} (e.g. 2 for the second joint)")
            e["other"] = int(digits) - 1
        entries[j] = e
    try:
        return joint_map_from_file_units(names, model.joint_types, entries, scale[a_unit], scale[l_unit])
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None


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


def urdf_root(path: Path) -> ET.Element:
    """The parsed URDF's root element; XML that does not parse is a :class:`ConfigError`."""
    try:
        return ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise ConfigError(f"{path}: not valid XML ({exc})") from None


def urdf_joint_origin(path: Path, joint: ET.Element) -> np.ndarray:
    """A ``<joint>``'s ``<origin>`` as a (4, 4) transform [mm, rad] (URDF default: identity)."""
    origin = joint.find("origin")
    xyz, rpy = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
    if origin is not None:
        xyz = [v * 1000.0 for v in _urdf_numbers(path, joint, "origin", "xyz", origin.get("xyz", "0 0 0"), 3)]
        rpy = _urdf_numbers(path, joint, "origin", "rpy", origin.get("rpy", "0 0 0"), 3)
    return pose_to_matrix(np.array(xyz + rpy))


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


def _leaves(link: str, out: dict[str, list[ET.Element]], child_of: dict[int, str]) -> list[str]:
    """The links without a child joint below ``link`` (the tips a chain from it could end at)."""
    leaves, stack = [], [link]
    while stack:
        here = stack.pop()
        below = out.get(here, [])
        if not below:
            leaves.append(here)
        stack.extend(child_of[id(j)] for j in reversed(below))
    return leaves


def _urdf_names(path: Path, root: ET.Element, edges: list[tuple[ET.Element, str, str]]) -> None:
    """Every link and joint named once, and every joint's parent and child a declared link: a
    duplicate or a link that is not there would silently pick one chain out of several."""
    links: set[str] = set()
    for kind, elements in (("link", root.findall("link")), ("joint", root.findall("joint"))):
        seen: set[str] = set()
        for el in elements:
            name = el.get("name")
            if not name:
                raise ConfigError(f"{path}: a <{kind}> without a name; give every {kind} a unique name")
            if name in seen:
                raise ConfigError(f"{path}: two <{kind}> elements are named {name!r}; {kind} names must be unique "
                                  f"(rename or delete one)")
            seen.add(name)
        if kind == "link":
            links = seen
    for j, parent, child in edges:
        for tag, link in (("parent", parent), ("child", child)):
            if link not in links:
                raise ConfigError(f"{path}: joint {_joint_name(j)!r}: its {tag} link {link!r} is not declared; add "
                                  f"<link name=\"{link}\"/> or correct the name")


def _urdf_chain(path: Path, root: ET.Element, base: str | None = None,
                tip: str | None = None) -> tuple[str, dict[str, ET.Element]]:
    """The chain's first link and each of its links' joint towards the tip; refuses a loop,
    several roots (without ``base``) and a branch without ``tip`` (a chain is never flattened:
    a dropped branch would drop its joints)."""
    elements = root.findall("joint")
    edges = [(j, _urdf_link(path, j, "parent"), _urdf_link(path, j, "child")) for j in elements]
    _urdf_names(path, root, edges)
    _urdf_loop(path, edges)
    children = {c for _, _, c in edges}
    link_names = [str(link.get("name")) for link in root.findall("link")]
    known = set(link_names) | children | {p for _, p, _ in edges}
    for flag, link in (("--base", base), ("--tip", tip)):
        if link is not None and link not in known:
            raise ConfigError(f"{path}: {flag} {link!r}: no such link; the links are "
                              f"{', '.join(repr(n) for n in link_names)}")
    out: dict[str, list[ET.Element]] = {}
    child_of: dict[int, str] = {}
    parent_joint: dict[str, tuple[ET.Element, str]] = {}
    for j, parent, child in edges:
        out.setdefault(parent, []).append(j)
        child_of[id(j)] = child
        parent_joint[child] = (j, parent)
    if base is None:
        roots = [n for n in link_names if n not in children]
        if len(roots) != 1:
            raise ConfigError(f"{path}: expected one root link, found {roots}"
                              f"{'; choose the chain with --base LINK' if len(roots) > 1 else ''}")
        base = roots[0]
    if tip is not None:  # the one path up from the tip to the base
        chain: dict[str, ET.Element] = {}
        here = tip
        while here != base:
            if here not in parent_joint:
                raise ConfigError(f"{path}: --tip {tip!r} is not below --base {base!r}: the chain runs from the "
                                  f"base link down to the tip; tips below {base!r}: "
                                  f"{', '.join(repr(n) for n in _leaves(base, out, child_of))}")
            j, parent = parent_joint[here]
            chain[parent] = j
            here = parent
        return base, chain
    chain, here = {}, base
    while here in out:
        js = out[here]
        if len(js) > 1:
            tips = []
            for j in js:  # the tip each branch ends at (the first, where it branches again)
                end = child_of[id(j)]
                while len(out.get(end, [])) == 1:
                    end = child_of[id(out[end][0])]
                tips.append(f"{end!r} (joint {_joint_name(j)!r})")
            leaves = _leaves(base, out, child_of)
            raise ConfigError(f"{path}: the chain branches at link {here!r} into joints {_names_of(js)}, towards "
                              f"{' and '.join(tips)}; the station calibrates one serial chain from {base!r} to "
                              f"the flange: choose it with --tip LINK, one of {', '.join(repr(n) for n in leaves)} "
                              f"(and --base LINK for another start), or keep the branch that ends at the flange and "
                              f"delete the other branches' joints and links")
        chain[here] = js[0]
        here = child_of[id(js[0])]
    return base, chain


def robot_from_urdf(path: Path, base: str | None = None, tip: str | None = None) -> RobotModel:
    """Model of the serial chain in a URDF file: from ``base`` (default: the root link) to
    ``tip`` (default: the end of an unbranched chain; a branch without ``tip`` is refused,
    naming the tips it could use; a loop is refused, naming its joints).

    Every joint needs ``<parent link>`` and ``<child link>``; ``<origin>`` (xyz, rpy) and
    ``<axis>`` are optional with the URDF defaults (identity, x axis). A revolute or prismatic
    joint without ``<limit>`` gets ±2π rad / ±1000 mm.
    """
    root = urdf_root(path)
    base, joints = _urdf_chain(path, root, base, tip)
    link, carry = base, np.eye(4)
    specs, poses, limits = [TransformSpec("R")], [np.zeros(6)], []
    while link in joints:
        j = joints[link]
        T = carry @ urdf_joint_origin(path, j)
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
            A = A @ _off_gimbal_lock(T @ A)
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
        raise ConfigError(f"{path}: no moving joints found between links {base!r} and {link!r}"
                          f"{'' if tip is None else '; check --base and --tip'}")
    specs.append(TransformSpec("K"))
    poses.append(matrix_to_pose(carry))
    return RobotModel(root.get("name", path.stem), tuple(specs), np.concatenate(poses), np.array(limits))
