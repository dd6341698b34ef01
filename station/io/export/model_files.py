"""Export of a (identified) model to the formats users feed to controllers and simulators.

* ``toml`` — the station's own robot file, angles in radians written with ``repr``: exact.
* ``urdf`` — one joint per transform: ``<origin xyz rpy>`` is exactly the station's
  ``Trans(x,y,z)·Rz(yaw)·Ry(pitch)·Rx(roll)``, the axis is ``0 0 1``; the set-up R and the tool K
  become fixed joints. Exact (metres written with ``repr``).
* ``mdh`` / ``dh`` — modified (Craig) / standard Denavit–Hartenberg rows in the CSV of
  docs/robot-file.md. Frames are placed on the joint axes by common normals, so each joint is one
  row. What four parameters per joint cannot hold — a general set-up in front of axis 1, a general
  tool after the last axis — is written as ``fixed`` rows (no joint), which keeps the export exact.
  A pair of nearly (not exactly) parallel axes has its common normal far away: DH can then hold
  the model only with offsets of kilometres, which no controller accepts. Beyond
  ``MAX_COMMON_NORMAL_MM`` the pair is written as parallel and the tilt is lost; the loss is
  measured, not estimated.

Every export is re-imported and its forward kinematics compared with the model's at joint
values spread over the limits; :class:`ExportResult` states the largest position [µm] and
orientation [″] difference (0 within round-off when the format holds the model exactly).
"""

from __future__ import annotations

import math
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from station.core.kinematics.forward import forward
from station.core.kinematics.model import RobotModel, robot_to_toml
from station.core.kinematics.poses import spread_joints
from station.core.kinematics.transforms import invert, matrix_to_pose, pose_error, rot_x, rot_z
from station.core.units import ARCSEC, UM
from station.errors import ConfigError

FORMATS = ("mdh", "dh", "urdf", "toml")
MAX_COMMON_NORMAL_MM = 1e4
_EPS = 1e-12


@dataclass(frozen=True)
class ExportResult:
    """The file's text and what the format lost, measured over the workspace."""

    fmt: str
    text: str
    max_position_um: float
    max_angle_arcsec: float
    notes: tuple[str, ...]

    @property
    def exact(self) -> bool:
        return self.max_position_um < 1e-3 and self.max_angle_arcsec < 1e-3


def _T(R=None, t=(0.0, 0.0, 0.0)) -> np.ndarray:
    T = np.eye(4)
    if R is not None:
        T[:3, :3] = R
    T[:3, 3] = t
    return T


def _mdh_matrix(alpha, a, theta, d) -> np.ndarray:
    return _T(rot_x(alpha)) @ _T(t=(a, 0, 0)) @ _T(rot_z(theta)) @ _T(t=(0, 0, d))


def _mdh_link(A: np.ndarray) -> tuple[tuple[float, float, float, float], float]:
    """MDH parameters (α, a, θ, d) of the transform ``A`` and how far ``A`` is from them."""
    alpha = math.atan2(-A[1, 2], A[2, 2])
    theta = math.atan2(-A[0, 1], A[0, 0])
    a = float(A[0, 3])
    d = float(-math.sin(alpha) * A[1, 3] + math.cos(alpha) * A[2, 3])
    err = float(np.abs(_mdh_matrix(alpha, a, theta, d) - A).max())
    return (alpha, a, theta, d), err


def _closest(p1, d1, p2, d2):
    """Closest points of two non-parallel lines; None where the lines are parallel to within
    round-off (``a·c − b²`` is 0 in doubles below a tilt of about 1e-8 rad)."""
    w0 = p1 - p2
    a, b, c, d, e = d1 @ d1, d1 @ d2, d2 @ d2, d1 @ w0, d2 @ w0
    den = a * c - b * b
    if not den > 0.0:
        return None
    t, s = (b * e - c * d) / den, (a * e - b * d) / den
    P, Q = p1 + t * d1, p2 + s * d2
    return (P, Q) if np.all(np.isfinite(P)) and np.all(np.isfinite(Q)) else None


def _two_links(A: np.ndarray) -> list[tuple[float, float, float, float]]:
    """Any rigid transform as two MDH links: a fixed one, then one ending on ``A``'s z axis."""
    x0 = np.array([1.0, 0.0, 0.0])
    z1, o1 = A[:3, 2], A[:3, 3]
    n = np.cross(x0, z1)
    if np.linalg.norm(n) > 1e-9:
        P, Q = _closest(np.zeros(3), x0, o1, z1)
        zm = n / np.linalg.norm(n)
    else:
        w = o1 - (o1 @ x0) * x0
        P = np.zeros(3)
        zm = w / np.linalg.norm(w) if np.linalg.norm(w) > 1e-9 else np.array([0.0, 0.0, 1.0])
        Q = P + (w @ zm) * zm
    xm = np.cross(zm, z1)
    xm /= np.linalg.norm(xm)
    M = _T(np.column_stack([xm, np.cross(zm, xm), zm]), Q)
    first, _ = _mdh_link(M)
    second, _ = _mdh_link(invert(M) @ A)
    return [first, second]


def mdh_rows(model: RobotModel, params=None, setup: bool = True) -> tuple[list[tuple], list[str]]:
    """Rows ``(type, θ, d, a, α)`` [rad, mm] of the MDH convention (each row's α, a act before
    its θ, d and joint) and notes on what could not be held exactly."""
    p = model.nominal if params is None else np.asarray(params, dtype=float)
    notes: list[str] = []
    g = model.n_joints
    x = np.zeros(3)
    # Station joint frames at q = 0 (the frame whose z is the joint axis, before the motion).
    frames = []
    T = pose_to_frame(p[0:6]) if setup else np.eye(4)
    for t in range(1, len(model.transforms)):
        T = T @ pose_to_frame(p[6 * t: 6 * t + 6])
        if model.transforms[t].joint is not None:
            frames.append(T)
    tool = T
    z = [F[:3, 2] for F in frames]
    o = [F[:3, 3] for F in frames]
    mdh = []
    for i in range(g):
        if i == g - 1:
            origin, x = o[i], frames[i][:3, 0]
        else:
            n = np.cross(z[i], z[i + 1])
            origin = None
            if np.linalg.norm(n) > 1e-9:
                closest = _closest(o[i], z[i], o[i + 1], z[i + 1])
                tilt = f"{np.degrees(np.arcsin(min(1.0, float(np.linalg.norm(n))))) * 3600:.3g}″"
                if closest is not None and np.linalg.norm(closest[0] - o[i]) <= MAX_COMMON_NORMAL_MM:
                    P, Q = closest
                    origin = P
                    x = (Q - P) if np.linalg.norm(Q - P) > 1e-9 else n
                elif closest is not None:
                    notes.append(f"axes {i + 1} and {i + 2} are nearly parallel ({tilt}); their common normal "
                                 f"lies {np.linalg.norm(closest[0] - o[i]) / 1000:.0f} m away, so they are "
                                 f"written as parallel")
                else:  # the tilt is below what doubles resolve: no common normal to place
                    notes.append(f"axes {i + 1} and {i + 2} are parallel but for a tilt of {tilt}, too small to "
                                 f"place a common normal; they are written as parallel")
            if origin is None:
                origin = o[i]
                w = (o[i + 1] - o[i]) - ((o[i + 1] - o[i]) @ z[i]) * z[i]
                x = w if np.linalg.norm(w) > 1e-9 else frames[i][:3, 0]
                x = x - (x @ z[i]) * z[i]
        x = x / np.linalg.norm(x)
        mdh.append(_T(np.column_stack([x, np.cross(z[i], x), z[i]]), origin))
    rows: list[tuple] = []
    prev = np.eye(4)
    for i, F in enumerate(mdh):
        A = invert(prev) @ F
        (alpha, a, theta, d), err = _mdh_link(A)
        if err > 1e-9 and i == 0:
            (a1, aa1, t1, d1), (alpha, a, theta, d) = _two_links(A)
            rows.append(("fixed", t1, d1, aa1, a1))
        rows.append((model.joint_types[i], theta, d, a, alpha))
        prev = F
    rest = invert(prev) @ tool
    if np.abs(rest - np.eye(4)).max() > 1e-12:
        (alpha, a, theta, d), err = _mdh_link(rest)
        if err > 1e-9:
            for al, aa, th, dd in _two_links(rest):
                rows.append(("fixed", th, dd, aa, al))
        else:
            rows.append(("fixed", theta, d, a, alpha))
    return rows, notes


def pose_to_frame(pose: np.ndarray) -> np.ndarray:
    from station.core.kinematics.transforms import pose_to_matrix

    return pose_to_matrix(np.asarray(pose, dtype=float))


def _dh_from_mdh(rows: list[tuple]) -> list[tuple]:
    """Standard DH rows from MDH rows: Rx(α)Tx(a) commute, so each row's (α, a) moves to the end
    of the row before it; the first row's (α, a) becomes a fixed row in front."""
    out = []
    if abs(rows[0][3]) > 0 or abs(rows[0][4]) > 0:
        out.append(("fixed", 0.0, 0.0, rows[0][3], rows[0][4]))
    for k, (kind, theta, d, _, _) in enumerate(rows):
        nxt = rows[k + 1] if k + 1 < len(rows) else ("fixed", 0.0, 0.0, 0.0, 0.0)
        out.append((kind, theta, d, nxt[3], nxt[4]))
    return out


def _dh_csv(model: RobotModel, rows: list[tuple], convention: str) -> str:
    lines = [f"# {model.name}: {convention.upper()} rows exported by the station "
             f"({'Rx(alpha)·Tx(a)·Rz(theta)·Tz(d), then the joint' if convention == 'mdh' else 'Rz(theta)·Tz(d)·Tx(a)·Rx(alpha), joint in theta/d'}); "
             "'fixed' rows carry no joint",
             "type,theta [rad],d [mm],a [mm],alpha [rad],lower [rad|mm],upper [rad|mm]"]
    j = 0
    for kind, theta, d, a, alpha in rows:
        if kind == "fixed":
            lo = hi = ""
        else:
            lo, hi = repr(float(model.joint_limits[j, 0])), repr(float(model.joint_limits[j, 1]))
            j += 1
        lines.append(",".join([kind, repr(float(theta)), repr(float(d)), repr(float(a)), repr(float(alpha)), lo, hi]))
    return "\n".join(lines) + "\n"


def _urdf(model: RobotModel, params: np.ndarray, setup: bool) -> str:
    def origin(pose):
        xyz = " ".join(repr(float(v) / 1000.0) for v in pose[:3])
        rpy = " ".join(repr(float(v)) for v in pose[3:])
        return f'<origin xyz="{xyz}" rpy="{rpy}"/>'

    out = ['<?xml version="1.0"?>',
           f'<!-- {model.name}: exported by the station; each joint origin is the station transform '
           f'Trans(x,y,z)·Rz(yaw)·Ry(pitch)·Rx(roll), the joint about/along its z axis. '
           f'Kinematics only: effort and velocity limits are placeholders. -->',
           f'<robot name="{model.name}">']
    links = ["world" if setup else "base_link"]
    body = []
    if setup:
        links.append("base_link")
        body.append(f'  <joint name="setup_R" type="fixed"><parent link="world"/><child link="base_link"/>'
                    f'{origin(params[0:6])}</joint>')
    j = 0
    for t in range(1, len(model.transforms)):
        spec = model.transforms[t]
        child = f"link_{spec.name}" if spec.joint else "tool0"
        pose = params[6 * t: 6 * t + 6]
        if spec.joint:
            lo, hi = model.joint_limits[j]
            s = 1000.0 if spec.joint == "prismatic" else 1.0
            body.append(f'  <joint name="joint_{spec.name}" type="{spec.joint}"><parent link="{links[-1]}"/>'
                        f'<child link="{child}"/>{origin(pose)}<axis xyz="0 0 1"/>'
                        f'<limit lower="{float(lo) / s!r}" upper="{float(hi) / s!r}" effort="0" velocity="0"/></joint>')
            j += 1
        else:
            body.append(f'  <joint name="tool_{spec.name}" type="fixed"><parent link="{links[-1]}"/>'
                        f'<child link="{child}"/>{origin(pose)}</joint>')
        links.append(child)
    out += [f'  <link name="{n}"/>' for n in links] + body + ["</robot>"]
    return "\n".join(out) + "\n"


def _reimport(fmt: str, text: str) -> RobotModel:
    from station.io.robot.files import load_robot

    suffix = {"mdh": ".mdh.csv", "dh": ".dh.csv", "urdf": ".urdf", "toml": ".toml"}[fmt]
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / f"export{suffix}"
        path.write_text(text)
        return load_robot(path)


def fk_difference(model: RobotModel, params, other: RobotModel, setup: bool, n: int = 500,
                  seed: int = 0) -> tuple[float, float]:
    """Largest position [mm] and orientation [rad] difference of two models' forward kinematics
    at ``n`` joint configurations spread over ``model``'s limits."""
    q = spread_joints(model, n, np.random.default_rng(seed), margin=0.0)
    e = pose_error(forward(other, q, setup=setup), forward(model, q, params, setup=setup))
    return float(np.linalg.norm(e[:, :3], axis=1).max()), float(np.linalg.norm(e[:, 3:], axis=1).max())


def export_model(model: RobotModel, fmt: str, params=None, setup: bool = True) -> ExportResult:
    """The model (with ``params``, default its own) in ``fmt``; re-imported and compared.

    ``setup=False`` leaves the set-up R out: the file then describes the robot in its base frame.
    """
    if fmt not in FORMATS:
        raise ConfigError(f"unknown export format {fmt!r}; use one of {', '.join(FORMATS)}")
    p = np.array(model.nominal if params is None else params, dtype=float)
    if not setup:
        p[:6] = 0.0
    notes: list[str] = []
    if fmt == "toml":
        text = robot_to_toml(model, p, angle_unit="rad")
    elif fmt == "urdf":
        text = _urdf(model, p, setup)
    else:
        rows, notes = mdh_rows(model, p, setup=True)
        if fmt == "dh":
            rows = _dh_from_mdh(rows)
        text = _dh_csv(model, rows, fmt)
        n_fixed = sum(r[0] == "fixed" for r in rows)
        if n_fixed:
            notes.append(f"{n_fixed} fixed row(s) hold the set-up and tool transforms that "
                         f"{fmt.upper()}'s four parameters per joint cannot")
    back = _reimport(fmt, text)
    dp, da = fk_difference(model, p, back, setup=True)
    if dp > 1e-6 or da > 1e-9:
        notes.append(f"{fmt.upper()} cannot hold this model exactly: forward kinematics differ by up to "
                     f"{dp / UM:.2f} µm and {da / ARCSEC:.2f}″ over the workspace")
    return ExportResult(fmt, text, dp / UM, da / ARCSEC, tuple(notes))


def model_pose(model: RobotModel, q) -> np.ndarray:
    """Poses ``(n, 6)`` of the model at ``q`` (a convenience for callers comparing files)."""
    return matrix_to_pose(forward(model, q))
