"""General inverse kinematics on the full model, with joint limits and named configurations.

For every target the solver finds *all* the solutions it can reach from a set of start values,
refines each on the full model (any parameters: nominal or identified) and chooses one
deterministically:

1. **Start values.** For a six-axis arm whose geometry (read from the parameters) has axis 1 ⟂
   axis 2, axes 2 ∥ 3 and a spherical wrist (axes 4, 5, 6 through one point, to within 1 mm),
   the closed form of that idealised geometry gives the eight branches: shoulder, elbow and
   wrist flips (Paden–Kahan subproblems on the axis lines at q = 0). A SCARA gets its two
   closed-form elbows (:func:`station.core.kinematics.forward.scara_ik`'s geometry). Any other chain
   gets a fixed set of 24 start values spread over the limits (the same every call), and so does
   a target that no closed-form branch reached inside the limits (near a double singularity the
   idealised geometry can be too far from the real one). A closed-form branch more than 5 mm
   out of the idealised arm's reach is not refined.
2. **Refinement.** Damped least squares (Levenberg–Marquardt, the analytic joint Jacobian),
   vectorised over targets × start values, until the residual is at round-off level.
3. **Classification.** A solution is *reached* if it misses the target by at most ``tol_mm``
   and ``tol_rad`` (a SCARA: x, y, z, yaw only; it cannot set roll and pitch); it is *valid* if
   it is reached and inside the joint limits (a revolute joint is moved by whole turns into its
   limits where that is possible). Solutions that agree to 1e-7 are one.
4. **Choice.** Among the valid solutions of the requested configuration (:class:`ArmConfig`;
   fields left at 0 mean "any"): the one nearest to ``near`` when it is given, otherwise the one
   with the largest score ``min(margin, ½·wrist sine)`` — ``margin`` the smallest normalised
   distance of a joint to its limits (0 at a limit, ½ mid-range), ``wrist sine`` = |sin| of the
   angle between axes 4 and 6 (≈ |sin q5|; 1 for chains without a wrist). Ties go to the first
   start value in a fixed order, so the same input always gives the same solution. Solutions
   that are near a singularity are taken only if no other is valid.

Configurations of a six-axis arm are geometric, so they mean the same for any parameter set
(:func:`configuration`): with ``w`` the wrist centre, ``o_i``/``z_i`` a point on and the
direction of axis i at the solution,

* ``shoulder = +1`` when the wrist centre lies on the side of axis 1 towards which axis 2 is
  offset (the arm reaches forward), −1 when it reaches over backwards;
* ``elbow = +1`` when the elbow (axis 3) lies on the upper side of the line from axis 2 to the
  wrist centre: seen from the side with the arm reaching to the right, to the left of that
  directed line (for a forward-reaching arm: above it); −1 on the other side;
* ``wrist = sign((z4 × z6) · z5)``; for the usual sign conventions that of sin q5.

A SCARA has only ``elbow`` (+1: q2 > 0, as :func:`~station.core.kinematics.forward.scara_ik`).

Statuses per target: ``ok``; ``unreachable`` (no start value reaches the target: out of
reach; the reason gives the closest miss); ``outside_limits`` (reached only outside the
joint limits; the reason names the joint); ``configuration_unavailable`` (valid solutions
exist, none in the requested configuration); ``near_singularity`` (the chosen solution has
wrist sine below sin(``singular_deg``) or a scaled Jacobian with σ_min/σ_max below
``singular_ratio``; its joints are still returned).

Shapes and units: targets ``(n, 4, 4)`` [mm] in the robot base frame (``setup=True``: in the
measurement frame, through the set-up R); joints ``(n, g)`` [rad | mm].
"""

from __future__ import annotations

import enum
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from station.core.kinematics.forward import _params, forward, joint_jacobian
from station.core.kinematics.ik_geometry import _axes, _is_six_r, _wrist_sine, configuration
from station.core.kinematics.ik_seeds import _seeds, _spread_seeds, has_closed_form
from station.core.kinematics.model import RobotModel
from station.core.kinematics.transforms import pose_error
from station.errors import ConfigError, UnreachableError

# configuration (ik_geometry) and has_closed_form (ik_seeds) are public here, where they always were
__all__ = [
    "ArmConfig",
    "IKStatus",
    "IKSolutions",
    "IKResult",
    "solve_ik",
    "ik_solutions",
    "configuration",
    "has_closed_form",
    "ALL_ARM_CONFIGS",
]

#: rotation residuals are weighted by this length [mm per rad] against positions in the refinement
ROTATION_WEIGHT_MM = 1000.0
_TWO_PI = 2.0 * np.pi
_SCARA_ROWS = np.array([0, 1, 2, 5])
_ALL_ROWS = np.arange(6)


@dataclass(frozen=True)
class ArmConfig:
    """A named arm configuration: each field +1, −1, or 0 for "any" (see the module docstring)."""

    shoulder: int = 0
    elbow: int = 0
    wrist: int = 0

    def __post_init__(self) -> None:
        for name in ("shoulder", "elbow", "wrist"):
            if getattr(self, name) not in (-1, 0, 1):
                raise ConfigError(f"configuration {name} must be +1, -1 or 0 (any), got {getattr(self, name)!r}")

    def as_array(self) -> np.ndarray:
        return np.array([self.shoulder, self.elbow, self.wrist], dtype=int)

    @classmethod
    def from_array(cls, a) -> ArmConfig:
        s, e, w = (int(v) for v in np.asarray(a).reshape(3))
        return cls(s, e, w)

    def __str__(self) -> str:
        def f(v: int) -> str:
            return "any" if v == 0 else f"{v:+d}"
        return f"shoulder {f(self.shoulder)}, elbow {f(self.elbow)}, wrist {f(self.wrist)}"


#: the eight configurations of a six-axis arm, in the order the solver tries them
ALL_ARM_CONFIGS = tuple(ArmConfig(s, e, w) for s in (1, -1) for e in (1, -1) for w in (1, -1))


class IKStatus(str, enum.Enum):
    OK = "ok"
    UNREACHABLE = "unreachable"
    OUTSIDE_LIMITS = "outside_limits"
    CONFIGURATION = "configuration_unavailable"
    NEAR_SINGULARITY = "near_singularity"


@dataclass(frozen=True)
class IKSolutions:
    """Every distinct solution found, per target: arrays ``(n, m, …)`` over ``m`` start values.

    ``joints`` ``(n, m, g)``; ``reached``, ``within_limits``, ``distinct`` ``(n, m)`` bool (a
    duplicate of an earlier start value's solution is not distinct); ``config`` ``(n, m, 3)``
    int; ``margin`` ``(n, m)`` (0 at a limit, ½ mid-range; negative outside);
    ``wrist_sine`` ``(n, m)``; ``condition_ratio`` ``(n, m)`` σ_min/σ_max of the scaled
    Jacobian; ``position_error_mm``, ``angle_error_rad`` ``(n, m)``.
    """

    joints: np.ndarray
    reached: np.ndarray
    within_limits: np.ndarray
    distinct: np.ndarray
    config: np.ndarray
    margin: np.ndarray
    wrist_sine: np.ndarray
    condition_ratio: np.ndarray
    position_error_mm: np.ndarray
    angle_error_rad: np.ndarray

    @property
    def valid(self) -> np.ndarray:
        """``(n, m)``: distinct solutions that reach the target inside the limits."""
        return self.reached & self.within_limits & self.distinct

    def configs_of(self, i: int) -> tuple[ArmConfig, ...]:
        """The configurations of target ``i``'s valid solutions (in start-value order)."""
        return tuple(ArmConfig.from_array(c) for c in self.config[i][self.valid[i]])


@dataclass(frozen=True)
class IKResult:
    """The chosen solution per target. ``joints`` ``(n, g)`` (NaN rows where none: statuses
    unreachable, outside_limits, configuration_unavailable); ``status`` and ``reason`` per
    target (reason "" when ok); ``config`` ``(n, 3)`` of the chosen solution (0 where none);
    ``position_error_mm``/``angle_error_rad`` ``(n,)`` of the chosen (or closest) solution;
    ``margin``, ``wrist_sine`` ``(n,)``; ``n_solutions`` ``(n,)`` valid distinct solutions.
    """

    joints: np.ndarray
    status: tuple[IKStatus, ...]
    reason: tuple[str, ...]
    config: np.ndarray
    position_error_mm: np.ndarray
    angle_error_rad: np.ndarray
    margin: np.ndarray
    wrist_sine: np.ndarray
    n_solutions: np.ndarray
    solutions: IKSolutions

    @property
    def ok(self) -> np.ndarray:
        """``(n,)`` bool: a valid solution away from singularities."""
        return np.array([s is IKStatus.OK for s in self.status], dtype=bool)

    @property
    def has_joints(self) -> np.ndarray:
        """``(n,)`` bool: joints were returned (ok or near a singularity)."""
        return np.isfinite(self.joints).all(axis=-1)

    def failures(self) -> list[tuple[int, IKStatus, str]]:
        """``(index, status, reason)`` of every target that is not ok (0-based index)."""
        return [(i, s, r) for i, (s, r) in enumerate(zip(self.status, self.reason)) if s is not IKStatus.OK]

    def raise_for_failures(self, allow_singular: bool = False) -> np.ndarray:
        """The joints, or :class:`UnreachableError` naming the first failed targets."""
        bad = [(i, s, r) for i, s, r in self.failures()
               if not (allow_singular and s is IKStatus.NEAR_SINGULARITY)]
        if bad:
            head = "; ".join(f"target {i}: {r}" for i, _, r in bad[:3])
            more = f" (and {len(bad) - 3} more)" if len(bad) > 3 else ""
            raise UnreachableError(f"{len(bad)} of {len(self.status)} targets cannot be reached: {head}{more}")
        return self.joints


# --- refinement -------------------------------------------------------------------------------

def _residual(model, q, Tt, p, setup, rows, W):
    res = joint_jacobian(model, q, p, setup=setup)
    e = pose_error(res.T, Tt)[:, rows] * W
    J = res.J[:, rows, :] * W[:, None]
    return e, J


def _refine(model: RobotModel, q0: np.ndarray, Tt: np.ndarray, p, setup: bool, rows: np.ndarray,
            max_iter: int, patience: int) -> np.ndarray:
    """Levenberg–Marquardt from ``q0`` ``(N, g)`` towards ``Tt`` ``(N, 4, 4)``, per row; a row
    stops after ``patience`` nearly undamped accepted steps in a row that did not halve its cost."""
    W = np.where(rows < 3, 1.0, ROTATION_WEIGHT_MM)
    q = q0.copy()
    e, J = _residual(model, q, Tt, p, setup, rows, W)
    cost = np.einsum("ni,ni->n", e, e)
    lam = np.full(q.shape[0], 1e-6)
    active = cost > 1e-24
    slow = np.zeros(q.shape[0], dtype=int)  # accepted steps in a row that did not halve the cost
    g = model.n_joints
    for _ in range(max_iter):
        idx = np.nonzero(active)[0]
        if idx.size == 0:
            break
        Ja, ea = J[idx], e[idx]
        JT = np.swapaxes(Ja, -1, -2)
        A = JT @ Ja
        diag = np.einsum("nii->ni", A)
        A = A + (lam[idx, None] * (diag + 1e-9))[:, :, None] * np.eye(g)
        dq = -np.linalg.solve(A, (JT @ ea[..., None]))[..., 0]
        big = np.max(np.abs(dq), axis=-1)
        dq *= np.minimum(1.0, 0.5 / np.maximum(big, 1e-300))[:, None]  # at most 0.5 rad a step
        q_try = q[idx] + dq
        e_t, J_t = _residual(model, q_try, Tt[idx], p, setup, rows, W)
        c_t = np.einsum("ni,ni->n", e_t, e_t)
        ok = np.isfinite(c_t) & (c_t <= cost[idx])
        # a nearly undamped Gauss-Newton step that does not halve the cost: no exact solution here
        slow[idx] = np.where(ok & (c_t > 0.5 * cost[idx]) & (c_t > 1e-8) & (lam[idx] <= 1e-4), slow[idx] + 1,
                             np.where(ok, 0, slow[idx]))
        acc = idx[ok]
        q[acc], e[acc], J[acc], cost[acc] = q_try[ok], e_t[ok], J_t[ok], c_t[ok]
        lam[acc] = np.maximum(lam[acc] * 0.1, 1e-12)
        lam[idx[~ok]] *= 10.0
        step = np.max(np.abs(dq), axis=-1)
        # converged, or stalled away from a solution (an unreachable branch: it keeps its miss)
        done = (ok & ((c_t < 1e-24) | (step < 1e-13))) | (lam[idx] > 1e10) | (slow[idx] >= patience)
        active[idx[done]] = False
    return q


def _wrap_into_limits(model: RobotModel, q: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Revolute joints moved by whole turns into their limits, nearest to ``ref`` ``(…, g)``."""
    q = q.copy()
    lim = model.joint_limits
    for j, kind in enumerate(model.joint_types):
        if kind != "revolute":
            continue
        lo, hi = lim[j]
        k0 = np.round((ref[..., j] - q[..., j]) / _TWO_PI)
        best = q[..., j] + k0 * _TWO_PI
        best_key = np.full(q.shape[:-1], np.inf)
        for dk in (-1, 0, 1):
            cand = q[..., j] + (k0 + dk) * _TWO_PI
            outside = np.maximum(lo - cand, 0.0) + np.maximum(cand - hi, 0.0)
            key = outside * 1e6 + np.abs(cand - ref[..., j])
            take = key < best_key
            best = np.where(take, cand, best)
            best_key = np.where(take, key, best_key)
        q[..., j] = best
    return q


def _margin(model: RobotModel, q: np.ndarray) -> np.ndarray:
    lim = model.joint_limits
    span = lim[:, 1] - lim[:, 0]
    return np.min(np.minimum(q - lim[:, 0], lim[:, 1] - q) / span, axis=-1)


def _condition_ratio(J: np.ndarray) -> np.ndarray:
    s = np.linalg.svd(J, compute_uv=False)
    return s[..., -1] / np.maximum(s[..., 0], 1e-300)


def ik_solutions(model: RobotModel, T_target, params=None, setup: bool = False, near=None,
                 tol_mm: float = 1e-6, tol_rad: float = 1e-9, max_iter: int = 60) -> IKSolutions:
    """Every distinct solution reachable from the start values (module docstring), refined on
    the model with ``params``. ``near`` ``(n, g)`` (optional) is one more start value per target
    and the reference for whole turns of revolute joints (default: mid-limits)."""
    p = _params(model, params)
    Tt = np.asarray(T_target, dtype=float).reshape(-1, 4, 4)
    n, g = Tt.shape[0], model.n_joints
    near_a = None if near is None else np.asarray(near, dtype=float).reshape(n, g)
    seeds, hopeless, closed = _seeds(model, Tt, p, setup, near_a)
    rows = _SCARA_ROWS if model.is_scara else _ALL_ROWS
    m = seeds.shape[1]
    # start values from a closed form are close (a few slow steps mean a branch out of reach);
    # spread start values may need many steps
    q = np.nan_to_num(seeds.reshape(n * m, g))
    go = ~hopeless.reshape(-1)
    q[go] = _refine(model, q[go], np.repeat(Tt, m, axis=0)[go], p, setup, rows, max_iter,
                    patience=4 if closed else max_iter)
    q = q.reshape(n, m, g)
    if closed:
        # a target that no closed-form branch reached inside the limits (near a double singularity,
        # or a geometry far from the ideal one) gets the spread start values too
        e = pose_error(forward(model, q, p, setup=setup), Tt[:, None])
        ang = np.abs(e[..., 5]) if model.is_scara else np.linalg.norm(e[..., 3:], axis=-1)
        inside = model.within_limits(_wrap_into_limits(model, q, np.broadcast_to(
            model.joint_limits.mean(axis=1) if near_a is None else near_a[:, None, :], q.shape)))
        retry = ~np.any((np.linalg.norm(e[..., :3], axis=-1) <= tol_mm) & (ang <= tol_rad) & inside, axis=1)
        retry &= np.all(np.isfinite(Tt), axis=(1, 2))
        if np.any(retry):
            grid = _spread_seeds(model)
            k, mg = int(retry.sum()), grid.shape[0]
            q2 = _refine(model, np.tile(grid, (k, 1)), np.repeat(Tt[retry], mg, axis=0), p, setup, rows,
                         max_iter, patience=max_iter).reshape(k, mg, g)
            extra = np.repeat(q[:, :1], mg, axis=1)  # duplicates of the first branch where not retried
            extra[retry] = q2
            q = np.concatenate([q, extra], axis=1)
    m = q.shape[1]
    T_rep = np.repeat(Tt, m, axis=0)
    ref = np.repeat(near_a if near_a is not None else np.broadcast_to(model.joint_limits.mean(axis=1), (n, g)),
                    m, axis=0)
    q = _wrap_into_limits(model, q.reshape(n * m, g), ref)
    res = joint_jacobian(model, q, p, setup=setup)
    err = pose_error(res.T, T_rep)
    pos = np.linalg.norm(err[:, :3], axis=-1)
    ang = np.abs(err[:, 5]) if model.is_scara else np.linalg.norm(err[:, 3:], axis=-1)
    reached = (pos <= tol_mm) & (ang <= tol_rad)
    inside = model.within_limits(q)
    Js = res.J[:, rows, :] * np.where(rows < 3, 1.0, ROTATION_WEIGHT_MM)[:, None]
    cond = _condition_ratio(Js)
    if _is_six_r(model):
        _, dirs = _axes(model, q, p, setup)
        wsin = np.abs(_wrist_sine(dirs))
    else:
        wsin = np.ones(n * m)
    cfg = configuration(model, q, p, setup)
    q, cfg = q.reshape(n, m, g), cfg.reshape(n, m, 3)
    reached, inside = reached.reshape(n, m), inside.reshape(n, m)
    distinct = np.ones((n, m), dtype=bool)
    for k in range(1, m):
        same = (np.max(np.abs(q[:, :k] - q[:, k:k + 1]), axis=-1) < 1e-7) & reached[:, :k]
        distinct[:, k] = ~np.any(same, axis=1)
    return IKSolutions(q, reached, inside, distinct, cfg, _margin(model, q), wsin.reshape(n, m),
                       cond.reshape(n, m), pos.reshape(n, m), ang.reshape(n, m))


def _as_configs(configuration, n: int) -> np.ndarray | None:
    if configuration is None:
        return None
    if isinstance(configuration, ArmConfig):
        return np.broadcast_to(configuration.as_array(), (n, 3))
    if isinstance(configuration, Sequence) and configuration and isinstance(configuration[0], ArmConfig):
        if len(configuration) != n:
            raise ConfigError(f"{len(configuration)} configurations for {n} targets")
        return np.array([c.as_array() for c in configuration])
    a = np.asarray(configuration, dtype=int)
    if a.shape == (3,):
        a = np.broadcast_to(a, (n, 3))
    if a.shape != (n, 3) or not np.all(np.isin(a, (-1, 0, 1))):
        raise ConfigError(f"configurations must be ArmConfig or (n, 3) signs in -1, 0, 1; got shape {a.shape}")
    return a


def solve_ik(model: RobotModel, T_target, params=None, setup: bool = False, configuration=None,
             near=None, singular_deg: float = 1.0, singular_ratio: float = 1e-4,
             tol_mm: float = 1e-6, tol_rad: float = 1e-9, max_iter: int = 60) -> IKResult:
    """Joints for targets ``(n, 4, 4)`` chosen deterministically (module docstring); never
    raises for a target: each gets a status and a reason (:meth:`IKResult.raise_for_failures`).

    ``configuration``: an :class:`ArmConfig` for all targets, a sequence of them, or ``(n, 3)``
    signs (0 = any). ``near`` ``(n, g)``: prefer the valid solution nearest to these joints.
    """
    Tt = np.asarray(T_target, dtype=float).reshape(-1, 4, 4)
    n, g = Tt.shape[0], model.n_joints
    want = _as_configs(configuration, n)
    if want is not None and not (_is_six_r(model) or model.is_scara) and np.any(want != 0):
        raise ConfigError(f"robot {model.name!r} has no named configurations (only six-axis arms and SCARAs)")
    if want is not None and model.is_scara and np.any(want[:, [0, 2]] != 0):
        raise ConfigError("a SCARA has only the elbow configuration; leave shoulder and wrist at 0")
    sol = ik_solutions(model, Tt, params, setup, near, tol_mm, tol_rad, max_iter)
    near_a = None if near is None else np.asarray(near, dtype=float).reshape(n, g)
    valid = sol.valid
    singular = (sol.wrist_sine < np.sin(np.radians(singular_deg))) | (sol.condition_ratio < singular_ratio)
    match = np.ones_like(valid) if want is None else np.all((want[:, None, :] == 0) | (sol.config == want[:, None, :]),
                                                           axis=-1)
    score = np.minimum(sol.margin, 0.5 * sol.wrist_sine)
    if near_a is not None:
        score = -np.max(np.abs(sol.joints - near_a[:, None, :]), axis=-1)
    # rank: valid & matching first, then not singular, then the score; ties to the first start value
    key = np.where(valid & match, 0.0, np.inf) + np.where(singular, 1.0, 0.0) * 1e6 - score
    key = np.where(np.isnan(key), np.inf, key)
    chosen = np.argmin(key, axis=1)
    rows = np.arange(n)
    joints = np.full((n, g), np.nan)
    cfg = np.zeros((n, 3), dtype=int)
    status: list[IKStatus] = []
    reason: list[str] = []
    lim = model.joint_limits
    for i in range(n):
        k = chosen[i]
        if valid[i, k] and match[i, k]:
            joints[i], cfg[i] = sol.joints[i, k], sol.config[i, k]
            if singular[i, k]:
                status.append(IKStatus.NEAR_SINGULARITY)
                reason.append(f"near a singularity (wrist sine {sol.wrist_sine[i, k]:.4f}, σ ratio "
                              f"{sol.condition_ratio[i, k]:.1e}): small pose changes need large joint motions")
            else:
                status.append(IKStatus.OK)
                reason.append("")
            continue
        if np.any(valid[i]):
            found = ", ".join(f"({ArmConfig.from_array(c)})" for c in sol.config[i][valid[i]])
            status.append(IKStatus.CONFIGURATION)
            reason.append(f"configuration ({ArmConfig.from_array(want[i])}) not reachable inside the limits "
                          f"(reachable: {found})" if want is not None else "no solution")
            continue
        if np.any(sol.reached[i]):
            r = sol.reached[i]
            # the limit violated least among the reached solutions
            viol = np.maximum(lim[:, 0] - sol.joints[i][r], 0.0) + np.maximum(sol.joints[i][r] - lim[:, 1], 0.0)
            best = int(np.argmin(viol.sum(axis=1)))
            j = int(np.argmax(viol[best]))
            qv = sol.joints[i][r][best, j]
            unit, s = ("°", 180.0 / np.pi) if model.joint_types[j] == "revolute" else (" mm", 1.0)
            status.append(IKStatus.OUTSIDE_LIMITS)
            reason.append(f"outside the joint limits: every solution needs joint {j + 1} at {qv * s:.2f}{unit}, "
                          f"limits [{lim[j, 0] * s:.2f}, {lim[j, 1] * s:.2f}]{unit}")
            continue
        if not np.all(np.isfinite(Tt[i])):
            status.append(IKStatus.UNREACHABLE)
            reason.append("the target contains NaN or infinity")
            continue
        k = int(np.argmin(sol.position_error_mm[i] + ROTATION_WEIGHT_MM * sol.angle_error_rad[i]))
        status.append(IKStatus.UNREACHABLE)
        reason.append(f"out of reach: the closest pose found misses by {sol.position_error_mm[i, k]:.3f} mm and "
                      f"{np.degrees(sol.angle_error_rad[i, k]) * 3600:.1f}″")
    c = chosen
    return IKResult(joints, tuple(status), tuple(reason), cfg, sol.position_error_mm[rows, c],
                    sol.angle_error_rad[rows, c], sol.margin[rows, c], sol.wrist_sine[rows, c],
                    np.sum(valid, axis=1), sol)
