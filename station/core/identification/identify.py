"""Parameter identification: weighted least squares on a minimal parameter set (brief §4).

Pose objective (eq. 7.3): Σ ((model − measured)/σ)² over x, y, z, rx, ry, rz of every pose.
Position objective: the same on x, y, z only. Distance objective (7.6): plain sum of squares of
distance residuals (one σ for all, so the weighting is only a scale).

Before fitting, the data are checked and registered (:mod:`station.core.identification.registration`): rows
that repeat, too few distinct configurations and absurd values are refused; pose and position
data are aligned to the nominal model by a similarity fit (a scale far from 1 is a unit mistake,
refused with the likely unit) and a rigid fit, which starts the set-up R wherever the instrument
stands (turned, flipped, metres away); the rank and condition are taken at the data.

Solved by Levenberg–Marquardt (MINPACK's ``lmder``, exactly as scipy ``least_squares(method="lm")``
calls it) on the minimal set chosen by :mod:`station.core.identification.identifiability`, with the analytic
Jacobian. The residuals and Jacobian come from :mod:`station.core.identification.fit_kernel` (the joints' motions
computed once, one chain per evaluation, the Jacobian at a point built from the frames its residuals
left; the same arithmetic as :func:`~station.core.measurement.measurements.residuals_and_jacobian`, bit for
bit), and the fit runs with one BLAS thread (:mod:`station.core.blas_threads`). Everything reported
is taken at the returned parameters (MINPACK does not always evaluate last at its result). The parameter
covariance is the linear propagation of the measurement covariance: diag(σ²) for pose and
position rows, and for distances the covariance built from the measured points, whose shared
points correlate the distances (:func:`station.core.measurement.uncertainty.distance_sandwich`).

With the calibration body's uncertainty in the data (``MeasurementSet.body_sigma``), every row is
weighted by σ_meas² + σ_body² and the covariance is the sandwich that also holds the correlation
of the measurements at one body point, which share its error
(:func:`station.core.measurement.uncertainty.body_sandwich`); a note says so.

Real data: distances between two rows with the same nominal point (q6 and q6 + 360°, a repeated
pose) have no direction and are dropped with a note; ``loss="huber"`` fits robustly (rows beyond
``HUBER_SCALE`` σ weigh less; the result lists them and its σ are the weighted fit's), starting
from the least-squares solution and so from the same set-up;
``tool_unknown`` registers an unknown tool or marker point and starts from it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from station.core.blas_threads import single_blas_thread
from station.core.identification.base_frame import base_frame_note
from station.core.identification.fit_kernel import DataEvaluator, FitProblem, LMSolution, minpack_lm
from station.core.identification.identifiability import Identifiability, analyze, structural_params
from station.core.identification.registration import (
    DataInformation,
    Registration,
    data_information,
    likely_unit,
    register,
)
from station.core.kinematics.forward import forward
from station.core.kinematics.model import RobotModel
from station.core.kinematics.transforms import rpy_to_matrix
from station.core.measurement.distance_pairs import coincident_pairs, shares_points
from station.core.measurement.measurements import MeasurementSet
from station.core.measurement.repeatability import VarianceFactor, scaled, variance_factor
from station.core.measurement.uncertainty import (
    LinearUncertainty,
    body_sandwich,
    distance_sandwich,
    linear_uncertainty,
    pair_units,
)
from station.core.units import ARCSEC, UM
from station.errors import ConfigError, IdentificationError

OUTLIER_SIGMAS = 4.0
#: the note of a fit that holds the calibration body's uncertainty starts with this
BODY_NOTE_PREFIX = "body uncertainty included"
REGISTRATION_START_ANGLE = np.radians(45.0)
LOSSES = ("linear", "huber")
#: the robust loss's corner in σ: a row within 3 σ keeps its full weight (an ordinary row rarely
#: leaves it), a row beyond it weighs c/|r| (its pull grows no further)
HUBER_SCALE = 3.0
#: the fit's evaluations at most, unless the caller says otherwise (``station identify --max-evaluations``)
MAX_EVALUATIONS = 200


@dataclass(frozen=True)
class IdentificationResult:
    """An identified model and how well it is known.

    ``params``: ``(n_params,)`` full parameter vector [mm, rad] (held parameters at their
    start values). ``chosen``: names of the identified parameters, ``estimates`` their values.
    ``residuals``: ``(n_items, rows_per_item)`` model − measured at the solution [mm, rad].
    ``normalized``: per-measurement RMS of residual/σ. ``outliers``: indices of measurements
    whose normalized residual exceeds ``OUTLIER_SIGMAS`` (robustly scaled). ``downweighted``:
    ``(item, weight)`` of every measurement the robust loss weighed below 1 (``loss="huber"``).
    ``dropped_pairs``: the ``(i, j)`` joint rows of distances left out because both rows give the
    same nominal point (residuals and items count without them). ``pairs``: the distances' joint
    rows ``(k, 2)`` as fitted (distance data), else None.
    """

    model: RobotModel
    kind: str
    params: np.ndarray
    start: np.ndarray
    chosen: tuple[str, ...]
    chosen_index: np.ndarray
    residuals: np.ndarray
    normalized: np.ndarray
    rms_normalized: float
    outliers: tuple[int, ...]
    iterations: int
    converged: bool
    message: str
    identifiability: Identifiability
    uncertainty: LinearUncertainty
    registration: Registration | None = None
    information: DataInformation | None = None
    design_rank: int | None = None
    notes: tuple[str, ...] = ()
    loss: str = "linear"
    downweighted: tuple[tuple[int, float], ...] = ()
    dropped_pairs: tuple[tuple[int, int], ...] = ()
    pairs: np.ndarray | None = None
    #: the evaluations the fit was allowed (``identify``'s ``max_nfev``)
    max_evaluations: int = 0
    #: the a-posteriori check of the assumed noise (:func:`~station.core.measurement.repeatability.variance_factor`):
    #: where it says the noise is larger, ``uncertainty`` is already scaled by its s0; None where it
    #: does not apply (no redundancy, distances, the robust loss)
    variance: VarianceFactor | None = None

    def item_rows(self, item: int) -> tuple[int, ...]:
        """The 0-based joint rows of measurement ``item``: itself, or a distance's two rows."""
        if self.pairs is None:
            return (int(item),)
        return tuple(int(r) for r in self.pairs[item])

    @property
    def estimates(self) -> np.ndarray:
        return self.params[self.chosen_index]

    @property
    def identified_model(self) -> RobotModel:
        return self.model.with_params(self.params)

    def rms_position_mm(self) -> float:
        if self.kind == "distance":
            return float(np.sqrt(np.mean(self.residuals**2)))
        return float(np.sqrt(np.mean(np.sum(self.residuals[:, :3] ** 2, axis=1))))


def body_note(data: MeasurementSet) -> str:
    """The line that says the calibration body's uncertainty is in the fit and its σ."""
    assert data.body_sigma is not None and data.body_point is not None
    used = data.body_sigma[np.unique(data.body_point)]
    pos, ang = used[:, 0] / UM, used[:, 1] / ARCSEC

    def span(v: np.ndarray, unit: str) -> str:
        lo, hi = float(v.min()), float(v.max())
        return f"{lo:.3g} {unit}" if np.isclose(lo, hi) else f"{lo:.3g}–{hi:.3g} {unit}"

    return (f"{BODY_NOTE_PREFIX}: {len(used)} points, σ {span(pos, 'µm')}, {span(ang, '″')} "
            f"(weights and σ; measurements of one point share its error)")


def _median(x: np.ndarray) -> float:
    """``np.median`` of all of ``x`` (the middle value, or the mean of the two middle values), by
    one sort: the same number without np.median's layers (a NaN anywhere: np.median's NaN)."""
    v = np.sort(x, axis=None)
    n = v.size
    if n == 0 or np.isnan(v[-1]):
        return float(np.median(x))
    h = n // 2
    return float(v[h]) if n % 2 else float((v[h - 1] + v[h]) / 2.0)


def _position_sigma(data: MeasurementSet) -> float:
    s = data.sigma.reshape(data.n_items, data.rows_per_item)
    return float(_median(s[:, :3]))


_DESIGN_RANKS: dict[tuple, int] = {}


def design_rank(model: RobotModel, kind: str, n_poses: int = 60, seed: int = 12345) -> int:
    """Rank of ``kind`` measurements at poses spread over the whole workspace (the design the
    data are compared with). Cached per robot structure and nominal geometry."""
    key = (model.transforms, model.nominal.tobytes(), model.joint_limits.tobytes(), kind, n_poses, seed)
    if key not in _DESIGN_RANKS:
        _DESIGN_RANKS[key] = _design_rank(model, kind, n_poses, seed)
    return _DESIGN_RANKS[key]


def _design_rank(model: RobotModel, kind: str, n_poses: int, seed: int) -> int:
    from station.core.kinematics.poses import spread_joints
    from station.core.measurement.measurements import synthetic_set

    rng = np.random.default_rng(seed)
    q = spread_joints(model, n_poses, rng)
    pairs = np.array(np.triu_indices(n_poses, 1)).T if kind == "distance" else None
    return analyze(model, synthetic_set(model, kind, q, model.nominal, pairs=pairs),  # type: ignore[arg-type]
                   structural_params(model, model.nominal), describe=False).rank


def identify(model: RobotModel, data: MeasurementSet, start=None, prefer=None, fix=(), exclude=(),
             chosen=None, max_nfev: int = MAX_EVALUATIONS, max_rms_normalized: float = 1e3,
             register_frame: bool = True, tool_unknown: bool = False,
             loss: str = "linear") -> IdentificationResult:
    """Identify ``model``'s parameters from ``data``.

    ``start``: start parameters (default nominal, with the set-up R from the registration).
    ``prefer`` / ``fix`` / ``exclude``: minimal set preferences (default: the robot file's
    ``prefer`` list). ``chosen``: identify exactly these parameters instead (must be
    identifiable). ``register_frame``: register pose/position data to the model first (unit
    check, start of R, residual check; the residual check is skipped when ``start`` is given).
    ``tool_unknown``: the tool (marker) point is registered as unknown too and the fit starts from
    it (pose/position data; for distances give a ``start`` with the tool point). ``loss``:
    ``"linear"`` (least squares) or ``"huber"`` (robust; rows beyond ``HUBER_SCALE`` σ weigh less,
    and the result lists them). Distances whose two rows give the same nominal point (a repeated
    pose, q and q + 360°) carry nothing and are dropped with a note.
    Raises :class:`~station.errors.ConfigError` for data that cannot be used (units, repeated
    rows, too few configurations) and :class:`IdentificationError` on a registration residual
    far above an uncalibrated robot's, rank deficiency or divergence.
    """
    with single_blas_thread():  # tall, narrow factorisations: one thread is faster (blas_threads)
        return _identify(model, data, start, prefer, fix, exclude, chosen, max_nfev, max_rms_normalized,
                         register_frame, tool_unknown, loss)


def _identify(model: RobotModel, data: MeasurementSet, start, prefer, fix, exclude, chosen, max_nfev: int,
              max_rms_normalized: float, register_frame: bool, tool_unknown: bool,
              loss: str) -> IdentificationResult:
    p0 = np.array(model.nominal if start is None else start, dtype=float)
    if p0.shape != (model.n_params,) or not np.all(np.isfinite(p0)):
        raise IdentificationError("start parameters must be a finite vector of the model's size")
    notes: list[str] = []
    if loss not in LOSSES:
        raise ConfigError(f"unknown loss {loss!r}; use one of {', '.join(LOSSES)}")
    dropped: tuple[tuple[int, int], ...] = ()
    if data.kind == "distance":
        data, dropped = _drop_coincident(model, data, p0, notes)
    info = data_information(model, data.joints, None if data.kind == "distance" else data.measured,
                            rows_per_item=3 if data.kind == "distance" else data.rows_per_item)
    if data.kind == "distance":
        _check_distance_scale(model, data, p0)
    evaluator = DataEvaluator(model, data)  # one chain for the registration, the analysis, the fit and its result
    reg = None
    if data.kind != "distance" and register_frame:
        reg = _register_start(model, data, evaluator, p0, start, fix, exclude, tool_unknown, notes)
    p_struct = structural_params(model, p0)
    ident = analyze(model, data, p_struct, prefer=model.prefer if prefer is None else prefer,
                    fix=fix, exclude=exclude, describe=True,
                    jacobian=evaluator.residuals_and_jacobian(p_struct)[1] / data.sigma[:, None])
    d_rank = design_rank(model, data.kind)
    if ident.rank < d_rank and not (fix or exclude or chosen is not None):
        notes.append(f"the data determine {ident.rank} of the {d_rank} parameters that a workspace-wide "
                     f"design determines (e.g. poses in one plane); the rest merge as listed")
    gimbal = ident.gimbal_note()  # a transform at pitch ±90° that costs this parametrisation rank
    if gimbal is not None:
        notes.append(gimbal)
    base = base_frame_note(model, ident) if chosen is None else None  # what the base frame is tied to (36)
    if base is not None:
        notes.append(base)
    idx = _chosen_index(model, data, evaluator, p0, chosen, ident)
    n_rows = data.sigma.size
    if n_rows < len(idx):
        raise IdentificationError(
            f"{n_rows} residual rows cannot determine {len(idx)} parameters; measure more poses"
        )
    # σ_meas² + σ_body² per row (the body's share, when given, weights every row by what its
    # measuring point's CMM uncertainty adds to it); exactly data.sigma without body σ
    w = 1.0 / data.fit_sigma(pair_units(model, data, p0) if data.has_body_sigma else None)

    prob = FitProblem(evaluator, p0, idx, w)
    sol = minpack_lm(prob, p0[idx], max_nfev)  # n_rows >= len(idx) here: Levenberg–Marquardt
    if loss == "huber":
        sol = _robust_from(prob, sol, max_nfev)
    p = prob.full(sol.x)
    r, J = evaluator.residuals_and_jacobian(p)  # at the result (MINPACK may not have evaluated last there)
    Jw = J[:, idx] * w[:, None]
    downweighted: tuple[tuple[int, float], ...] = ()
    if loss == "huber":
        # IRLS weights at the solution: the covariance is that of the weighted fit the loss solved
        omega = np.minimum(1.0, HUBER_SCALE / np.maximum(np.abs(r * w), 1e-300))
        Jw = Jw * np.sqrt(omega)[:, None]
        item_w = omega.reshape(data.n_items, data.rows_per_item).min(axis=1)
        downweighted = tuple((int(i), float(item_w[i])) for i in np.argsort(item_w) if item_w[i] < 1.0)
        notes.append(f"robust loss huber (corner {HUBER_SCALE:g} σ): {len(downweighted)} of {data.n_items} "
                     f"measurements down-weighted")
    names = tuple(model.param_names[i] for i in idx.tolist())
    unc = _uncertainty(model, data, p, Jw, w, names, notes)
    rn = (r * w).reshape(data.n_items, data.rows_per_item)
    rn2 = rn**2  # np.mean's sums and divisions, without its layers
    per_item = np.sqrt(np.add.reduce(rn2, 1) / rn2.shape[1])
    rms = float(np.sqrt(np.add.reduce(rn2, None) / rn2.size))
    if not np.all(np.isfinite(p)) or rms > max_rms_normalized:
        raise IdentificationError(_diverged(rms, sol.nfev, reg, loss))
    if unc.rank < len(idx):
        raise IdentificationError(
            f"rank deficient at the solution ({unc.rank} of {len(idx)} parameters determined); "
            f"spread the poses over the workspace or identify fewer parameters"
        )
    var = _variance_check(data, r * w, len(idx), loss)
    if var is not None:
        notes.append(var.note())
        unc = scaled(unc, var.factor)
    med = _median(per_item)
    mad = 1.4826 * _median(np.abs(per_item - med)) or 1.0
    outliers = tuple(int(i) for i in np.nonzero((per_item - med) / mad > OUTLIER_SIGMAS)[0]
                     if per_item[i] > 3.0)
    converged = bool(sol.status > 0)
    return IdentificationResult(
        model=model, kind=data.kind, params=p, start=p0,
        chosen=names, chosen_index=idx,
        residuals=r.reshape(data.n_items, data.rows_per_item), normalized=per_item,
        rms_normalized=rms, outliers=outliers, iterations=int(sol.nfev), converged=converged,
        message=str(sol.message), identifiability=ident, uncertainty=unc,
        registration=reg, information=info, design_rank=d_rank, notes=tuple(notes),
        loss=loss, downweighted=downweighted, dropped_pairs=dropped,
        pairs=data.distance_pairs() if data.kind == "distance" else None, max_evaluations=max_nfev,
        variance=var,
    )


def _variance_check(data: MeasurementSet, weighted: np.ndarray, n_params: int, loss: str) -> VarianceFactor | None:
    """The a-posteriori variance factor of a least-squares fit of independent rows (pose, position):
    distances share their points (rᵀWr is then no χ²(m − n)), and the robust loss's residuals are
    not Gaussian by design, so neither is checked."""
    if data.kind == "distance" or loss != "linear":
        return None
    return variance_factor(weighted, n_params)


def _check_distance_scale(model: RobotModel, data: MeasurementSet, p0: np.ndarray) -> None:
    """Distances in another unit than the robot file's are refused, naming the likely unit, before
    a fit would bend the robot to them."""
    pts = forward(model, data.joints, p0, setup=False)[:, :3, 3]
    pr = data.distance_pairs()
    d_nom = np.linalg.norm(pts[pr[:, 0]] - pts[pr[:, 1]], axis=1)
    scale = float(np.sum(d_nom * data.measured) / max(np.sum(d_nom**2), 1e-300))
    if not (abs(scale - 1.0) <= 0.02):
        likely = likely_unit(scale) if np.isfinite(scale) and scale > 0 else None
        raise ConfigError(
            f"the measured distances are {scale:.4g}× the nominal model's"
            + (f": they look like {likely[0]}, not mm. Label the columns with their unit or {likely[1]}"
               if likely else "; check the length unit of the data and of the robot file"))


def _register_start(model: RobotModel, data: MeasurementSet, evaluator: DataEvaluator, p0: np.ndarray, start,
                    fix, exclude, tool_unknown: bool, notes: list[str]) -> Registration | None:
    """The set-up (and, with ``tool_unknown``, the tool point) registered from the measured
    positions; ``p0`` takes what the fit should start from, and ``notes`` say why."""
    reg = None
    pos = data.measured[:, :3, 3] if data.kind == "pose" else data.measured
    try:
        reg = register(model, data.joints, pos, _position_sigma(data), params=p0, tool_unknown=tool_unknown,
                       explain_marker=start is None, base_points=evaluator.chain.tool(p0, setup=False)[:, :3, 3])
    except IdentificationError:
        if start is None:
            raise
        notes.append("registration residual above the limit; fitted from the given start anyway")
    if reg is not None and reg.tool_offset_mm is not None:
        p0[-6:-3] = reg.tool_offset_mm
        d = reg.tool_offset_mm - model.nominal[-6:-3]
        notes.append(f"tool point unknown: started from the registration's, ({d[0]:.2f}, {d[1]:.2f}, "
                     f"{d[2]:.2f}) mm from the robot file's")
    if reg is not None and start is None and not any(
            model.param_names[i] in (*fix, *exclude) for i in range(6)):
        # Keep the robot file's set-up where Levenberg–Marquardt converges from it (the
        # translation enters linearly; a rotation within REGISTRATION_START_ANGLE does), so
        # parameters that merge into R keep their file values; otherwise start from the
        # registration (an instrument turned or flipped far from the file's R).
        R_file = rpy_to_matrix(p0[3:6])  # pose_to_matrix(p0[:6])'s rotation
        angle = float(np.arccos(np.clip((np.trace(R_file.T @ reg.transform[:3, :3]) - 1) / 2, -1, 1)))
        if angle > REGISTRATION_START_ANGLE:
            p0[:6] = reg.setup_pose
            notes.append(f"set-up R started from the registration (the robot file's R is turned "
                         f"{np.degrees(angle):.0f}° from the instrument's frame)")
    return reg


def _chosen_index(model: RobotModel, data: MeasurementSet, evaluator: DataEvaluator, p0: np.ndarray, chosen,
                  ident: Identifiability) -> np.ndarray:
    """The fitted parameters' indices: the caller's ``chosen`` (checked identifiable from these
    data) or the analysis's minimal set."""
    if chosen is not None:
        idx = np.array(model.param_indices(chosen), dtype=int)
        J = evaluator.residuals_and_jacobian(p0)[1][:, idx] / data.sigma[:, None]
        Js = J / np.maximum(np.linalg.norm(J, axis=0), 1e-300)
        s = np.linalg.svd(Js, compute_uv=False)
        if s[-1] <= 1e-9 * s[0]:
            raise IdentificationError(
                f"the parameters {list(chosen)} are not all identifiable from these "
                f"{data.kind} measurements (rank {int(np.sum(s > 1e-9 * s[0]))} of {len(idx)}); "
                f"run 'station analyze' to see a minimal set"
            )
    else:
        idx = ident.chosen_indices()
    return idx


def _uncertainty(model: RobotModel, data: MeasurementSet, p: np.ndarray, Jw: np.ndarray, w: np.ndarray,
                 names: tuple[str, ...], notes: list[str]) -> LinearUncertainty:
    """The identified parameters' covariance as the data's kind needs it: the sandwich for
    distances (they share points) and for rows sharing a body point's error, else linear."""
    if data.kind == "distance":
        pts = forward(model, data.joints, p, setup=False)[:, :3, 3]
        pr = data.distance_pairs()
        diff = pts[pr[:, 0]] - pts[pr[:, 1]]
        unit = diff / np.linalg.norm(diff, axis=1)[:, None]
        if data.has_body_sigma:
            unc = body_sandwich(Jw, names, data, 1.0 / w, unit)
        else:
            unc = distance_sandwich(Jw, names, pr, unit, data.sigma, data.points_sigma(), data.joints.shape[0])
        if shares_points(pr):
            notes.append(f"{len(pr)} distances share measured points; their correlation is in the σ "
                         f"(sandwich from the points' covariance)")
    elif data.has_body_sigma:
        unc = body_sandwich(Jw, names, data, 1.0 / w)
    else:
        unc = linear_uncertainty(Jw, names)
    if data.has_body_sigma:
        notes.append(body_note(data))
    return unc


def require_converged(res: IdentificationResult) -> None:
    """Refuse a fit that stopped before meeting its tolerance: no result, exit 3 with what to do
    (``identify`` returns it, for callers that look at it; the CLI prints and writes nothing of it)."""
    if res.converged:
        return
    what = (f"the fit did not converge ({res.message.rstrip('.')}; {res.iterations} evaluations, normalised RMS "
            f"residual {res.rms_normalized:.3g}, RMS position residual {res.rms_position_mm() * 1e3:.4g} µm): its "
            f"parameters are not used and nothing was written. ")
    hold = ("hold the parameters these poses barely determine (--fix, --exclude; station analyze names them) or "
            "measure poses spread over the workspace")
    if res.max_evaluations and res.iterations >= res.max_evaluations:
        raise IdentificationError(f"{what}It ran out of evaluations: allow more with --max-evaluations (now "
                                  f"{res.max_evaluations}); if it still does not converge, {hold}")
    raise IdentificationError(f"{what}{hold[0].upper()}{hold[1:]}")


def _diverged(rms: float, nfev: int, reg: Registration | None, loss: str) -> str:
    """What a diverged fit says: units and joint order only where nothing has checked them yet (a
    registration that passed did; distances' scale check sees the length unit only)."""
    head = f"identification diverged (normalised RMS residual {rms:.3g} after {nfev} evaluations)"
    if reg is None:
        return (f"{head}: the start model is too far from the robot or the data are wrong. Check units (mm, "
                f"deg/rad in the file header), joint order and sign conventions")
    return (f"{head}, although the registration placed the nominal model within {reg.rms_mm:.3g} mm RMS of "
            f"the data, so units and joint order are consistent. The fit itself ran away: "
            f"a few gross rows (try --loss {'linear' if loss != 'linear' else 'huber'}), parameters these poses "
            f"barely determine (hold them with --fix or --exclude; station analyze names them), or a σ far "
            f"below the instrument's noise (--sigma-position)")


def _robust_from(prob: FitProblem, linear: LMSolution, max_nfev: int) -> LMSolution:
    """The Huber fit started from the least-squares solution ``linear``.

    Why not from the start itself: there the residuals of a set-up still metres off (a tracker
    4 m away that the registration left to the fit, being turned less than
    ``REGISTRATION_START_ANGLE``) are thousands of σ, every row sits far beyond the corner and
    weighs c/|r|, and the robust loss crawls like an L1 fit: 200 evaluations left it 500 mm off.
    Least squares takes the set-up in a few steps; from its solution only the outliers lie beyond
    the corner. The evaluations of both count, and the robust fit's status is the result's."""
    if not np.all(np.isfinite(prob.fun(linear.x))):
        return linear  # diverged already: the caller refuses it
    left = max(max_nfev - linear.nfev, 1)
    sol = least_squares(prob.fun, linear.x, jac=prob.jac, method="trf", x_scale="jac", max_nfev=left,
                        loss="huber", f_scale=HUBER_SCALE, xtol=1e-15, ftol=1e-15, gtol=1e-15)
    return LMSolution(np.asarray(sol.x, dtype=float), linear.nfev + int(sol.nfev), int(sol.status), str(sol.message))


def _drop_coincident(model: RobotModel, data: MeasurementSet, p0: np.ndarray,
                     notes: list[str]) -> tuple[MeasurementSet, tuple[tuple[int, int], ...]]:
    """Leave out distances whose two rows give the same nominal point: their direction, and so
    their Jacobian, is undefined (a repeated pose; q and q + 360° on a wrist)."""
    pts = forward(model, data.joints, p0, setup=False)[:, :3, 3]
    pr = data.distance_pairs()
    bad = coincident_pairs(pts, pr)
    if not bad.any():
        return data, ()
    dropped = tuple((int(a), int(b)) for a, b in pr[bad])
    if bad.all():
        raise ConfigError(
            f"every one of the {len(pr)} distances joins two rows with the same nominal point (e.g. rows "
            f"{dropped[0][0] + 1} and {dropped[0][1] + 1}); measure poses at different places")
    a, b = dropped[0]
    notes.append(f"{len(dropped)} of {len(pr)} distances dropped: both of their rows give the same nominal "
                 f"point (a repeated pose, or q and q + 360°), e.g. rows {a + 1} and {b + 1}")
    return data.subset(np.nonzero(~bad)[0]), dropped
