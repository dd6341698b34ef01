"""Is a kept term's physical size plausible for the robot's class? (issue 38) Pure numerics.

A term is fitted as whatever number best fits the data; a gear error of half a degree or a joint
that sags by a centimetre per metre fits as well as a real one, and says that the term carries
something else (a set-up that moved, a wrong robot file). Every kept joint term is judged by the
largest joint turn it gives over the data, with its σ (the fit's covariance of the term values);
a compliance in rad/(N·m) (the robot file gives masses) also by the joint stiffness it implies.
The limits and why (docs/error-terms.md, "Term sizes"):

* **gravity sag** (``compliance`` and ``mass_shape`` of one joint together): at most
  :data:`SAG_MAX_RAD` (5 mrad, 5 mm per metre of lever). Published joint-stiffness identifications
  of industrial arms give 10⁵–10⁷ N·m/rad for the main axes; under the gravity torques of their
  own weight (10²–10⁴ N·m, balancers included) that is 0.01–2 mrad. The heavy FANUC R-2000iC of
  the real tracker data sags up to 1.8 mrad at J3 (377″, ``bench_real_data.py``); the simulated
  IRB 2600 class ~0.3 mrad. Beyond 5 mrad the arm would miss its data sheet's repeatability class
  under a payload change alone.
* **cyclic** (a harmonic of a joint) and **backlash** (its full width): at most
  :data:`GEAR_MAX_RAD` (3 arcmin). Robot reducers are specified for a lost motion and a
  transmission error of about 1 arcmin (RV cycloidal and harmonic drives of robot sizes); three
  times that allows for wear and an encoder's own once-per-turn error.
* **stiffness** (compliance with the file's masses): within the class's range of
  :data:`CLASSES` widened by :data:`STIFFNESS_MARGIN` either way: small arms (reach under 1 m,
  harmonic drives, cobots with torque sensors) 10⁴–10⁶, medium (1–2 m) 10⁵–10⁷, heavy (over 2 m)
  10⁶–5·10⁷ N·m/rad.

A size is implausible when it exceeds its limit by more than 2 σ. The robot's class comes from the
robot file: its reach (the tool point's largest distance from joint 1's axis over the joint ranges)
and its payload where its ``[gravity]`` gives one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from station.core.kinematics.model import RobotModel
from station.core.terms.fit import TermFit

__all__ = ["SAG_MAX_RAD", "GEAR_MAX_RAD", "CLASSES", "RobotClass", "TermSize", "robot_class", "term_sizes"]

#: the largest gravity sag [rad] of one joint a real arm shows (see the module)
SAG_MAX_RAD = 5e-3
#: the largest once-per-turn error or lost motion [rad] of a robot joint's reducer (3 arcmin)
GEAR_MAX_RAD = float(np.radians(3.0 / 60.0))
#: (class, reach from [mm], reach to [mm], joint stiffness range [N·m/rad]) of the main axes
CLASSES = (("small", 0.0, 1000.0, (1e4, 1e6)), ("medium", 1000.0, 2000.0, (1e5, 1e7)),
           ("heavy", 2000.0, float("inf"), (1e6, 5e7)))
#: the stiffness ranges are widened this many times either way before a compliance is implausible
STIFFNESS_MARGIN = 10.0
#: a size beyond its limit by more than this many σ is implausible
SIGMAS = 2.0
_ARCSEC = float(np.radians(1.0 / 3600.0))


@dataclass(frozen=True)
class RobotClass:
    """The class a robot's term sizes are judged in: ``name``, ``reach_mm`` (the tool point's
    largest distance from joint 1's axis), ``payload_kg`` (None: the robot file gives none), ``stiffness`` the
    plausible joint stiffness range [N·m/rad]."""

    name: str
    reach_mm: float
    payload_kg: float | None
    stiffness: tuple[float, float]

    def to_dict(self) -> dict:
        return {"class": self.name, "reach_mm": self.reach_mm, "payload_kg": self.payload_kg,
                "stiffness_nm_per_rad": list(self.stiffness), "units": {"reach_mm": "mm", "payload_kg": "kg",
                                                                        "stiffness_nm_per_rad": "N·m/rad"}}


#: poses (seeded) over the joint ranges at which the reach is taken
REACH_POSES = 256


def robot_class(model: RobotModel, payload_kg: float | None = None) -> RobotClass:
    """The class of ``model`` by its reach, with the payload the robot file gives (None: none). The
    reach: the largest distance of the tool point from joint 1's axis at :data:`REACH_POSES` seeded
    poses over the joint ranges of the nominal geometry (a data sheet's reach is the wrist centre's
    or the flange's; the tool point is within a tool length of it)."""
    from station.core.kinematics.forward import _chain
    from station.core.kinematics.poses import spread_joints

    q = spread_joints(model, REACH_POSES, np.random.default_rng(38))
    T, pres, consts, _ = _chain(model, q, None, setup=False, keep_frames=True)
    axis = pres[model.joint_transforms[0]] @ consts[model.joint_transforms[0]]
    d = T[:, :3, 3] - axis[..., :3, 3]
    z = np.broadcast_to(axis[..., :3, 2], d.shape)
    radial = d - np.sum(d * z, axis=1, keepdims=True) * z
    reach = float(np.max(np.linalg.norm(radial, axis=1)))
    name, _, _, stiff = next(c for c in CLASSES if c[1] <= reach < c[2])
    return RobotClass(name, reach, payload_kg if payload_kg else None, stiff)


@dataclass(frozen=True)
class TermSize:
    """One joint's kept terms of one kind (``gravity sag``, ``cyclic``, ``backlash``): the largest
    joint turn they give over the data and its σ [rad], the tool displacement at the class's reach
    [mm], the limit [rad]; ``stiffness`` ``(value, σ)`` [N·m/rad] of a compliance with masses."""

    joint: int
    kind: str
    terms: tuple[str, ...]
    turn_rad: float
    sigma_rad: float
    tool_mm: float
    limit_rad: float
    stiffness: tuple[float, float] | None = None
    stiffness_range: tuple[float, float] | None = None

    @property
    def plausible(self) -> bool:
        ok = abs(self.turn_rad) - SIGMAS * self.sigma_rad <= self.limit_rad
        if self.stiffness is not None and self.stiffness_range is not None:
            k, s = self.stiffness
            lo, hi = self.stiffness_range
            ok = ok and k + SIGMAS * s >= lo / STIFFNESS_MARGIN and k - SIGMAS * s <= hi * STIFFNESS_MARGIN
        return ok

    def describe(self) -> str:
        text = (f"joint {self.joint} {self.kind}: up to {abs(self.turn_rad) / _ARCSEC:.1f} ± {self.sigma_rad / _ARCSEC:.1f}″ "
                f"({self.tool_mm:.3g} mm at the reach; plausible up to {self.limit_rad / _ARCSEC:.0f}″)")
        if self.stiffness is not None:
            text += f", stiffness {self.stiffness[0]:.3g} ± {self.stiffness[1]:.2g} N·m/rad"
        return text + ("" if self.plausible else " — IMPLAUSIBLE for the robot's class")

    def to_dict(self) -> dict:
        out = {"joint": self.joint, "kind": self.kind, "terms": list(self.terms),
               "largest_turn_arcsec": abs(self.turn_rad) / _ARCSEC, "sigma_arcsec": self.sigma_rad / _ARCSEC,
               "tool_mm": self.tool_mm, "limit_arcsec": self.limit_rad / _ARCSEC, "plausible": self.plausible,
               "units": {"largest_turn_arcsec": "″", "sigma_arcsec": "″", "tool_mm": "mm", "limit_arcsec": "″"}}
        if self.stiffness is not None:
            out["stiffness_nm_per_rad"] = {"value": self.stiffness[0], "sigma": self.stiffness[1],
                                           "plausible_range": list(self.stiffness_range or ()), "unit": "N·m/rad"}
        return out


def _kind(name: str) -> str | None:
    head = name.split(".", 1)[0]
    return {"compliance": "gravity sag", "mass_shape": "gravity sag", "cyclic": "cyclic",
            "backlash": "backlash"}.get(head)


def term_sizes(fit: TermFit, rclass: RobotClass) -> tuple[TermSize, ...]:
    """The size of every kept joint term of ``fit``, joint by joint and kind by kind (the module)."""
    names, B = fit.basis.names, fit.basis.B
    m = len(fit.chosen_index)
    cov = np.asarray(fit.uncertainty.covariance)[m:, m:]
    groups: dict[tuple[int, str], list[int]] = {}
    for k, n in enumerate(names):
        kind = _kind(n)
        if kind is None:
            continue  # drift moves the instrument's point, not a joint
        for jj in np.nonzero(np.any(B[:, :, k] != 0.0, axis=0))[0].tolist():
            groups.setdefault((int(jj), kind), []).append(k)
    out = []
    for (j, kind), cols in sorted(groups.items()):
        b = B[:, j, cols]  # (n, c) joint change per unit term value
        turn = b @ fit.values[cols]
        i = int(np.argmax(np.abs(turn)))
        sigma = float(np.sqrt(max(b[i] @ cov[np.ix_(cols, cols)] @ b[i], 0.0)))
        stiffness = srange = None
        if kind == "gravity sag" and len(cols) == 1 and fit.basis.units[cols[0]] == "rad/(N·m)":
            c, sc = float(fit.values[cols[0]]), float(fit.sigma[cols[0]])
            if c > 0:
                stiffness, srange = (1.0 / c, sc / c**2), rclass.stiffness
        limit = SAG_MAX_RAD if kind == "gravity sag" else GEAR_MAX_RAD
        out.append(TermSize(j + 1, kind, tuple(names[c] for c in cols), float(turn[i]), sigma,
                            abs(float(turn[i])) * rclass.reach_mm, limit, stiffness, srange))
    return tuple(out)
