"""The corrected robot judged in its true base frame, with the simulator's truth (issue 36, §2).

A correction table commands joints ``q`` with ``FK_identified(q) = target`` in the robot's base
frame; the true robot then stands at ``FK_true(q)``. Its error there, ``FK_true(q) − FK_identified(q)``
at targets drawn over the table's region, is what a user who commands the robot in its base frame
meets. The verification on the body cannot see it: it is measured through the identified set-up,
which absorbs whatever the robot's base frame took of the set-up's error.

The true base frame is the robot's as its maker defines it, tied to axis 1
(:func:`axis1_base_frame`). Three figures (RMS of the head frame's origin over the same targets, µm):

* ``nominal``: the true robot commanded through the robot file's model (no table);
* ``corrected``: through the identified model (a perfect table's);
* ``reference``: through the best a body calibration can reach, the true robot with the
  directions the body cannot tell from the set-up handed to the set-up by the identification's
  own convention (its chosen parameters fitted to the true robot's exact measurements, every
  other robot parameter at the robot file's). What stays is the truth's own unobservable part
  (the height of axis 1, the zero of joint 1, …), which no body measurement can remove.

The ratio ``corrected / reference`` is the figure a test holds to 1.2.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from simulators.truth_kinematics import true_forward
from station.core.identification.identify import identify
from station.core.kinematics.model import RobotModel
from station.core.measurement.measurements import synthetic_set

#: joint configurations drawn per round of the rejection sampling over the joint limits
_DRAW = 4000


@dataclass(frozen=True)
class BaseFrameCheck:
    """The figures of :func:`base_frame_check` [µm], RMS over ``n_targets`` targets."""

    n_targets: int
    nominal_um: float
    corrected_um: float
    reference_um: float

    @property
    def ratio(self) -> float:
        """corrected / reference: 1 is the best a body calibration can do in the base frame."""
        return self.corrected_um / self.reference_um if self.reference_um > 0 else float("inf")


def targets_in_box(model: RobotModel, lo, hi, n: int, rng: np.random.Generator,
                   max_rounds: int = 50) -> np.ndarray:
    """``(n, g)`` joints drawn uniformly within the joint limits whose nominal head frame (base
    frame, no set-up) lies in the box ``lo``–``hi`` [mm]: targets over the table's region."""
    lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    lim = model.joint_limits
    found: list[np.ndarray] = []
    for _ in range(max_rounds):
        q = lim[:, 0] + rng.random((_DRAW, model.n_joints)) * (lim[:, 1] - lim[:, 0])
        p = _head(model, q, model.nominal)
        found.append(q[np.all((p >= lo) & (p <= hi), axis=1)])
        if sum(len(f) for f in found) >= n:
            break
    q = np.concatenate(found)[:n]
    if len(q) < n:
        raise ValueError(f"only {len(q)} of {n} joint draws reach the region {lo.tolist()} – {hi.tolist()} mm")
    return q


def _head(model: RobotModel, q: np.ndarray, params: np.ndarray) -> np.ndarray:
    """The head frame's origin in the base frame, ``(n, 3)`` [mm], with the simulator's own
    kinematics (the robot file's documented convention), never the station's."""
    return true_forward([t.joint for t in model.transforms], params, q, setup=False)[:, :3, 3]


def _rms_um(model: RobotModel, q: np.ndarray, p_true: np.ndarray, p_used: np.ndarray) -> float:
    a = _head(model, q, p_true)
    b = _head(model, q, p_used)
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1)))) * 1e3


def reference_params(model: RobotModel, p_true: np.ndarray, chosen, kind: str, joints: np.ndarray) -> np.ndarray:
    """The true robot as the identification's convention sees it: ``chosen`` fitted to the true
    robot's exact ``kind`` measurements at ``joints`` (through the true set-up), every other
    parameter at the robot file's. Its base frame is the best a body calibration can reach."""
    pairs = np.array(np.triu_indices(len(joints), 1)).T if kind == "distance" else None
    data = synthetic_set(model, kind, joints, p_true, pairs=pairs)  # type: ignore[arg-type]
    return identify(model, data, chosen=tuple(chosen), max_nfev=400).params


def prior_best_params(model: RobotModel, p_true: np.ndarray, sigma: np.ndarray, kind: str,
                      joints: np.ndarray) -> np.ndarray:
    """The true robot with what ``kind`` measurements at ``joints`` cannot see resolved by the
    prior: of every robot that the exact measurements cannot tell from the truth, the one closest
    to the robot file's in σ units (``sigma`` (n_params,), the size a robot's error is expected to
    have), the set-up free. The physically most likely robot, whatever parameters a minimal set
    names; the identification's convention holds when its reference stands where this one does.
    Linear about the robot file's (errors of micrometres and arc minutes: second order is far
    below a micrometre)."""
    from station.core.identification.identifiability import weighted_jacobian

    pairs = np.array(np.triu_indices(len(joints), 1)).T if kind == "distance" else None
    data = synthetic_set(model, kind, joints, model.nominal, pairs=pairs)  # type: ignore[arg-type]
    J = weighted_jacobian(model, data)
    w = np.asarray(sigma, dtype=float).copy()
    w[model.setup_slice()] *= 1e3  # the set-up's error costs (next to) nothing: it is the set-up's
    e = np.asarray(p_true, dtype=float) - model.nominal
    u = np.linalg.lstsq(J * w, J @ e, rcond=1e-10)[0]
    return model.nominal + w * u


def base_frame_check(model: RobotModel, p_true: np.ndarray, p_corrected: np.ndarray, chosen, kind: str,
                     targets: np.ndarray, fit_joints: np.ndarray | None = None) -> BaseFrameCheck:
    """Nominal, corrected and reference base-frame errors at ``targets`` (joints, ``(n, g)``).
    ``chosen`` / ``kind``: the identification's parameters and objective; ``fit_joints``: the
    poses the reference is fitted at (default the targets)."""
    q_fit = targets if fit_joints is None else fit_joints
    p_ref = reference_params(model, p_true, chosen, kind, q_fit)
    p_base = axis1_base_frame(model, p_true)
    return BaseFrameCheck(n_targets=len(targets), nominal_um=_rms_um(model, targets, p_base, model.nominal),
                          corrected_um=_rms_um(model, targets, p_base, p_corrected),
                          reference_um=_rms_um(model, targets, p_base, p_ref))


def axis1_base_frame(model: RobotModel, p_true: np.ndarray) -> np.ndarray:
    """The true robot in its base frame as its maker defines it: tied to axis 1 (z along the true
    axis 1, x where the first arm points at joint 1's zero, the origin on the axis), as ISO 9787
    and the makers' manuals place a robot's base coordinate system. The simulated truth draws
    axis 1's tilt, position and zero like any other axis's, but against a frame tied to axis 1
    they are not errors of the robot: they only say where that frame stands, which is the
    set-up's to carry. The height along axis 1 stays the truth's: the base frame's origin is on
    the mounting face, and how high the arm stands above it is the robot's (a body calibration
    cannot see it: it is part of what the reference keeps).

    Returns the parameters ``(n_params,)`` whose chain from A1 on equals the true chain seen from
    that frame: A1 at the robot file's values with the true height. Exact, not linearised: for
    a constant frame B = A1_true · A1'⁻¹, B⁻¹ · A1_true · joint(q1) · … = A1' · joint(q1) · …"""
    p = np.array(p_true, dtype=float).reshape(-1, 6)
    a1 = np.array(model.nominal, dtype=float).reshape(-1, 6)[1].copy()
    a1[2] = p[1, 2]
    p[1] = a1
    return p.ravel()
