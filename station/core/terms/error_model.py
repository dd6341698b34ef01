"""Error terms beyond geometry (issue 30): joint compliance under gravity, cyclic joint errors,
drift over the measurement and backlash. Pure functions; mm, rad, kg, N·m inside.

Every term is *linear in its parameters* at the measured joints: a joint term moves the joint
angles the robot really stands at, ``q_true = q + B(q) · x`` with ``B`` ``(n, g, k)``, before the
forward kinematics; a task term (drift) moves the measured point, ``p_meas = p + D · x`` with
``D`` ``(n, 3, k)``. :class:`TermBasis` holds ``B`` and ``D`` for one data set with every
parameter's name and unit; :func:`term_basis` builds it for the families asked for.

Families (:data:`FAMILIES`):

* ``compliance`` — joint compliance under gravity, ``Δq_i = c_i · τ_i(q)``, one parameter per
  joint the gravity loads. ``τ_i`` [N·m] is the gravity torque about joint i at the measured
  joints of the nominal geometry, from the link masses and centres of mass when the robot's
  :class:`GravityModel` gives them (``c_i`` in rad/(N·m)), plus the payload (kg, centre in the
  tool frame). Without masses, a *lumped* torque: a unit mass (1 kg) at the origin of every joint
  after i and at the tool point — ``c_i`` is then in rad per (N·m of that lumped term), the
  product of the unknown masses and the joint's compliance. Joints whose torque hardly varies over
  the data (a vertical axis 1: none; under :data:`LOADED_SHARE` of the most loaded joint's) get
  no term. Gravity is −z of the robot base frame unless the :class:`GravityModel` says otherwise.
* ``mass_shape`` — where the robot file gives no masses, the lumped torque's shape fitted: per
  loaded joint, one parameter per lumped point it carries (the joint's compliance times the mass
  there), :mod:`station.core.terms.mass_shape`.
* ``cyclic.q<j>`` — the first harmonic of joint j's angle: ``Δq_j = a·cos(r_j q_j) + b·sin(r_j q_j)``
  [rad] (a gear's eccentricity, an encoder's once-per-turn error), ``r_j`` the gear ratio of the
  angle the error cycles with (1: the joint angle; the motor angle where the robot gives ratios).
  ``cyclic2.q<j>`` adds the second harmonic (cos 2rq, sin 2rq). Revolute joints only.
* ``drift`` — a linear drift of the measured point over the measurement, ``Δp = v · t`` with
  ``t`` the time (or row order) scaled to −½ … ½ from the first row to the last: ``v`` [mm] is the
  drift from the first row to the last (x, y, z of the measuring instrument's frame).
* ``backlash`` — lost motion where the data say from which side each joint arrived:
  ``Δq_j = ½ b_j · s_j`` with ``s_j = ±1`` the approach sign; ``b_j`` [rad, mm for prismatic] is
  the full width of the lost motion.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from station.core.kinematics.forward import _chain
from station.core.kinematics.model import RobotModel
from station.errors import ConfigError

__all__ = ["FAMILIES", "GravityModel", "TermRows", "TermBasis", "TermSpec", "term_basis", "gravity_torques",
           "available_families", "apply_terms", "family_of", "prediction_basis"]

#: joints loaded by gravity less than this share of the most loaded joint's RMS torque get no
#: compliance term (a vertical axis 1, a wrist that carries only the tool)
LOADED_SHARE = 0.1
STANDARD_GRAVITY = 9.80665


def family_of(name: str) -> str:
    """The family of a parameter name: ``compliance.q2`` → ``compliance``; ``cyclic.q4.cos1`` →
    ``cyclic.q4``; ``drift.x`` → ``drift``."""
    head, _, rest = name.partition(".")
    if head in ("cyclic", "cyclic2"):
        return f"{head}.{rest.split('.')[0]}"
    return head


@dataclass(frozen=True)
class GravityModel:
    """What the gravity torques are computed from. ``gravity``: ``(3,)`` [m/s²] in the robot base
    frame. ``masses``: ``(g,)`` [kg] of the link each joint moves (None: lumped unit masses, see the
    module); ``com``: ``(g, 3)`` [mm] each link's centre of mass in its frame after the joint's
    motion. ``payload_kg`` at ``payload_com`` ``(3,)`` [mm] in the tool frame."""

    gravity: tuple[float, float, float] = (0.0, 0.0, -STANDARD_GRAVITY)
    masses: tuple[float, ...] | None = None
    com: tuple[tuple[float, float, float], ...] | None = None
    payload_kg: float = 0.0
    payload_com: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def lumped(self) -> bool:
        return self.masses is None


@dataclass(frozen=True)
class TermRows:
    """What the data say per row beyond the joints: ``order`` ``(n,)`` the time or row number of
    every row (None: the row order), ``approach`` ``(n, g)`` the sign (±1) each joint arrived from
    (None: not recorded; no backlash term), ``payload_kg`` the payload carried."""

    order: np.ndarray | None = None
    approach: np.ndarray | None = None
    #: ``(n,)`` [kg] the payload of every row (None: the gravity model's), at its ``payload_com``
    payload_kg: np.ndarray | None = None


@dataclass(frozen=True)
class TermSpec:
    """The extra terms of a model: ``families`` (names as in :data:`FAMILIES`, e.g.
    ``("compliance", "cyclic.q2")``), how gravity acts, and the gear ratios ``(g,)`` the cyclic
    terms cycle with (None: the joint angles)."""

    families: tuple[str, ...] = ()
    gravity: GravityModel = field(default_factory=GravityModel)
    ratios: tuple[float, ...] | None = None


#: the family kinds; ``cyclic`` and ``cyclic2`` are per joint (``cyclic.q3``)
FAMILIES = ("compliance", "mass_shape", "cyclic", "cyclic2", "drift", "backlash")


@dataclass(frozen=True)
class TermBasis:
    """The extra terms at one data set's rows. ``names``/``units``: ``(k,)``; ``B``: ``(n, g, k)``
    joint change per unit parameter; ``D``: ``(n, 3, k)`` [mm per unit parameter] change of the
    measured point."""

    names: tuple[str, ...]
    units: tuple[str, ...]
    B: np.ndarray
    D: np.ndarray

    @property
    def size(self) -> int:
        return len(self.names)

    def subset(self, rows: np.ndarray) -> "TermBasis":
        rows = np.asarray(rows, dtype=int)
        return TermBasis(self.names, self.units, self.B[rows], self.D[rows])

    def select(self, keep: np.ndarray) -> "TermBasis":
        """The basis of the parameters ``keep`` (indices)."""
        keep = np.asarray(keep, dtype=int)
        return TermBasis(tuple(self.names[i] for i in keep), tuple(self.units[i] for i in keep),
                         self.B[..., keep], self.D[..., keep])

    def joint_delta(self, x: np.ndarray) -> np.ndarray:
        """``(n, g)`` joint change at parameters ``x`` ``(k,)``."""
        return self.B @ np.asarray(x, dtype=float)

    def point_delta(self, x: np.ndarray) -> np.ndarray:
        """``(n, 3)`` [mm] change of the measured point at ``x``."""
        return self.D @ np.asarray(x, dtype=float)


def gravity_torques(model: RobotModel, joints: np.ndarray, gravity: GravityModel, params=None,
                    payload_kg: np.ndarray | None = None) -> np.ndarray:
    """``(n, g)`` [N·m] gravity torque about every joint axis (revolute; a prismatic joint: the
    force along it [N]) at ``joints`` ``(n, g)`` of the geometry ``params`` (default nominal), in
    the robot base frame (the set-up R plays no part). Lumped (no masses): 1 kg at every later
    joint's origin and at the tool point. ``payload_kg`` ``(n,)``: each row's payload [kg] at the
    gravity model's ``payload_com``, in place of its ``payload_kg``."""
    q = model.check_joints(joints)
    T, pres, consts, _ = _chain(model, q, params, setup=False, keep_frames=True)
    jt = model.joint_transforms
    axes = [pres[t] @ consts[t] for t in jt]  # frame whose z axis is joint k's axis, (n, 4, 4)
    bodies = [pres[t + 1] for t in jt]  # link k's frame after joint k's motion
    g_vec = np.asarray(gravity.gravity, dtype=float)
    tool = T[..., :3, 3]
    # point masses [kg], their positions [mm] and the last joint that carries each
    if gravity.lumped:
        points = [np.broadcast_to(a[..., :3, 3], tool.shape) for a in axes[1:]] + [tool]
        last = list(range(len(axes) - 1)) + [len(axes) - 1]  # joint m's origin: carried by joints < m
        mass = [1.0] * len(points)
    else:
        assert gravity.masses is not None
        if len(gravity.masses) != model.n_joints:
            raise ConfigError(f"gravity model gives {len(gravity.masses)} link masses for {model.n_joints} joints")
        com = np.zeros((model.n_joints, 3)) if gravity.com is None else np.asarray(gravity.com, dtype=float)
        points = [np.einsum("...ij,j->...i", b[..., :3, :3], com[k]) + b[..., :3, 3] for k, b in enumerate(bodies)]
        last = list(range(model.n_joints))  # link k: carried by joints 1 … k
        mass = [float(m) for m in gravity.masses]
    payload = gravity.payload_kg if payload_kg is None else np.asarray(payload_kg, dtype=float)
    if np.any(payload):
        if np.ndim(payload) and np.shape(payload) != (q.shape[0],):
            raise ConfigError(f"payload per row: {q.shape[0]} values needed, got shape {np.shape(payload)}")
        pc = np.asarray(gravity.payload_com, dtype=float)
        points.append(np.einsum("...ij,j->...i", T[..., :3, :3], pc) + tool)
        last.append(model.n_joints - 1)
        mass.append(payload)  # type: ignore[arg-type]  # a number, or one per row
    tau = np.zeros(q.shape)
    for i, a in enumerate(axes):
        z = np.broadcast_to(a[..., :3, 2], tool.shape)
        o = a[..., :3, 3]
        for pt, k_last, m in zip(points, last, mass):
            if i > k_last:
                continue
            force = np.asarray(m, dtype=float)[..., None] * g_vec  # N: (3,), or (n, 3) for a payload per row
            if model.joint_types[i] == "revolute":
                lever = (pt - o) * 1e-3  # m
                tau[..., i] += np.einsum("...c,...c->...", z, np.cross(lever, force))
            else:
                tau[..., i] += np.einsum("...c,...c->...", z, np.broadcast_to(force, z.shape))
    return tau


def available_families(model: RobotModel, rows: TermRows | None = None) -> tuple[str, ...]:
    """The families a data set can carry: compliance, the harmonics of every revolute joint, drift,
    and backlash where the data give the approach direction."""
    fams = ["compliance"]
    for j, t in enumerate(model.joint_types):
        if t == "revolute":
            fams.append(f"cyclic.q{j + 1}")
    fams.append("drift")
    if rows is not None and rows.approach is not None:
        fams.append("backlash")
    return tuple(fams)


def _scaled_order(n: int, order: np.ndarray | None) -> np.ndarray:
    t = np.arange(n, dtype=float) if order is None else np.asarray(order, dtype=float)
    if t.shape != (n,) or not np.all(np.isfinite(t)):
        raise ConfigError(f"the drift needs one finite time or row number per row ({n}), got shape {t.shape}")
    span = float(t.max() - t.min()) if n else 0.0
    if span <= 0.0:
        return np.zeros(n)
    return (t - t.min()) / span - 0.5


def term_basis(model: RobotModel, joints: np.ndarray, spec: TermSpec, rows: TermRows | None = None,
               params=None, loaded: tuple[int, ...] | None = None) -> TermBasis:
    """The basis of ``spec``'s families at ``joints`` ``(n, g)`` (the measured joints; compliance
    from the geometry ``params``, default nominal; ``loaded``: the 0-based joints that get a
    compliance term, default those the gravity loads over these joints). A family the data cannot
    carry (backlash without approach signs, a harmonic of a prismatic joint) raises
    :class:`ConfigError`."""
    q = model.check_joints(joints)
    n, g = q.shape
    rows = TermRows() if rows is None else rows
    names: list[str] = []
    units: list[str] = []
    Bcols: list[np.ndarray] = []
    Dcols: list[np.ndarray] = []

    def add(name: str, unit: str, b: np.ndarray | None = None, d: np.ndarray | None = None) -> None:
        names.append(name)
        units.append(unit)
        Bcols.append(np.zeros((n, g)) if b is None else b)
        Dcols.append(np.zeros((n, 3)) if d is None else d)

    ratios = np.ones(g) if spec.ratios is None else np.asarray(spec.ratios, dtype=float)
    for fam in dict.fromkeys(spec.families):  # in the given order, once each
        head, _, joint = fam.partition(".")
        if fam in ("compliance", "mass_shape"):
            tau = gravity_torques(model, q, spec.gravity, params, rows.payload_kg)
            rms = np.sqrt(np.mean(tau**2, axis=0))
            unit = "rad/(N·m)" if not spec.gravity.lumped else "rad per N·m of the lumped term"
            if loaded is None:
                loaded = tuple(np.nonzero(rms >= LOADED_SHARE * rms.max())[0].tolist() if rms.max() > 0 else [])
            if fam == "mass_shape":
                _add_mass_shape(model, q, spec.gravity, params, loaded, add)
                continue
            for jl in loaded:
                b = np.zeros((n, g))
                b[:, jl] = tau[:, jl]
                add(f"compliance.q{jl + 1}", unit if model.joint_types[jl] == "revolute" else "mm/N", b)
        elif head in ("cyclic", "cyclic2") and joint.startswith("q") and joint[1:].isdigit():
            j = int(joint[1:]) - 1
            if not (0 <= j < g) or model.joint_types[j] != "revolute":
                raise ConfigError(f"{fam}: joint {j + 1} is not a revolute joint of {model.name!r}")
            for h in ((1,) if head == "cyclic" else (1, 2)):
                for fn, label in ((np.cos, "cos"), (np.sin, "sin")):
                    b = np.zeros((n, g))
                    b[:, j] = fn(h * ratios[j] * q[:, j])
                    add(f"cyclic.q{j + 1}.{label}{h}", "rad", b)
        elif fam == "drift":
            t = _scaled_order(n, rows.order)
            for c, axis in enumerate("xyz"):
                d = np.zeros((n, 3))
                d[:, c] = t
                add(f"drift.{axis}", "mm over the measurement", d=d)
        elif fam == "backlash":
            if rows.approach is None:
                raise ConfigError("backlash needs the approach direction of every joint per row; the data have none")
            s = np.asarray(rows.approach, dtype=float)
            if s.shape != (n, g):
                raise ConfigError(f"approach signs must have shape ({n}, {g}), got {s.shape}")
            for j in range(g):
                if np.all(s[:, j] == s[0, j]):
                    continue  # one side only: merges with the joint's zero
                b = np.zeros((n, g))
                b[:, j] = 0.5 * np.sign(s[:, j])
                add(f"backlash.q{j + 1}", "rad" if model.joint_types[j] == "revolute" else "mm", b)
        else:
            raise ConfigError(f"unknown error term {fam!r}; terms are compliance, mass_shape, cyclic.q<j>, "
                              f"cyclic2.q<j>, drift, backlash")
    B = np.stack(Bcols, axis=-1) if Bcols else np.zeros((n, g, 0))
    D = np.stack(Dcols, axis=-1) if Dcols else np.zeros((n, 3, 0))
    return TermBasis(tuple(names), tuple(units), B, D)


def _add_mass_shape(model: RobotModel, q: np.ndarray, gravity: GravityModel, params, loaded: tuple[int, ...],
                    add) -> None:
    """The ``mass_shape`` columns (:mod:`station.core.terms.mass_shape`): per loaded joint, the
    torque of 1 kg at every lumped point it carries. Only where the robot file gives no masses."""
    from station.core.terms.mass_shape import FAMILY, UNIT, lumped_points, point_torques

    if not gravity.lumped:
        raise ConfigError("mass_shape: the robot file gives the masses; the compliance term takes its torque shape "
                          "from them (the shape is fitted only where a file has none)")
    tau_b = point_torques(model, q, gravity.gravity, params)
    for jl in loaded:
        for b, label in enumerate(lumped_points(model)):
            if np.any(tau_b[b, :, jl] != 0.0):
                col = np.zeros(q.shape)
                col[:, jl] = tau_b[b, :, jl]
                add(f"{FAMILY}.q{jl + 1}.{label}", UNIT, col)


def apply_terms(model: RobotModel, joints: np.ndarray, params, basis: TermBasis, x, setup: bool = True) -> np.ndarray:
    """World←tool transforms ``(n, 4, 4)`` of the robot ``params`` with the extra terms ``x`` of
    ``basis`` (built at these joints): the joints moved by ``B·x``, the point by ``D·x``."""
    from station.core.kinematics.forward import forward

    q = np.asarray(joints, dtype=float) + basis.joint_delta(x)
    T = np.array(forward(model, q, params, setup=setup))
    T[..., :3, 3] += basis.point_delta(x)
    return T


def prediction_basis(model: RobotModel, joints: np.ndarray, families: tuple[str, ...], names: tuple[str, ...],
                     gravity: GravityModel | None = None,
                     ratios: tuple[float, ...] | None = None) -> tuple[TermBasis, tuple[str, ...]]:
    """The basis of the stored terms ``names`` (of ``families``) at new joints ``(n, g)``, to predict
    where the robot stands, and the terms it leaves at zero: drift (it describes a measurement run,
    not the robot) and backlash (the approach direction of new joints is not known: the middle of
    the lost motion). Unknown names raise :class:`ConfigError`."""
    q = model.check_joints(joints)
    loaded = tuple(dict.fromkeys(int(n.split(".q")[1].split(".")[0]) - 1 for n in names
                                 if n.startswith(("compliance.q", "mass_shape.q"))))
    kept = tuple(f for f in families if f not in ("drift", "backlash"))
    b = term_basis(model, q, TermSpec(kept, gravity or GravityModel(), ratios), loaded=loaded)
    zeros = tuple(n for n in names if family_of(n) in ("drift", "backlash"))
    missing = [n for n in names if n not in b.names and n not in zeros]
    if missing:
        raise ConfigError(f"error terms {missing} are not terms of the families {list(families)}")
    n, g = q.shape
    B = np.zeros((n, g, len(names)))
    for k, name in enumerate(names):
        if name not in zeros:
            B[..., k] = b.B[..., b.names.index(name)]
    units = tuple(b.units[b.names.index(nm)] if nm in b.names else "" for nm in names)
    return TermBasis(tuple(names), units, B, np.zeros((n, 3, len(names)))), zeros
