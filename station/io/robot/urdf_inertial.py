"""The link masses of a URDF chain for the compliance term (issue 30): each ``<inertial>`` (mass,
centre of mass) of the links the chain moves, in the station's frames.

:func:`station.io.robot.formats.robot_from_urdf` turns every moving joint's axis into the z axis of
its transform (a rotation ``A``), so the station's frame after joint k's motion is the URDF child
link's frame times ``A``: a centre of mass ``c`` in the child link is ``A⁻¹ c`` in the station's
frame. Links hung on by fixed joints count with the moving link before them (a flange, a tool);
links before the first moving joint do not move and are left out, as are branches off the chain
(a camera on a bracket: its mass is not counted).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from station.core.kinematics.transforms import invert
from station.core.terms.error_model import GravityModel
from station.errors import ConfigError
from station.io.robot.formats import (
    _T,
    _axis_to_z,
    _off_gimbal_lock,
    _urdf_chain,
    _urdf_link,
    _urdf_numbers,
    urdf_joint_origin,
    urdf_root,
)

__all__ = ["urdf_gravity"]


def _inertial(path: Path, link: ET.Element | None) -> tuple[float, np.ndarray] | None:
    """``(mass [kg], centre [mm] in the link frame)`` of a link's ``<inertial>``, or None."""
    el = None if link is None else link.find("inertial")
    if el is None:
        return None
    m_el = el.find("mass")
    try:
        mass = float(m_el.get("value", "")) if m_el is not None else float("nan")
    except ValueError:
        mass = float("nan")
    if not (np.isfinite(mass) and mass >= 0):
        raise ConfigError(f"{path}: link {link.get('name') if link is not None else '?'!r}: <inertial> needs "
                          f"<mass value=\"…\"/> ≥ 0 [kg]")
    origin = el.find("origin")
    xyz = np.zeros(3)
    if origin is not None:
        try:
            xyz = np.array([float(v) for v in origin.get("xyz", "0 0 0").split()], dtype=float) * 1000.0
        except ValueError:
            xyz = np.full(3, np.nan)
        if xyz.shape != (3,) or not np.all(np.isfinite(xyz)):
            raise ConfigError(f"{path}: link {link.get('name') if link is not None else '?'!r}: <inertial> "
                              f"<origin xyz> must be three numbers [m]")
    return mass, xyz


def urdf_gravity(path: str | Path, base: str | None = None, tip: str | None = None) -> GravityModel | None:
    """The :class:`GravityModel` (masses and centres of mass per moving joint) of the URDF chain
    ``base`` … ``tip``, or None when no link of the chain moves with an ``<inertial>``."""
    path = Path(path)
    root = urdf_root(path)
    base, joints = _urdf_chain(path, root, base, tip)
    links = {el.get("name"): el for el in root.findall("link")}
    link, carry = base, np.eye(4)
    masses: list[float] = []
    moments: list[np.ndarray] = []
    frame = np.eye(4)  # the current link's frame in the current moving body's station frame
    found = False
    while link in joints:
        j = joints[link]
        T_origin = urdf_joint_origin(path, j)
        T = carry @ T_origin
        if j.get("type") == "fixed":
            carry = T
            frame = frame @ T_origin
        else:
            ax = j.find("axis")
            axis = np.array(_urdf_numbers(path, j, "axis", "xyz", "1 0 0" if ax is None else ax.get("xyz", "1 0 0"), 3))
            A = _T(_axis_to_z(axis))
            A = A @ _off_gimbal_lock(T @ A)
            carry = invert(A)
            frame = invert(A)  # the child link in the station's frame after this joint: A⁻¹
            masses.append(0.0)
            moments.append(np.zeros(3))
        link = _urdf_link(path, j, "child")
        got = _inertial(path, links.get(link))
        if got is not None and masses:
            m, c = got
            masses[-1] += m
            moments[-1] += m * (frame[:3, :3] @ c + frame[:3, 3])
            found = True
    if not found:
        return None
    com = tuple(tuple(float(v) for v in (s / m if m > 0 else np.zeros(3))) for m, s in zip(masses, moments))
    return GravityModel(masses=tuple(masses), com=com)  # type: ignore[arg-type]
