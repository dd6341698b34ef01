"""The pose design with the error terms beyond geometry (issue 30): the Jacobians that
:func:`station.core.identification.pose_design.select_i_optimal` takes, with the terms' columns beside the
geometric parameters', so that an I-optimal design determines the terms too and weighs what they
leave uncertain at the working poses. Pure numerics, mm and rad inside.
"""

from __future__ import annotations

import numpy as np

from station.core.kinematics.forward import forward_with_jacobian, joint_jacobian
from station.core.kinematics.model import RobotModel
from station.core.terms.error_model import TermBasis, TermSpec, term_basis

__all__ = ["design_jacobians", "term_columns"]


def term_columns(model: RobotModel, joints: np.ndarray, params, basis: TermBasis) -> np.ndarray:
    """``(n, 6, k)``: the change of the tool pose (x, y, z [mm], rotation vector [rad]) per unit of
    every term of ``basis`` (built at ``joints`` ``(n, g)``), at the geometry ``params``."""
    Jq = joint_jacobian(model, joints, params, setup=True).J
    cols = np.einsum("nrg,ngk->nrk", Jq, basis.B)
    cols[:, :3, :] += basis.D
    return cols


def design_jacobians(model: RobotModel, params, chosen_index, spec: TermSpec, candidates: np.ndarray,
                     working: np.ndarray, sigma: np.ndarray, kind: str = "pose") -> tuple[np.ndarray, np.ndarray,
                                                                                           tuple[str, ...]]:
    """``J`` ``(c, r, p + k)``: the σ-weighted Jacobian rows (``r`` = 6 pose, 3 position) of every
    candidate pose ``(c, g)`` over the geometric parameters ``chosen_index`` and the terms of
    ``spec`` (drift and backlash describe a run, not a pose: give the joint families); ``G``
    ``(m, 3, p + k)``: the position Jacobian [mm per unit] at the working poses ``(m, g)``; and the
    terms' names. The compliance terms are those the gravity loads over the candidates."""
    idx = np.asarray(chosen_index, dtype=int)
    p = np.asarray(params, dtype=float)
    cand = model.check_joints(candidates)
    work = model.check_joints(working)
    b_c = term_basis(model, cand, spec, params=p)
    loaded = tuple(int(n.split(".q")[1]) - 1 for n in b_c.names if n.startswith("compliance.q"))
    b_w = term_basis(model, work, spec, params=p, loaded=loaded)
    Jc = np.concatenate([forward_with_jacobian(model, cand, p).J[:, :, idx], term_columns(model, cand, p, b_c)], axis=-1)
    Gw = np.concatenate([forward_with_jacobian(model, work, p).J[:, :3, idx], term_columns(model, work, p, b_w)[:, :3]],
                        axis=-1)
    rows = 6 if kind == "pose" else 3
    s = np.asarray(sigma, dtype=float).reshape(-1)[:rows]
    return Jc[:, :rows, :] / s[None, :, None], Gw, b_c.names
