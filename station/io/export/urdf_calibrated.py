"""The calibrated joint origins written into the robot's own URDF (issue 41 §2).

The station imports a URDF chain (:func:`station.io.robot.formats.robot_from_urdf`) as
``A_k = P_k · O_k · X_k``: ``O_k`` the ``<origin>`` of moving joint k, ``P_k`` the inverse of
the previous joint's axis rotation ``X_{k-1}`` times the fixed joints' origins in between, and
``X_k`` the rotation taking the joint's ``<axis>`` onto z. An identified ``A'_k`` is written as
``O'_k = P_k⁻¹ · A'_k · X_k⁻¹``: the axis and every fixed joint stay as they are, only the
moving joints' origins change. The tool K goes into the origin of the last fixed joint of the
chain (the one whose child is the tip link); a chain that ends at a moving joint has no place
for a K other than its own, which is then named, not dropped.

Everything else in the file — comments, formatting, visuals, inertials, other branches — is
kept byte for byte: the file is edited in place at the byte offsets expat reports for each
``<joint>`` and ``<origin>`` start tag (a tag inside a comment or CDATA is no tag to expat),
and only the ``xyz`` and ``rpy`` attribute values of the chain's origins change. One XML
comment is inserted before the root element: what was written and what the URDF cannot hold
(the set-up R, error terms), so the file itself says what it lacks.

URDF ``<origin>`` is ``Trans(xyz) · Rz(yaw)·Ry(pitch)·Rx(roll)`` in metres and radians (URDF
specification, joint element, ``origin``), the station's own form: the written file holds the
model exactly but for the shortest round-trip decimal of each number.
"""

from __future__ import annotations

import re
import xml.parsers.expat
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from station.core.kinematics.model import RobotModel
from station.core.kinematics.transforms import invert, matrix_to_pose, pose_to_matrix
from station.errors import ConfigError
from station.io.robot.formats import _urdf_chain, urdf_joint_origin, urdf_root

#: K or an origin closer than this to what the file holds needs no edit [mm, rad]: round-off of
#: the import and the metre conversion, far below the parity the export promises (1 µm, 1 µrad)
_SAME = 1e-9


@dataclass(frozen=True)
class UrdfEdit:
    """The file's new bytes and what changed: ``joints`` the joints whose origins were written."""

    data: bytes
    joints: tuple[str, ...]
    notes: tuple[str, ...]


def _chain_transforms(path: Path, base: str | None, tip: str | None):
    """The chain's joints in order as ``(name, type, origin (4, 4) [mm])``."""
    root = urdf_root(path)
    first, joints = _urdf_chain(path, root, base, tip)
    out, link = [], first
    while link in joints:
        j = joints[link]
        out.append((j.get("name", ""), j.get("type", ""), urdf_joint_origin(path, j)))
        child = j.find("child")
        link = (child.get("link") or "") if child is not None else ""
    return out


def calibrated_origins(nominal: RobotModel, params: np.ndarray, chain) -> tuple[dict[str, np.ndarray], list[str]]:
    """New ``<origin>`` transforms [mm] by joint name for the model ``params`` (robot base frame:
    R is not part of a URDF chain), and notes on what the chain cannot hold."""
    p = np.asarray(params, dtype=float)
    moving = [c for c in chain if c[1] != "fixed"]
    if len(moving) != nominal.n_joints:
        raise ConfigError(f"the URDF chain has {len(moving)} moving joints, the model {nominal.n_joints}: "
                          f"the model was not identified on this chain; give the URDF (and --base-link/--tip-link) "
                          f"it was identified with")
    new: dict[str, np.ndarray] = {}
    notes: list[str] = []
    carry = np.eye(4)  # P_k accumulated: X_{k-1}⁻¹ times the fixed origins since
    k = 0
    tail: list[tuple[str, np.ndarray]] = []
    for name, kind, origin in chain:
        if kind == "fixed":
            carry = carry @ origin
            tail.append((name, origin))
            continue
        t = nominal.joint_transforms[k]
        A_nom = pose_to_matrix(nominal.nominal[6 * t: 6 * t + 6])
        X = invert(carry @ origin) @ A_nom  # the import's axis rotation, recovered from its result
        new[name] = invert(carry) @ pose_to_matrix(p[6 * t: 6 * t + 6]) @ invert(X)
        carry, tail, k = invert(X), [], k + 1
    K = pose_to_matrix(p[-6:])
    if tail:
        name, origin = tail[-1]
        before = carry @ invert(origin)
        new[tail[-1][0]] = invert(before) @ K
    elif np.abs(K - carry).max() > _SAME:
        notes.append(f"the tool K ({_pose_text(matrix_to_pose(invert(carry) @ K))} from the last joint's link) "
                     f"is not written: the chain ends at a moving joint, so the URDF has no fixed joint to hold it; "
                     f"add a fixed joint to a tool link and give it as --tip-link")
    return new, notes


def _pose_text(pose: np.ndarray) -> str:
    return (f"x {pose[0]:.4f} mm, y {pose[1]:.4f} mm, z {pose[2]:.4f} mm, roll {np.degrees(pose[3]):.6f}°, "
            f"pitch {np.degrees(pose[4]):.6f}°, yaw {np.degrees(pose[5]):.6f}°")


def _tag_spans(data: bytes, names: set[str]) -> dict[str, tuple[tuple[int, int] | None, int, int]]:
    """For each joint in ``names``: its ``<origin>`` start tag's byte span (None if it has none)
    and its own start tag's span; plus the root element's start under the key ``""``."""
    parser = xml.parsers.expat.ParserCreate()
    found: dict[str, list] = {}
    stack: list[str | None] = []  # per open element: the tracked joint's name, else None

    def start(tag, attrs):
        pos = parser.CurrentByteIndex
        if not stack:
            found[""] = [None, pos, pos]
        if tag == "joint" and len(stack) == 1 and attrs.get("name") in names:
            found[attrs["name"]] = [None, pos, _tag_end(data, pos)]
            stack.append(attrs["name"])
            return
        if tag == "origin" and len(stack) == 2 and stack[-1] is not None and found[stack[-1]][0] is None:
            found[stack[-1]][0] = (pos, _tag_end(data, pos))
        stack.append(None)

    def end(tag):
        stack.pop()

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    try:
        parser.Parse(data, True)
    except xml.parsers.expat.ExpatError as exc:
        raise ConfigError(f"the URDF is not valid XML ({exc})") from None
    return {k: (v[0], v[1], v[2]) for k, v in found.items()}


def _tag_end(data: bytes, pos: int) -> int:
    """The offset just past the ``>`` closing the start tag at ``pos`` (quotes respected)."""
    quote = None
    for i in range(pos, len(data)):
        c = data[i:i + 1]
        if quote:
            quote = None if c == quote else quote
        elif c in (b'"', b"'"):
            quote = c
        elif c == b">":
            return i + 1
    raise ConfigError("the URDF ends inside a tag")


def _origin_attrs(T: np.ndarray) -> tuple[str, str]:
    pose = matrix_to_pose(T)
    xyz = " ".join(repr(float(v) / 1000.0) for v in pose[:3])
    rpy = " ".join(repr(float(v)) for v in pose[3:])
    return xyz, rpy


def _set_attr(tag: bytes, name: str, value: str) -> bytes:
    """``tag`` with attribute ``name`` set to ``value``: its value replaced in its own quotes, or
    the attribute added before the tag's end."""
    m = re.search(rb"(\s" + name.encode() + rb"\s*=\s*)(\"[^\"]*\"|'[^']*')", tag)
    if m:
        q = m.group(2)[:1]
        return tag[:m.start(2)] + q + value.encode() + q + tag[m.end(2):]
    cut = len(tag) - (2 if tag.endswith(b"/>") else 1)
    return tag[:cut].rstrip() + f' {name}="{value}"'.encode() + tag[cut:]


def write_calibrated_urdf(path: Path, nominal: RobotModel, params: np.ndarray, base: str | None = None,
                          tip: str | None = None, header_notes: tuple[str, ...] = ()) -> UrdfEdit:
    """The URDF at ``path`` with the model ``params``' joint origins (and K) written in place."""
    data = path.read_bytes()
    chain = _chain_transforms(path, base, tip)
    new, notes = calibrated_origins(nominal, params, chain)
    originals = {name: origin for name, _, origin in chain}
    changed = {n: T for n, T in new.items() if np.abs(T - originals[n]).max() > _SAME}
    spans = _tag_spans(data, set(changed))
    edits: list[tuple[int, int, bytes]] = []
    for name, T in changed.items():
        origin, _, jend = spans[name]
        xyz, rpy = _origin_attrs(T)
        if origin is None:
            edits.append((jend, jend, f'<origin xyz="{xyz}" rpy="{rpy}"/>'.encode()))
        else:
            tag = _set_attr(_set_attr(data[origin[0]:origin[1]], "xyz", xyz), "rpy", rpy)
            edits.append((origin[0], origin[1], tag))
    notes = [*notes, *header_notes]
    root = spans[""][1]
    edits.append((root, root, _header(sorted(changed), notes).encode()))
    out = data
    for a, b, text in sorted(edits, key=lambda e: e[0], reverse=True):
        out = out[:a] + text + out[b:]
    return UrdfEdit(out, tuple(sorted(changed)), tuple(notes))


def _header(joints: list[str], notes: list[str]) -> str:
    written = ", ".join(joints) if joints else "(none: the model is the file's own)"
    lines = [f"station export-model (format urdf): the calibrated origins of the joints {written} are written in place "
             "(URDF origin = Trans(xyz) · Rz(yaw)·Ry(pitch)·Rx(roll), m and rad); the rest of the file is as it was."]
    lines += [f"NOT HELD: {n}" for n in notes]
    body = "\n     ".join(s.replace("--", "- -") for s in lines)  # '--' may not appear inside a comment
    return f"<!-- {body} -->\n"
