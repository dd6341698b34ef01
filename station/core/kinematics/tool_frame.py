"""The working tool after the probe head comes off (chapter §7.2): the tool-mount (flange) frame
derived from the identified head transform, and the model of a tool mounted on it.

The model is ``R · A1(q1) · … · Ag(qg) · K`` with ``K`` the last joint frame → MKKS (the probe
head frame). The minimal parameter set identifies ``K`` in full and holds the last axis's
non-identifiable parts (for a SCARA: A4's z, yaw, and the sum of the z offsets along the parallel
axes) at their nominal values, so the identified ``K`` absorbs them: it is not "the flange plus
the head's CMM geometry", and a tool must not be modelled by putting its own TCP in place of K.

What stays true is the product. With ``H`` the head frame MKKS in the flange frame (the head's
CMM report) and ``T`` a tool's TCP in the flange frame (the tool's own measurement)::

    flange (last joint frame ← flange)   F      = K · H⁻¹
    tool   (last joint frame ← TCP)      K_tool = K · H⁻¹ · T

and the tool's forward kinematics is the head's times the fixed ``H⁻¹ · T``:
``FK_tool(q) = FK_head(q) · H⁻¹ · T``. Whatever the identified chain did with the parts that
only their product fixes, the tool is right wherever the head was. Nominal and identified tools
use the same ``H`` and ``T``; only ``K`` differs (robot file vs identification).

Without a head file ``H`` falls back to the robot model's nominal ``K``
(:func:`nominal_head_in_flange`): the nominal flange is then the last joint frame, and a tool's
TCP is given in that frame.

Pure numerics: 4×4 homogeneous transforms and ``(n_params,)`` parameter vectors in mm and rad
(the layout of :class:`station.core.kinematics.model.RobotModel`); no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from station.core.kinematics.forward import forward
from station.core.kinematics.model import RobotModel
from station.core.kinematics.transforms import invert, matrix_to_pose, pose_to_matrix, rotation_log
from station.core.units import ARCSEC

__all__ = [
    "MAX_MARKER_OFFSET_MM",
    "MarkerFit",
    "ToolKinematics",
    "derive_tool",
    "fit_marker_offset",
    "flange_frame",
    "head_K",
    "nominal_head_in_flange",
    "tool_model",
    "tool_params",
    "tool_transform",
]


def _frame(T: np.ndarray, what: str) -> np.ndarray:
    M = np.asarray(T, dtype=float)
    if M.shape[-2:] != (4, 4) or not np.all(np.isfinite(M)):
        raise ValueError(f"{what} must be finite (4, 4) homogeneous transforms, got shape {M.shape}")
    R = M[..., :3, :3]
    if not np.allclose(R @ np.swapaxes(R, -1, -2), np.eye(3), atol=1e-9):
        raise ValueError(f"{what} is not a rigid transform (its rotation part is not orthonormal)")
    return M


def head_K(model: RobotModel, params: np.ndarray | None = None) -> np.ndarray:
    """The head transform K (last joint frame ← MKKS) of ``params`` ``(..., n_params)``
    (default: the model's nominal) as ``(..., 4, 4)`` [mm]."""
    p = model.nominal if params is None else np.asarray(params, dtype=float)
    if p.shape[-1] != model.n_params:
        raise ValueError(f"expected {model.n_params} parameters, got shape {p.shape}")
    return pose_to_matrix(p[..., -6:])


def nominal_head_in_flange(model: RobotModel) -> np.ndarray:
    """The fallback ``H`` while no head file gives MKKS in the flange frame: the robot model's
    nominal K, so that the nominal flange is the last joint frame ``(4, 4)``."""
    return head_K(model)


def flange_frame(K: np.ndarray, head_in_flange: np.ndarray) -> np.ndarray:
    """The tool-mount (flange) frame in the last joint frame: ``K · H⁻¹`` ``(..., 4, 4)``.

    ``K`` ``(..., 4, 4)``: last joint frame ← MKKS (nominal or identified); ``head_in_flange``
    ``(4, 4)``: flange ← MKKS from the head's CMM report."""
    return _frame(K, "K") @ invert(_frame(head_in_flange, "head_in_flange"))


def _mount(head_in_flange: np.ndarray, tcp: np.ndarray) -> np.ndarray:
    """``H⁻¹ · T`` (MKKS ← TCP); exactly the identity for a tool equal to the head."""
    H, T = _frame(head_in_flange, "head_in_flange"), _frame(tcp, "tcp")
    if np.array_equal(H, T):
        return np.eye(4)
    return invert(H) @ T


def tool_transform(K: np.ndarray, head_in_flange: np.ndarray, tcp: np.ndarray) -> np.ndarray:
    """The tool transform ``K_tool = K · H⁻¹ · T`` (last joint frame ← TCP) ``(..., 4, 4)`` [mm].

    ``tcp`` ``(4, 4)``: flange ← TCP, from the tool's measurement. A tool equal to the head
    (``tcp`` = ``head_in_flange``) gives ``K`` itself."""
    return _frame(K, "K") @ _mount(head_in_flange, tcp)


def tool_params(model: RobotModel, params: np.ndarray | None, head_in_flange: np.ndarray,
                tcp: np.ndarray) -> np.ndarray:
    """``params`` ``(..., n_params)`` [mm, rad] (default: the nominal) with K replaced by the
    tool's ``K · H⁻¹ · T``; every other parameter unchanged. A tool equal to the head returns
    the parameters unchanged (bit for bit)."""
    p = np.array(model.nominal if params is None else params, dtype=float)
    X = _mount(head_in_flange, tcp)
    if np.array_equal(X, np.eye(4)):
        return p
    p[..., -6:] = matrix_to_pose(head_K(model, p) @ X)
    return p


def tool_model(model: RobotModel, head_in_flange: np.ndarray, tcp: np.ndarray) -> RobotModel:
    """The controller's nominal model with the tool mounted: the robot file's chain with the
    nominal ``K · H⁻¹ · T`` as its last transform."""
    return model.with_params(tool_params(model, None, head_in_flange, tcp))


@dataclass(frozen=True, eq=False)
class ToolKinematics:
    """A tool on the identified robot.

    ``nominal``: the controller's model with the tool (nominal ``K_tool``); ``params``
    ``(n_params,)`` [mm, rad]: the identified parameters with the identified ``K_tool``.
    ``flange_nominal`` / ``flange_identified`` ``(4, 4)``: the tool-mount frame in the last joint
    frame, nominal and identified (``K · H⁻¹``). ``flange_shift_mm`` ``(3,)`` and
    ``flange_rotation_rad`` ``(3,)`` (rotation vector): the identified flange in the nominal
    flange frame, i.e. what K absorbed (the last axis's unidentifiable parts and the head's own
    error) as the tool sees it. ``tcp_shift_mm`` ``(3,)``: where the identified TCP lies in the
    nominal TCP frame at the same joints (the error a tool correction removes at the TCP, set-up
    and joints aside).
    """

    nominal: RobotModel
    params: np.ndarray
    flange_nominal: np.ndarray
    flange_identified: np.ndarray
    flange_shift_mm: np.ndarray
    flange_rotation_rad: np.ndarray
    tcp_shift_mm: np.ndarray

    @property
    def flange_shift_um(self) -> float:
        return float(np.linalg.norm(self.flange_shift_mm) * 1e3)

    @property
    def flange_rotation_arcsec(self) -> float:
        return float(np.linalg.norm(self.flange_rotation_rad) / ARCSEC)


def derive_tool(model: RobotModel, identified_params: np.ndarray, head_in_flange: np.ndarray | None,
                tcp: np.ndarray) -> ToolKinematics:
    """Everything about one tool on the identified robot (see :class:`ToolKinematics`).

    ``model``: the robot file's model (its nominal is the controller's); ``identified_params``
    ``(n_params,)`` [mm, rad]; ``head_in_flange`` ``(4, 4)`` or None (fallback:
    :func:`nominal_head_in_flange`); ``tcp`` ``(4, 4)`` flange ← TCP [mm]."""
    p_id = np.asarray(identified_params, dtype=float)
    if p_id.shape != model.nominal.shape or not np.all(np.isfinite(p_id)):
        raise ValueError(f"identified parameters must be a finite vector of {model.n_params} values")
    H = nominal_head_in_flange(model) if head_in_flange is None else _frame(head_in_flange, "head_in_flange")
    F_nom = flange_frame(head_K(model), H)
    F_id = flange_frame(head_K(model, p_id), H)
    D = invert(F_nom) @ F_id
    K_nom_tool = tool_transform(head_K(model), H, tcp)
    K_id_tool = tool_transform(head_K(model, p_id), H, tcp)
    return ToolKinematics(
        nominal=tool_model(model, H, tcp), params=tool_params(model, p_id, H, tcp),
        flange_nominal=F_nom, flange_identified=F_id, flange_shift_mm=D[:3, 3].copy(),
        flange_rotation_rad=rotation_log(D[:3, :3]),
        tcp_shift_mm=(invert(K_nom_tool) @ K_id_tool)[:3, 3].copy())


# --- an unknown tool or marker offset --------------------------------------------------------

#: the largest tool/marker offset from the robot file's tool that a fit takes for one [mm]: a
#: reflector on an adapter, a motion-capture marker on a plate; beyond it is no tool but a wrong
#: robot file
MAX_MARKER_OFFSET_MM = 1000.0


@dataclass(frozen=True)
class MarkerFit:
    """Result of :func:`fit_marker_offset`. ``transform`` ``(4, 4)``: measurement frame ← robot
    base (rigid); ``offset_mm`` ``(3,)``: the tool point in the last joint frame (K's translation,
    replacing the robot file's); ``shift_mm`` ``(3,)``: how far it lies from the file's tool point;
    ``residuals_mm`` ``(n,)``: per row after the fit; ``rms_mm``: their RMS; ``undetermined``: how
    many directions of the offset the data leave open (0 when the tool turns about two axes; 1 for
    a SCARA, whose tool only turns about z: its height merges with the tracker's), held at the
    robot file's values."""

    transform: np.ndarray
    offset_mm: np.ndarray
    shift_mm: np.ndarray
    residuals_mm: np.ndarray
    rms_mm: float
    undetermined: int


def _kabsch(b: np.ndarray, m: np.ndarray) -> np.ndarray:
    """Rigid ``(4, 4)`` with ``m ≈ R b + t`` (least squares, proper rotation)."""
    bc, mc = b.mean(0), m.mean(0)
    U, _, Vt = np.linalg.svd((m - mc).T @ (b - bc))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0])
    T = np.eye(4)
    T[:3, :3] = U @ D @ Vt
    T[:3, 3] = mc - T[:3, :3] @ bc
    return T


# The tracker's position enters the linear step scaled by this, so that a direction the data leave
# open goes into the tracker's position and the tool point keeps the robot file's value there.
_POSITION_SCALE = 1e6


def fit_marker_offset(model: RobotModel, joints: np.ndarray, measured_mm: np.ndarray,
                      params: np.ndarray | None = None, iterations: int = 500) -> MarkerFit:
    """Register measured tool points ``(n, 3)`` [mm] with the tool point itself unknown.

    The measured point of row i is ``R (a_i + C_i t) + p``, with ``a_i``, ``C_i`` the last joint
    frame of ``params`` (default nominal) at ``joints`` ``(n, g)`` and ``t`` the tool point in it
    (K's translation). Alternates a rigid fit (R, p for a given t) with the linear least squares
    of (t, p) for a given R until nothing moves; from the robot file's t that converges for any
    offset well below the workspace's spread, which is where a marker lies. The tool's
    orientation does not enter a point, so it stays the file's.
    """
    p = np.array(model.nominal if params is None else params, dtype=float)
    m = np.asarray(measured_mm, dtype=float)
    bare = p.copy()
    bare[-6:] = 0.0  # K = identity: the last joint frame itself
    F = forward(model, joints, bare, setup=False)
    a, C = F[:, :3, 3], F[:, :3, :3]
    t0 = p[-6:-3].copy()
    t = t0.copy()

    def points(tt: np.ndarray) -> np.ndarray:
        return a + np.einsum("nij,j->ni", C, tt)

    rank = 6
    for _ in range(iterations):
        R = _kabsch(points(t), m)[:3, :3]
        # m_i − R (a_i + C_i t0) = (R C_i) Δt + p: one (3n, 6) linear system
        A = np.concatenate([np.einsum("ij,njk->nik", R, C),
                            np.broadcast_to(np.eye(3) * _POSITION_SCALE, C.shape)], axis=2).reshape(-1, 6)
        rhs = (m - points(t0) @ R.T).reshape(-1)
        sol, _, rank, _ = np.linalg.lstsq(A, rhs, rcond=1e-9)
        t_new = t0 + sol[:3]
        step = float(np.linalg.norm(t_new - t))
        t = t_new
        if step < 1e-10 * max(1.0, float(np.linalg.norm(t))):
            break
    T = _kabsch(points(t), m)
    res = np.linalg.norm(m - (points(t) @ T[:3, :3].T + T[:3, 3]), axis=1)
    return MarkerFit(T, t, t - t0, res, float(np.sqrt(np.mean(res**2))), int(6 - rank))
