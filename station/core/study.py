"""The chapter's simulation studies (section 7.5), re-run with the station's own core.

Each study draws a seeded workspace sample, identifies, propagates uncertainty linearly and by
Monte Carlo, and reports its figures beside the chapter's (brief §7). Exact agreement is not
expected — the method is; the orders of magnitude should match.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from station.core.identification import identify
from station.core.measurements import random_pairs, synthetic_set
from station.core.model import RobotModel
from station.core.poses import spread_joints
from station.core.uncertainty import monte_carlo, pose_accuracy
from station.core.units import ARCSEC, UM


@dataclass(frozen=True)
class StudyInputs:
    """Input uncertainties (chapter Fig. 5.3, 5.5, 6.11 orders of magnitude)."""

    sigma_position_mm: float = 0.015   # head: a point to ≤ 15 µm (chapter Table 5.4)
    sigma_angle_rad: float = 20 * ARCSEC  # a few ″ per µm of reading over ~50 mm
    sigma_joint_rad: float = 1.0e-5     # robot repeatability, ≈ 5–9 µm at the arm's end
    sigma_joint_mm: float = 0.003
    sigma_body_mm: float = 0.002        # body geometry per measuring point (CMM)
    sigma_body_rad: float = 2 * ARCSEC
    error_length_mm: float = 0.05       # "several 10 µm"
    error_angle_rad: float = 3 / 60 * np.pi / 180  # "several arc minutes"


@dataclass(frozen=True)
class StudyRow:
    quantity: str
    station: str
    chapter: str


@dataclass(frozen=True)
class StudyReport:
    name: str
    rows: tuple[StudyRow, ...]
    details: dict = field(default_factory=dict)


def perturbed(model: RobotModel, rng, inputs: StudyInputs) -> np.ndarray:
    """A 'true' robot: every parameter off by N(0, σ) of the error magnitudes."""
    err = np.where(model.is_angle(), inputs.error_angle_rad, inputs.error_length_mm)
    return model.nominal + rng.standard_normal(model.n_params) * err


def _rng_fmt(values, scale, unit, digits=1) -> str:
    v = np.asarray(values) / scale
    return f"{v.min():.{digits}f}–{v.max():.{digits}f} {unit}"


def _split(names, values):
    ang = np.array([n.split(".")[1] in ("roll", "pitch", "yaw") for n in names])
    return np.asarray(values)[~ang], np.asarray(values)[ang]


def _param_rows(label, names, sigma, chapter_len, chapter_ang):
    lin_len, lin_ang = _split(names, sigma)
    rows = []
    if lin_len.size:
        rows.append(StudyRow(f"{label} σ lengths", _rng_fmt(lin_len, UM, "µm"), chapter_len))
    if lin_ang.size:
        rows.append(StudyRow(f"{label} σ angles", _rng_fmt(lin_ang, ARCSEC, "″"), chapter_ang))
    return rows


def _accuracy_rows(label, sigma_pose, chapter_pos, chapter_ang):
    s = np.asarray(sigma_pose)
    return [
        StudyRow(f"{label} pose σ x,y,z", _rng_fmt(s[:, :3], UM, "µm"), chapter_pos),
        StudyRow(f"{label} pose σ rx,ry,rz", _rng_fmt(s[:, 3:], ARCSEC, "″"), chapter_ang),
    ]


def _mc_pose_sigma(model, start, true, idx, estimates, joints):
    """Spread of the poses the Monte Carlo models predict, in the measurement frame (where the
    set-up R absorbs the parameters merged into it, so the models are comparable)."""
    P = np.broadcast_to(start, (estimates.shape[0], start.size)).copy()
    P[:, idx] = estimates
    from station.core.kinematics import forward
    from station.core.transforms import pose_error

    T = forward(model, np.broadcast_to(joints, (P.shape[0],) + joints.shape), P)
    T0 = forward(model, joints, true)
    err = pose_error(T, T0)
    return err.std(axis=0, ddof=1)


def pose_study(model: RobotModel, planar: bool, n_poses: int = 25, n_sets: int = 1000,
               seed: int = 0, inputs: StudyInputs = StudyInputs()) -> StudyReport:
    rng = np.random.default_rng(seed)
    true = perturbed(model, rng, inputs)
    q = spread_joints(model, n_poses, rng, planar=planar)
    sig = np.array([inputs.sigma_position_mm] * 3 + [inputs.sigma_angle_rad] * 3)
    exact = synthetic_set(model, "pose", q, true, sigma=sig)
    res = identify(model, exact)
    unc = res.uncertainty
    q_eval = spread_joints(model, 200, rng, planar=planar)
    acc = pose_accuracy(model, res.params, res.chosen_index, unc.covariance, q_eval, setup=True)
    sj = [inputs.sigma_joint_rad if k == "revolute" else inputs.sigma_joint_mm for k in model.joint_types]
    point_ids = np.arange(n_poses)
    mc = monte_carlo(model, exact, true, res.chosen_index, n_sets, rng, sigma_joints=sj,
                     point_ids=point_ids, sigma_point=[inputs.sigma_body_mm] * 3 + [inputs.sigma_body_rad] * 3)
    mc_pose = _mc_pose_sigma(model, res.start, true, res.chosen_index, mc.estimates, q_eval)
    mc_noise_only = monte_carlo(model, exact, true, res.chosen_index, n_sets, rng)
    ratio = mc_noise_only.sigma / unc.sigma
    if planar:
        chapter = ("(not given)", "(not given)", "5–9 µm x-y, 4 µm z", "20–35″ rx,ry, 15″ rz",
                   "6–19 µm x-y, 6 µm z", "7–22″ rz")
        name = f"pose evaluation, {n_poses} poses in one plane"
    else:
        chapter = ("7–33 µm", "0.8–15″", "4–9 µm", "10–20″", "6–19 µm", "7–22″")
        name = f"pose evaluation, {n_poses} poses spread in 3-D"
    rows = [StudyRow("identifiable parameters", str(len(res.chosen)), "18" if planar else "20")]
    rows += _param_rows("linear", res.chosen, unc.sigma, chapter[0], chapter[1])
    rows.append(StudyRow("max |correlation|", f"{unc.max_abs_correlation():.2f}", "0.74" if not planar else "–"))
    rows += _accuracy_rows("linear", acc.sigma, chapter[2], chapter[3])
    rows += _accuracy_rows("Monte Carlo", mc_pose, chapter[4], chapter[5])
    rows.append(StudyRow("MC/linear σ per parameter (noise only)",
                         f"{ratio.min():.2f}–{ratio.max():.2f}", "same order"))
    return StudyReport(name, tuple(rows), {"chosen": res.chosen, "linear_sigma": unc.sigma.tolist(),
                                           "mc_sigma": mc_noise_only.sigma.tolist(),
                                           "mc_linear_ratio": ratio.tolist()})


def out_of_plane_study(model: RobotModel, n_poses: int = 25, seed: int = 0,
                       inputs: StudyInputs = StudyInputs()) -> StudyReport:
    """Identify the 18-parameter planar model, then evaluate it at poses spread in 3-D."""
    rng = np.random.default_rng(seed)
    true = perturbed(model, rng, inputs)
    q = spread_joints(model, n_poses, rng, planar=True)
    res = identify(model, synthetic_set(model, "pose", q, true))
    q3 = spread_joints(model, 200, rng)
    from station.core.kinematics import forward
    from station.core.transforms import pose_error

    err = pose_error(forward(model, q3, res.params), forward(model, q3, true))
    pos = np.linalg.norm(err[:, :3], axis=1)
    ang = np.linalg.norm(err[:, 3:], axis=1)
    rows = (
        StudyRow("parameters (planar model)", str(len(res.chosen)), "18"),
        StudyRow("position error off the plane", _rng_fmt(np.percentile(pos, [10, 90]), UM, "µm (10–90 %)", 0), "20–70 µm"),
        StudyRow("orientation error off the plane", f"{np.percentile(ang, 90) / ARCSEC:.0f}″ (90 %)", "30″"),
    )
    return StudyReport("18-parameter model used off its plane", rows)


def distance_study(model: RobotModel, planar: bool, exclude=(), n_points: int = 25,
                   n_distances: int = 28, n_sets: int = 50, seed: int = 0,
                   inputs: StudyInputs = StudyInputs(), label: str = "") -> StudyReport:
    rng = np.random.default_rng(seed)
    true = perturbed(model, rng, inputs)
    q = spread_joints(model, n_points, rng, planar=planar)
    pairs = random_pairs(n_points, n_distances, rng)
    s_d = np.sqrt(2.0) * 0.015  # chapter: σ of a distance = √2 · 15 µm
    exact = synthetic_set(model, "distance", q, true, sigma=s_d, pairs=pairs)
    res = identify(model, exact, exclude=exclude)
    unc = res.uncertainty
    mc = monte_carlo(model, exact, true, res.chosen_index, n_sets, rng)
    q_eval = spread_joints(model, 200, rng, planar=planar)
    acc = pose_accuracy(model, res.params, res.chosen_index, unc.covariance, q_eval, setup=True)
    if planar:
        chapter = ("5–7 µm", "(not given)", "5", "(not given)", "(not given)")
    elif exclude:
        chapter = ("few–27 µm", "18–21″", "9", "9–25 µm x-y, ≤30 µm z", "15″–1′")
    else:
        chapter = ("up to 0.2 mm", "up to 11′", "11", "–", "–")
    rows = [StudyRow("identifiable parameters", str(len(res.chosen)), chapter[2]),
            StudyRow("condition (scaled columns)", f"{res.identifiability.chosen_condition:.0f}",
                     "43" if exclude else ("1600" if not planar else "–"))]
    rows += _param_rows(f"Monte Carlo ({n_sets} sets)", res.chosen, mc.sigma, chapter[0], chapter[1])
    rows += _param_rows("linear", res.chosen, unc.sigma, "5–25 µm" if exclude else "–", "12–18″" if exclude else "–")
    rows += [StudyRow("linear pose σ x,y,z", _rng_fmt(acc.sigma[:, :3], UM, "µm"), chapter[3]),
             StudyRow("linear pose σ rx,ry,rz", _rng_fmt(acc.sigma[:, 3:], ARCSEC, "″"), chapter[4])]
    name = f"distance evaluation, {n_distances} distances{' in one plane' if planar else ''}"
    if label:
        name += f" ({label})"
    return StudyReport(name, tuple(rows), {"chosen": res.chosen})


def chapter_studies(model: RobotModel, seed: int = 0, n_sets: int = 1000) -> list[StudyReport]:
    """All of §7.5: pose 3-D, planar, off-plane, distance 11 / 9 / planar."""
    return [
        pose_study(model, planar=False, n_sets=n_sets, seed=seed),
        pose_study(model, planar=True, n_sets=n_sets, seed=seed),
        out_of_plane_study(model, seed=seed),
        distance_study(model, planar=False, seed=seed, label="all identifiable"),
        distance_study(model, planar=False, exclude=("A3.roll", "A3.pitch"), seed=seed,
                       label="without A3.roll, A3.pitch"),
        distance_study(model, planar=False, exclude=("A4.roll", "A4.pitch"), seed=seed,
                       label="without A4.roll, A4.pitch"),
        distance_study(model, planar=True, seed=seed),
    ]
