"""Is an identified robot plausible? (issue 36, §3)

A fit can converge, with a full-rank minimal set and σ of micrometres, to a robot that is no robot:
on real tracker data whose joint 4 stands at one angle modulo a turn (−360°, 0°, +360°), a
geometric fit moved a wrist length by 127 mm at σ 50 µm and missed the other poses by 200 mm. The
rank did not see it (q and q + 360° are different numbers, the same angle), nor did the σ: both
describe the fit's linearisation, not whether its result is a robot the file describes.

Two checks, both pure numerics:

* :func:`joint_angle_counts` counts each joint's distinct values in the data, a revolute joint's
  modulo a full turn. A joint at fewer than :data:`MIN_DISTINCT_ANGLES` distinct values leaves
  the parameters next to it to the rest of the chain: the likely cause of an implausible result.
* :func:`plausibility` compares the identified robot with the robot file's geometry where the
  set-up cannot hide the difference. The set-up and the parameters that merge with it (a tracker
  4 m away, turned 22°) move by metres in any good fit, and a joint-1 zero turns the next
  transform's offsets with it, so parameter values cannot be compared with the file's directly.
  The file's geometry is placed where the identified robot stands (the identified tool where the
  tool was fitted, the best rigid fit of its points onto the identified robot's) and the two
  robots' points are compared at poses over the joint ranges and at the data's: a real robot
  keeps to millimetres (the FANUC of the tracker data: 3.1 mm RMS with every joint measured;
  144 mm with its joint 4 at one angle). To name the parameters, the placed file geometry is
  fitted, noise-free over the same poses, with the very parameters the identification chose,
  starting from the identified values: the parameters then carry the set-up the same way, and
  the difference is the robot's own deviation from its file.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from station.core.identification.registration import rigid_setup
from station.core.kinematics.forward import forward
from station.core.kinematics.model import RobotModel
from station.core.kinematics.poses import spread_joints
from station.core.measurement.measurements import MeasurementSet, synthetic_set
from station.errors import ConfigError, IdentificationError

#: a joint the data show at fewer distinct values than this (a revolute joint's modulo a turn)
#: cannot separate the parameters next to it from the rest of the chain: two angles fix a
#: direction and a length, not where the axis lies
MIN_DISTINCT_ANGLES = 3
#: two values of a revolute joint within this [rad] (0.1°) are one angle (a repeated pose, the
#: controller's rounding); a prismatic joint's within DISTINCT_LENGTH_MM
DISTINCT_ANGLE_RAD = np.radians(0.1)
DISTINCT_LENGTH_MM = 0.1
#: a robot built to its file deviates from it by fractions of a millimetre and of a degree
#: (a worn, re-mastered heavy arm by a few mm and tenths of a degree); a parameter beyond these
#: [mm, rad] is no such deviation but a direction the data do not hold. A cell's [simulation] σ
#: may widen them (PRIOR_FACTOR times its σ), never narrow them
PLAUSIBLE_LENGTH_MM = 10.0
PLAUSIBLE_ANGLE_RAD = np.radians(2.0)
PRIOR_FACTOR = 100.0
#: the robot file's geometry must be expressible in the fit's gauge to this [mm] RMS for the
#: comparison to mean anything; beyond it the check says it could not compare
#: poses over the joint ranges (seeded) at which the identified robot meets its file's geometry
WORKSPACE_POSES = 60
WORKSPACE_SEED = 36

_ANGLE_SUFFIXES = ("roll", "pitch", "yaw")


def _distinct(values: np.ndarray, period: float | None, tol: float) -> int:
    """How many clusters ``values`` form (gaps above ``tol``), on a circle of ``period`` if given."""
    v = np.sort(np.mod(values, period) if period else np.asarray(values, dtype=float))
    if v.size == 0:
        return 0
    gaps = np.diff(v) > tol
    n = 1 + int(np.count_nonzero(gaps))
    if period and n > 1 and (v[0] + period - v[-1]) <= tol:
        n -= 1  # the first and the last cluster meet across the wrap (359.95° and 0°)
    return n


def joint_angle_counts(model: RobotModel, joints: np.ndarray) -> tuple[int, ...]:
    """Distinct values of every joint in ``joints`` ``(n, g)`` [rad, mm]: a revolute joint's modulo a
    full turn (q and q ± 360° are one angle), values within :data:`DISTINCT_ANGLE_RAD` /
    :data:`DISTINCT_LENGTH_MM` counted once."""
    q = np.asarray(joints, dtype=float).reshape(-1, model.n_joints)
    return tuple(_distinct(q[:, j], 2 * np.pi if kind == "revolute" else None,
                           DISTINCT_ANGLE_RAD if kind == "revolute" else DISTINCT_LENGTH_MM)
                 for j, kind in enumerate(model.joint_types))


def few_angle_joints(model: RobotModel, joints: np.ndarray) -> tuple[tuple[int, int], ...]:
    """``(joint number, distinct values)`` of every joint the data show at fewer than
    :data:`MIN_DISTINCT_ANGLES` distinct values (1-based joint numbers)."""
    return tuple((j + 1, n) for j, n in enumerate(joint_angle_counts(model, joints)) if n < MIN_DISTINCT_ANGLES)


def few_angles_text(model: RobotModel, joints: np.ndarray) -> str | None:
    """The sentence naming the joints of :func:`few_angle_joints` and their values (None: none)."""
    few = few_angle_joints(model, joints)
    if not few:
        return None
    q = np.asarray(joints, dtype=float).reshape(-1, model.n_joints)
    parts = []
    for j, n in few:
        revolute = model.joint_types[j - 1] == "revolute"
        vals = np.unique(np.round(np.degrees(q[:, j - 1]) if revolute else q[:, j - 1], 3))
        shown = ", ".join(f"{v:g}{'°' if revolute else ' mm'}" for v in vals[:6]) + (" …" if len(vals) > 6 else "")
        parts.append(f"joint {j} stands at {n} distinct {'angle' if revolute else 'position'}{'s' if n != 1 else ''}"
                     + (" modulo a turn" if revolute else "") + f" ({shown})")
    return ("; ".join(parts) + f": fewer than {MIN_DISTINCT_ANGLES} distinct values cannot place a joint's axis "
            f"(q and q ± 360° are the same angle)")


@dataclass(frozen=True)
class Implausible:
    """A parameter beyond what a robot built to its file deviates by: its identified value, the
    robot file's geometry in the same gauge, the deviation and the limit [mm or rad], its σ."""

    name: str
    value: float
    reference: float
    deviation: float
    limit: float
    sigma: float

    @property
    def is_angle(self) -> bool:
        return self.name.endswith(_ANGLE_SUFFIXES)

    def describe(self) -> str:
        if self.is_angle:
            return (f"{self.name} = {np.degrees(self.value):.4f}°, {np.degrees(self.deviation):+.3f}° from the robot "
                    f"file's geometry in the same parameters (plausible within ±{np.degrees(self.limit):g}°) at "
                    f"σ {np.degrees(self.sigma) * 3600:.3g}″")
        return (f"{self.name} = {self.value:.3f} mm, {self.deviation:+.3f} mm from the robot file's geometry in the "
                f"same parameters (plausible within ±{self.limit:g} mm) at σ {self.sigma * 1e3:.3g} µm")

    def to_dict(self) -> dict:
        scale, unit = (np.degrees(1.0), "deg") if self.is_angle else (1.0, "mm")
        return {"name": self.name, "unit": unit, "value": self.value * scale, "reference": self.reference * scale,
                "deviation": self.deviation * scale, "limit": self.limit * scale,
                "sigma": self.sigma * scale}


@dataclass(frozen=True)
class Plausibility:
    """Result of :func:`plausibility`: ``implausible`` parameters (largest deviation per limit
    first), ``deviations`` ``{name: (deviation, limit)}`` of every compared parameter [mm, rad],
    ``few_angles`` the joints of :func:`few_angle_joints`, ``compared``: False where the robot
    file's geometry could not be expressed in the fit's gauge (``note`` says why)."""

    implausible: tuple[Implausible, ...]
    deviations: dict[str, tuple[float, float]]
    few_angles: tuple[tuple[int, int], ...]
    compared: bool
    note: str = ""
    #: RMS [mm] of the identified robot's points against its file's geometry (same tool, best
    #: rigid placement) at WORKSPACE_POSES poses over the joint ranges and at the data's
    workspace_mm: float = 0.0
    workspace_ok: bool = True

    @property
    def ok(self) -> bool:
        return not self.implausible and self.workspace_ok

    def to_dict(self) -> dict:
        return {"plausible": self.ok, "compared": self.compared, "note": self.note,
                "workspace_deviation_mm": self.workspace_mm,
                "implausible": [p.to_dict() for p in self.implausible],
                "joints_with_few_distinct_values": [{"joint": j, "distinct_values": n} for j, n in self.few_angles],
                "limits": {"length_mm": PLAUSIBLE_LENGTH_MM, "angle_deg": float(np.degrees(PLAUSIBLE_ANGLE_RAD))}}


def _reference_params(model: RobotModel, params: np.ndarray, chosen: tuple[str, ...], q: np.ndarray) -> np.ndarray:
    """The robot file's geometry standing where ``params`` stands: the identified tool where it was
    fitted (a marker's offset is no robot deviation) and the set-up of the best rigid fit of its
    points onto the identified robot's at joints ``q``."""
    ref = np.array(model.nominal, dtype=float)
    if any(n.startswith("K.") for n in chosen):
        ref[-6:] = params[-6:]
    pts = forward(model, q, params)[:, :3, 3]
    ref[:6] = rigid_setup(model, q, pts, params=ref)
    return ref


def _gauge_deviations(model: RobotModel, kind: str, q: np.ndarray, params: np.ndarray, ref: np.ndarray,
                      chosen: tuple[str, ...]) -> np.ndarray | None:
    """``ref`` expressed with the parameters ``chosen``, the others held at ``params``' values: a
    noise-free fit at joints ``q`` (over the joint ranges: at the data's poses alone a wrong
    branch reproduces the file's geometry as well as the right one) that starts from ``params``
    (None where it cannot be fitted)."""
    from station.core.identification.identify import identify  # identification's users import this module

    exact = synthetic_set(model, "pose" if kind == "pose" else "position", q, ref)
    try:
        # no residual limit: where the fit converged to another branch (a mirror solution the data
        # cannot tell apart), the file's geometry is reached only partly, and what is left is the point
        return identify(model, exact, start=params, chosen=chosen, register_frame=False,
                        max_rms_normalized=np.inf).params
    except (IdentificationError, ConfigError):
        return None


def plausibility(model: RobotModel, data: MeasurementSet, params: np.ndarray, chosen: tuple[str, ...],
                 sigma: np.ndarray, length_mm: float = PLAUSIBLE_LENGTH_MM,
                 angle_rad: float = PLAUSIBLE_ANGLE_RAD) -> Plausibility:
    """Compare the identified ``params`` (fitted ``chosen`` with σ ``sigma``, from ``data``) with the
    robot file's geometry in the same gauge (the module says how) over the joint ranges and at the
    data: every chosen parameter except the set-up's (``R.*``) whose deviation exceeds ``length_mm``
    / ``angle_rad`` is implausible, and so is a robot whose points over the joint ranges stand
    further than ``length_mm`` RMS from its file's after the best rigid placement."""
    params = np.asarray(params, dtype=float)
    few = few_angle_joints(model, data.joints)
    # each pose once: a data set's repeated poses would be exact copies in the noise-free fit below
    q = np.unique(np.concatenate([spread_joints(model, WORKSPACE_POSES, np.random.default_rng(WORKSPACE_SEED)),
                                  np.asarray(data.joints, dtype=float)]), axis=0)
    ref = _reference_params(model, params, chosen, q)
    d = forward(model, q, params)[:, :3, 3] - forward(model, q, ref)[:, :3, 3]
    workspace = float(np.sqrt(np.mean(np.sum(d**2, axis=1))))
    gauge = _gauge_deviations(model, data.kind, q, params, ref, chosen)
    dev: dict[str, tuple[float, float]] = {}
    bad = []
    for k, name in enumerate(chosen):
        if name.startswith("R.") or gauge is None:
            continue  # the set-up: the instrument stands wherever it stands
        i = model.param_index(name)
        dv = float(params[i] - gauge[i])
        limit = angle_rad if name.endswith(_ANGLE_SUFFIXES) else length_mm
        if name.endswith(_ANGLE_SUFFIXES):
            dv = float((dv + np.pi) % (2 * np.pi) - np.pi)
        dev[name] = (dv, limit)
        if abs(dv) > limit:
            bad.append(Implausible(name, float(params[i]), float(gauge[i]), dv, limit, float(sigma[k])))
    if workspace > length_mm and not bad and dev:  # name the parameter that carries most of it
        name = max(dev, key=lambda n: abs(dev[n][0]) / dev[n][1])
        i, k = model.param_index(name), chosen.index(name)
        bad.append(Implausible(name, float(params[i]), float(params[i] - dev[name][0]), dev[name][0],
                               dev[name][1], float(sigma[k])))
    bad.sort(key=lambda b: -abs(b.deviation) / b.limit)
    note = "" if gauge is not None else "the robot file's geometry could not be expressed in the fit's parameters"
    return Plausibility(tuple(bad), dev, few, gauge is not None, note, workspace, workspace <= length_mm)


def refusal_text(p: Plausibility, cause_text: str | None) -> str:
    """The message of an implausible result: the parameters, their values and σ, the likely cause
    and what to do."""
    shown = "; ".join(b.describe() for b in p.implausible[:3]) or "no single parameter"
    if len(p.implausible) > 3:
        shown += f" (and {len(p.implausible) - 3} more)"
    shown += (f"; over the joint ranges its points stand {p.workspace_mm:.3g} mm RMS from the robot file's geometry "
              f"(same tool, best rigid placement)")
    cause = (f"Likely cause: {cause_text}. " if cause_text else
             "Likely cause: the poses barely separate these parameters from others (a joint moved through a small "
             "range, or angles that wrap to the same value). ")
    return (f"the fit converged to a robot far from its robot file: {shown}. Its σ describes the fit's "
            f"linearisation, not this: the result is refused and nothing was written. {cause}"
            f"Measure poses that move every joint through at least {MIN_DISTINCT_ANGLES} distinct angles (modulo a "
            f"turn) over its range, or hold the parameters named (--fix); if the robot really differs from its file "
            f"by this much, correct the robot file's nominal geometry")


def require_plausible(model: RobotModel, data: MeasurementSet, params: np.ndarray, chosen: tuple[str, ...],
                      sigma: np.ndarray, length_mm: float = PLAUSIBLE_LENGTH_MM,
                      angle_rad: float = PLAUSIBLE_ANGLE_RAD) -> Plausibility:
    """:func:`plausibility`, raising :class:`~station.errors.IdentificationError` (exit 3) with
    :func:`refusal_text` when a parameter is implausible; returns the check otherwise."""
    p = plausibility(model, data, params, chosen, sigma, length_mm, angle_rad)
    if not p.ok:
        raise IdentificationError(refusal_text(p, few_angles_text(model, data.joints)))
    return p
