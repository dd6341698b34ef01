"""Start values of the inverse kinematics (:mod:`station.core.kinematics.ik` refines them on the full model).

* A six-axis arm whose geometry has axis 1 ⟂ axis 2, axes 2 ∥ 3 and a spherical wrist: the
  closed form of that idealised geometry gives eight branches (Paden–Kahan subproblems on the
  axis lines at q = 0), each with how far its wrist centre lies outside the idealised arm's reach.
* A SCARA: its two closed-form elbows (:func:`station.core.kinematics.forward.scara_closed_form`).
* Any other chain: a fixed set of start values spread over the limits, the same every call.

Shapes and units: targets ``(n, 4, 4)`` [mm]; start values ``(n, m, g)`` [rad | mm].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from station.core.kinematics.forward import _chain, _cross, _params, scara_closed_form
from station.core.kinematics.ik_geometry import _axes, _closest_point, _is_six_r, _unit
from station.core.kinematics.model import RobotModel
from station.core.kinematics.transforms import invert, pose_to_matrix

__all__ = ["has_closed_form"]

_TWO_PI = 2.0 * np.pi
_N_GENERIC_SEEDS = 24
#: a closed-form branch whose wrist centre lies this far [mm] outside the idealised arm's reach is
#: not refined (the identified geometry differs from the ideal one by far less)
_HOPELESS_MM = 5.0


def _rodrigues(w: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Rotations ``(..., 3, 3)`` about the unit axis ``w`` ``(3,)`` or ``(..., 3)`` by ``theta`` ``(...)``."""
    w = np.broadcast_to(w, np.shape(theta) + (3,))
    K = np.zeros(w.shape[:-1] + (3, 3))
    K[..., 0, 1], K[..., 0, 2] = -w[..., 2], w[..., 1]
    K[..., 1, 0], K[..., 1, 2] = w[..., 2], -w[..., 0]
    K[..., 2, 0], K[..., 2, 1] = -w[..., 1], w[..., 0]
    s, c = np.sin(theta)[..., None, None], np.cos(theta)[..., None, None]
    return np.eye(3) + s * K + (1.0 - c) * (K @ K)


def _sub1(w, u, v) -> np.ndarray:
    """Angle rotating ``u`` onto ``v`` about the unit axis ``w`` (components along ``w`` dropped)."""
    up = u - np.einsum("...i,...i->...", u, w)[..., None] * w
    vp = v - np.einsum("...i,...i->...", v, w)[..., None] * w
    return np.arctan2(np.einsum("...i,...i->...", w, _cross(up, vp)), np.einsum("...i,...i->...", up, vp))


def _perp(x, ax) -> np.ndarray:
    """``x`` without its component along the unit vector ``ax``."""
    return x - np.einsum("...i,i->...", x, ax)[..., None] * ax


def _acos_pair(a, b, c) -> tuple[np.ndarray, np.ndarray]:
    """The two solutions x of ``a cos x + b sin x = c`` (clipped to the nearest when none)."""
    r = np.hypot(a, b)
    phi = np.arctan2(b, a)
    d = np.arccos(np.clip(c / np.where(r > 0, r, 1.0), -1.0, 1.0))
    return phi + d, phi - d


@dataclass(frozen=True)
class _ArmGeometry:
    p: np.ndarray  # (6, 3) points on the axes at q = 0
    w: np.ndarray  # (6, 3) axis directions at q = 0
    M: np.ndarray  # (4, 4) tool at q = 0
    c: np.ndarray  # (3,) wrist centre at q = 0


def _arm_geometry(model: RobotModel, params, setup: bool, tol_angle: float = 0.02,
                  tol_mm: float = 1.0) -> _ArmGeometry | None:
    """The axis lines at q = 0 if the closed form applies, else None."""
    if not _is_six_r(model):
        return None
    p, w = _axes(model, np.zeros(6), params, setup)
    M = _chain(model, np.zeros((1, 6)), params, setup, keep_frames=False)[0][0]
    if abs(w[0] @ w[1]) > tol_angle or np.linalg.norm(_cross(w[1], w[2])) > tol_angle:
        return None
    if min(np.linalg.norm(_cross(w[3], w[4])), np.linalg.norm(_cross(w[4], w[5]))) < 0.1:
        return None
    c = _closest_point(p[3:6], w[3:6])
    for k in (3, 4, 5):  # the wrist axes pass through one point
        d = c - p[k]
        if np.linalg.norm(d - (d @ w[k]) * w[k]) > tol_mm:
            return None
    return _ArmGeometry(p, w, M, c)


def has_closed_form(model: RobotModel, params=None, setup: bool = False) -> bool:
    """Whether the geometry allows the eight closed-form start values (the module docstring)."""
    return _arm_geometry(model, _params(model, params), setup) is not None


def _arm_seeds(geo: _ArmGeometry, Tt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(n, 8, 6)`` closed-form joints of the idealised arm, in :data:`station.core.kinematics.ik.ALL_ARM_CONFIGS`' branch
    order (the branches are relabelled from the refined joints afterwards), and ``(n, 8)`` how far
    [mm] each branch's wrist centre lies outside the idealised arm's reach (0 inside)."""
    p, w = geo.p, geo.w
    n = Tt.shape[0]
    c_tool = invert(geo.M) @ np.append(geo.c, 1.0)
    wt = (Tt @ c_tool)[:, :3]  # (n, 3) wrist centre of each target
    # q1: the wrist centre's component along the turned axis 2 is the arm's lateral offset.
    w2 = _unit(w[1] - (w[1] @ w[0]) * w[0])
    d_lat = (geo.c - p[0]) @ w2
    v = wt - p[0]
    a1, b1 = v @ w2, v @ _cross(w[0], w2)
    q1a, q1b = _acos_pair(a1, b1, np.full(n, d_lat))
    out = np.empty((n, 8, 6))
    excess = np.zeros((n, 8))
    ex1 = np.maximum(abs(d_lat) - np.hypot(a1, b1), 0.0)  # inside the shoulder's cylinder
    for i1, q1 in enumerate((q1a, q1b)):
        R1 = _rodrigues(w[0], -q1)
        w1 = p[0] + np.einsum("nij,nj->ni", R1, wt - p[0])  # target wrist centre, arm turned back
        # q3 (subproblem 3 in the plane normal to axis 2): |c3 + R(q3) u| = δ
        u = _perp(geo.c - p[2], w[1])
        c3 = _perp(p[2] - p[1], w[1])
        d1 = _perp(w1 - p[1], w[1])
        delta2 = np.einsum("ni,ni->n", d1, d1)
        rhs = 0.5 * (delta2 - c3 @ c3 - u @ u)
        q3a, q3b = _acos_pair(np.full(n, c3 @ u), np.full(n, c3 @ _cross(w[2], u)), rhs)
        la, lb, dist = np.linalg.norm(c3), np.linalg.norm(u), np.sqrt(delta2)
        ex3 = np.maximum(np.maximum(dist - (la + lb), abs(la - lb) - dist), 0.0)  # beyond the arm's reach
        excess[:, 4 * i1: 4 * i1 + 4] = np.maximum(ex1, ex3)[:, None]
        for i3, q3 in enumerate((q3a, q3b)):
            R3 = _rodrigues(w[2], q3)
            x = p[2] + np.einsum("nij,j->ni", R3, geo.c - p[2])
            q2 = _sub1(w[1], x - p[1], w1 - p[1])
            R2 = _rodrigues(w[1], q2)
            R123 = _rodrigues(w[0], q1) @ R2 @ R3
            G = np.swapaxes(R123, -1, -2) @ Tt[:, :3, :3] @ geo.M[:3, :3].T
            # subproblem 2: R4(q4) R5(q5) w6 = G w6
            a, b = w[3], w[4]
            xx, yy = w[5], np.einsum("nij,j->ni", G, w[5])
            ab = a @ b
            den = ab * ab - 1.0
            alpha = (ab * (b @ xx) - yy @ a) / den
            beta = (ab * (yy @ a) - b @ xx) / den
            cab = _cross(a, b)
            g2 = (1.0 - alpha ** 2 - beta ** 2 - 2 * alpha * beta * ab) / (cab @ cab)
            g = np.sqrt(np.clip(g2, 0.0, None))
            for i5, sgn in enumerate((1.0, -1.0)):
                z = alpha[:, None] * a + beta[:, None] * b + (sgn * g)[:, None] * cab
                q5 = _sub1(b, np.broadcast_to(xx, z.shape), z)
                q4 = _sub1(a, z, yy)
                R45 = _rodrigues(a, q4) @ _rodrigues(b, q5)
                ref = _unit(_cross(w[5], np.array([1.0, 0.0, 0.0])) if abs(w[5][0]) < 0.9
                            else _cross(w[5], np.array([0.0, 1.0, 0.0])))
                q6 = _sub1(w[5], np.broadcast_to(ref, (n, 3)),
                           np.einsum("nji,njk,k->ni", R45, G, ref))
                out[:, 4 * i1 + 2 * i3 + i5] = np.stack([q1, q2, q3, q4, q5, q6], axis=-1)
    return out, excess


def _spread_seeds(model: RobotModel) -> np.ndarray:
    """``(m, g)`` fixed start values spread over the limits (mid-range first; the same every call)."""
    lim = model.joint_limits
    lo = np.where(lim[:, 1] - lim[:, 0] > _TWO_PI, -np.pi, lim[:, 0])
    hi = np.where(lim[:, 1] - lim[:, 0] > _TWO_PI, np.pi, lim[:, 1])
    u = np.random.default_rng(0).uniform(size=(_N_GENERIC_SEEDS - 1, model.n_joints))
    return np.vstack([0.5 * (lo + hi), lo + 0.05 * (hi - lo) + 0.9 * (hi - lo) * u])


def _seeds(model: RobotModel, Tt: np.ndarray, p, setup: bool, near) -> tuple[np.ndarray, np.ndarray, bool]:
    """``(n, m, g)`` start values (the module docstring), ``(n, m)`` which of them are hopeless (a
    closed-form branch more than :data:`_HOPELESS_MM` out of reach: not refined) and whether they
    come from a closed form."""
    n = Tt.shape[0]
    closed = True
    hopeless = None
    if model.is_scara:
        Tb = invert(pose_to_matrix(p[0:6]))[None] @ Tt if setup else Tt
        seeds = np.stack([scara_closed_form(model, Tb, e, p)[0] for e in (1, -1)], axis=1)
    else:
        geo = _arm_geometry(model, p, setup)
        if geo is not None:
            seeds, excess = _arm_seeds(geo, Tt)
            hopeless = excess > _HOPELESS_MM
        else:
            closed = False
            grid = _spread_seeds(model)
            seeds = np.broadcast_to(grid, (n,) + grid.shape).copy()
    if hopeless is None:
        hopeless = np.zeros(seeds.shape[:2], dtype=bool)
    if near is not None:
        seeds = np.concatenate([seeds, near[:, None, :]], axis=1)
        hopeless = np.concatenate([hopeless, np.zeros((n, 1), dtype=bool)], axis=1)
    return seeds, hopeless, closed
