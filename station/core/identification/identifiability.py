"""Which parameters a measurement set can identify, and a minimal set to identify (brief §3).

Procedure (chapter §2.4/§3.3):

1. Assemble the σ-normalised identification Jacobian at the measurement poses.
2. Columns with no effect at all are recognised as zero **before** any column scaling; scaling
   first would blow round-off up into fake rank.
3. Scale the remaining columns to unit norm (mm and rad become comparable) and take the SVD:
   the rank, singular values and condition number follow.
4. Choose a minimal set greedily in preference order (the set-up R first, then the user's
   ``prefer`` list, then the order of a column-pivoted QR), adding a parameter only if it raises
   the rank. ``fix`` and ``exclude`` keep parameters out (held at their current values).
   R first: every direction the measurements cannot tell from where the body stands (for a
   SCARA the height along axis 1, the rotation about it, the base origin) goes to the set-up,
   and the robot's own parameters stay at the robot file's there, so the robot's base frame is
   the robot's, never where the body happened to stand (issue 36). Holding R (``fix``) hands
   those directions to the robot: the way to measure them with a known set-up.
5. Every parameter left out is named with the chosen parameters it merges with.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import scipy.linalg

from station.core.blas_threads import single_blas_thread
from station.core.identification.fit_kernel import DataEvaluator
from station.core.kinematics.model import RobotModel
from station.core.kinematics.transforms import pose_to_matrix
from station.core.measurement.measurements import MeasurementSet, residuals_and_jacobian
from station.errors import ConfigError

# Relative size below which a singular value counts as zero. Structural dependencies give
# ~1e-15; the weakest genuinely identifiable SR 800 parameter sits near 1e-4.
RANK_RTOL = 1e-9
ZERO_COLUMN_RTOL = 1e-10
GS_RTOL = 1e-7


@dataclass(frozen=True)
class Dependency:
    """A parameter left out and the chosen parameters its effect merges into."""

    name: str
    merges_with: tuple[tuple[str, float], ...]  # (chosen name, coefficient)

    def describe(self) -> str:
        if not self.merges_with:
            return f"{self.name}: no effect on these measurements"
        terms = " ".join(f"{c:+.4g}·{n}" for n, c in self.merges_with)
        return f"{self.name} ≡ {terms}"


@dataclass(frozen=True)
class Identifiability:
    """Result of :func:`analyze`. Singular values are of the scaled candidate columns.

    ``dependencies`` are worked out when first read (a least-squares fit of every parameter left
    out, which a fit never reads and a report reads once); ``find_dependencies`` computes them."""

    param_names: tuple[str, ...]
    candidates: tuple[str, ...]
    zero_effect: tuple[str, ...]
    held: tuple[str, ...]
    rank: int
    singular_values: np.ndarray
    condition: float
    chosen: tuple[str, ...]
    #: the chosen parameters' unit columns (of the triangular factor): their singular values
    chosen_columns: np.ndarray = field(repr=False, compare=False)
    find_dependencies: Callable[[], tuple[Dependency, ...]] = field(repr=False, compare=False)
    #: transforms at pitch ±90°, the gimbal lock of roll-pitch-yaw (:func:`gimbal_locked`)
    gimbal_locked: tuple[str, ...] = ()
    #: where a transform is locked: the rank of the chain itself (:func:`chain_jacobian`), which
    #: exceeds ``rank`` by the rotations the lock takes from this parametrisation; else None
    chain_rank: int | None = None

    @cached_property
    def chosen_singular_values(self) -> np.ndarray:
        """Singular values of the chosen parameters' unit columns (worked out when first read)."""
        with single_blas_thread():
            return np.linalg.svd(self.chosen_columns, compute_uv=False)

    @property
    def chosen_condition(self) -> float:
        sc = self.chosen_singular_values
        return float(sc[0] / sc[-1]) if len(sc) else float("inf")

    @cached_property
    def dependencies(self) -> tuple[Dependency, ...]:
        """Every parameter left out and what its effect merges into (empty from ``describe=False``)."""
        with single_blas_thread():
            return self.find_dependencies()

    @property
    def lost_to_gimbal_lock(self) -> int:
        """Parameters the chain determines that this parametrisation cannot (0 without a lock)."""
        return 0 if self.chain_rank is None else max(self.chain_rank - self.rank, 0)

    def gimbal_note(self) -> str | None:
        """The line that says a gimbal lock costs rank, naming the transforms and the fix."""
        if not self.lost_to_gimbal_lock:
            return None
        names = ", ".join(self.gimbal_locked)
        return (f"the chain determines {self.chain_rank} parameters, this parametrisation {self.rank}: "
                f"{names} {'sits' if len(self.gimbal_locked) == 1 else 'sit'} at pitch ±90°, where roll and yaw "
                f"turn about one axis (the gimbal lock of roll-pitch-yaw), so {self.lost_to_gimbal_lock} "
                f"rotation(s) cannot be identified. Turn the frame after a joint about its joint axis (imports do), "
                f"or choose a tool frame whose x axis does not lie along the last joint axis (docs/robot-file.md)")

    def chosen_indices(self) -> np.ndarray:
        return np.array([self.param_names.index(n) for n in self.chosen], dtype=int)

    def to_dict(self) -> dict:
        return {
            "rank": self.rank,
            "n_parameters": len(self.param_names),
            "condition": self.condition,
            "chosen": list(self.chosen),
            "chosen_condition": self.chosen_condition,
            "singular_values": self.singular_values.tolist(),
            "zero_effect": list(self.zero_effect),
            "held": list(self.held),
            "dependencies": [d.describe() for d in self.dependencies],
            "gimbal_locked": list(self.gimbal_locked),
            "chain_rank": self.chain_rank,
        }


STRUCTURAL_SNAP_RAD = np.deg2rad(5.0)


def structural_params(model: RobotModel, params) -> np.ndarray:
    """The design geometry behind ``params``: every angle within 5° of a multiple of 90° snapped
    onto it. Identifiability is structural: a small identified tilt turns an exact dependency
    (e.g. R.z ≡ K.z) into a near one that would pass a rank test as round-off-sized rank, so
    the choice of parameters is made at the design point and the fit then starts from ``params``."""
    p = np.array(params, dtype=float)
    ang = _angle_index(p.size)
    pa = p[ang]
    snapped = np.round(pa / (np.pi / 2)) * (np.pi / 2)
    near = np.abs(pa - snapped) < STRUCTURAL_SNAP_RAD
    p[ang[near]] = snapped[near]
    return p


@functools.cache
def _angle_index(n_params: int) -> np.ndarray:
    """The positions of the angles in a parameter vector of ``n_params`` (``RobotModel.is_angle``'s)."""
    out = np.nonzero(np.tile(np.array([False, False, False, True, True, True]), n_params // 6))[0]
    out.flags.writeable = False
    return out


def weighted_jacobian(model: RobotModel, data: MeasurementSet, params=None) -> np.ndarray:
    """The σ-normalised identification Jacobian ``(n_rows, n_params)``."""
    p = model.nominal if params is None else params
    _, J = residuals_and_jacobian(model, data, p)
    return J / data.sigma[:, None]


#: |cos pitch| below this is the gimbal lock (a structural ±90°, as an import or a snap gives it)
GIMBAL_COS = 1e-6


def gimbal_locked(model: RobotModel, params=None) -> tuple[str, ...]:
    """Transforms whose pitch is ±90°: there ``Rz(yaw)·Ry(pitch)·Rx(roll)`` turns roll and yaw
    about the same axis, and the rotation about the third axis has no parameter."""
    p = np.asarray(model.nominal if params is None else params, dtype=float).reshape(-1, 6)
    return tuple(model.transform_names[i] for i in np.nonzero(np.abs(np.cos(p[:, 4])) < GIMBAL_COS)[0])


def chain_jacobian(model: RobotModel, data: MeasurementSet, params=None) -> np.ndarray:
    """σ-normalised Jacobian ``(n_rows, n_params)`` of ``data`` by a small rigid motion of every
    transform in its own frame (along and about the frame's three axes, at its origin) in place of
    its x, y, z, roll, pitch, yaw. The same chain, no Euler angles: nothing locks, so its rank is
    the number of parameters the chain and the measurements determine (4R + 2P + 6 from full poses
    of a generic chain, 4R + 2P + 3 from positions of a point off the last axis; Everett,
    Hollerbach), against which :func:`analyze`'s rank is checked where a transform is locked."""
    p = np.asarray(model.nominal if params is None else params, dtype=float)
    ev = DataEvaluator(model, data)
    T, P = ev.chain.frames(p)
    nt = len(model.transforms)
    F = P[:, :, :3, :3] @ pose_to_matrix(p.reshape(nt, 6))[:, None, :3, :3]  # (nt, n, 3, 3) axes after each
    origin = P[:, :, :3, 3] + np.einsum("tnij,tj->tni", P[:, :, :3, :3], p.reshape(nt, 6)[:, :3])
    lever = T[None, :, :3, 3] - origin  # (nt, n, 3)
    axes = np.swapaxes(F, -1, -2)  # (nt, n, 3 axes, 3 coordinates)
    J = np.zeros((T.shape[0], 6, nt, 6))
    J[:, :3, :, :3] = np.moveaxis(F, 0, 2)
    J[:, :3, :, 3:] = np.moveaxis(np.cross(axes, lever[:, :, None, :]), (0, 3), (2, 1))
    J[:, 3:, :, 3:] = np.moveaxis(F, 0, 2)
    if not data.uses_setup:
        J[:, :, 0] = 0.0
    rows = ev._jacobian_rows(T, J.reshape(T.shape[0], 6, nt * 6))
    return rows / data.sigma[:, None]


def _scaled_rank(J: np.ndarray, held: set[str], names: tuple[str, ...]) -> int:
    """:func:`analyze`'s rank of ``J``: zero columns out before scaling, the rest to unit norm."""
    norms = np.linalg.norm(J, axis=0)
    keep = [i for i in range(J.shape[1]) if norms[i] > ZERO_COLUMN_RTOL * norms.max() and names[i] not in held]
    return _rank(J[:, keep] / norms[keep])[0]


def _rank(Js: np.ndarray) -> tuple[int, np.ndarray]:
    if Js.shape[1] == 0:
        return 0, np.zeros(0)
    s = np.linalg.svd(Js, compute_uv=False)
    return int(np.sum(s > RANK_RTOL * s[0])) if s[0] > 0 else 0, s


def _pivot_order(Js: np.ndarray) -> list[int]:
    """The column order of ``scipy.linalg.qr(Js, pivoting=True)`` (strongest first): LAPACK's geqp3
    called as that function calls it (a workspace query, then the factorisation), without its
    layers and the R it builds, which nothing here reads."""
    if Js.size == 0:
        return list(range(Js.shape[1]))
    lwork = scipy.linalg.lapack.dgeqp3(Js, lwork=-1)[-2][0].real.astype(np.int_)
    _, jpvt, _, _, info = scipy.linalg.lapack.dgeqp3(Js, lwork=lwork)
    if info < 0:
        raise ValueError(f"illegal value in {-info}th argument of internal geqp3")
    return (jpvt - 1).tolist()


def _greedy(J: np.ndarray, norms: np.ndarray, order: list[int], rank: int) -> list[int]:
    """The columns of ``J`` taken in ``order`` when each is taken whose unit column has a part
    outside the span of those taken before it above ``GS_RTOL``, up to ``rank`` of them: the
    incremental, twice re-orthogonalised Gram-Schmidt choice.

    Fast path: one Householder QR of the unit columns in that order gives every column's distance
    from the span of *all* columns before it, taken or not. A column taken by that (distance above
    the limit) is taken by Gram-Schmidt too, whose span is a part of that one; a column left out
    is checked against the span of those taken before it, as Gram-Schmidt measures it. Where every
    check agrees, the choice is Gram-Schmidt's; otherwise Gram-Schmidt itself decides."""
    if order and J.shape[0] >= len(order):
        V = J[:, order] / norms[order]
        # R's diagonal as LAPACK left it (mode "raw": the factor untouched, its transpose; mode "r"
        # would copy out the whole triangle for the diagonal alone)
        d = np.abs(np.diagonal(np.linalg.qr(V, mode="raw")[0])).tolist()
        taken: list[int] = []  # positions in order
        left: list[tuple[int, int]] = []  # (position, number taken before it)
        for k, dk in enumerate(d):
            if dk > GS_RTOL:
                taken.append(k)
            else:
                left.append((k, len(taken)))
            if len(taken) == rank:
                break
        if not left:
            return [order[k] for k in taken]
        if taken:
            Q = np.linalg.qr(V[:, taken])[0]
            W = V[:, [k for k, _ in left]]
            before = np.array([j for _, j in left])
            mask = np.arange(len(taken))[:, None] < before[None, :]  # the basis vectors before each
            for _ in range(2):
                W = W - Q @ ((Q.T @ W) * mask)
            if np.all(np.linalg.norm(W, axis=0) <= GS_RTOL):
                return [order[k] for k in taken]
    chosen: list[int] = []
    basis = np.zeros((J.shape[0], 0))
    for i in order:
        v = J[:, i] / norms[i]
        for _ in range(2):
            v = v - basis @ (basis.T @ v)
        nv = np.linalg.norm(v)
        if nv > GS_RTOL:
            chosen.append(i)
            basis = np.column_stack([basis, v / nv])
        if len(chosen) == rank:
            break
    return chosen


def _setup_first(J: np.ndarray, norms: np.ndarray, chosen: list[int], setup: list[int],
                 preferred: list[int]) -> list[int]:
    """``chosen`` (a basis of the candidates' span) with every set-up column in it: each set-up
    column left out lies in the span, so it can replace one robot column of the basis and the rank
    holds (the exchange lemma). Then what the measurements cannot tell from where the body stands
    is the set-up's, and the robot's own parameters stay at the robot file's in those directions
    (issue 36).

    Which robot column goes: among those whose exchange leaves a set conditioned within 10 × the
    best exchange's, one the user did not prefer, else the one latest in the user's ``prefer``
    list. Why an exchange rather than the set-up first in the greedy order: taken first, the
    set-up's columns make the greedy take whatever robot columns raise the rank next in pivot
    order, and on a SCARA whose body sits to one side that gave a set conditioned 1 755 where the
    exchange's is 20: the identified lengths then scatter by millimetres."""
    rank_of = {c: k for k, c in enumerate(preferred)}
    basis = list(chosen)
    for r in setup:
        if r in basis:
            continue
        trials: list[tuple[float, int]] = []
        for k, c in enumerate(basis):
            if c < 6:
                continue
            trial = basis[:k] + [r] + basis[k + 1:]
            sv = np.linalg.svd(J[:, trial] / norms[trial], compute_uv=False)
            if sv[-1] > GS_RTOL * sv[0]:  # else r does not replace c: the rank would drop
                trials.append((float(sv[0] / sv[-1]), k))
        if not trials:
            continue
        best = min(cond for cond, _ in trials)
        fair = [(basis[k] in rank_of, -rank_of.get(basis[k], 0), cond, k) for cond, k in trials if cond <= 10 * best]
        basis[min(fair)[3]] = r
    return sorted(basis)


def analyze(model: RobotModel, data: MeasurementSet, params=None, prefer=(), fix=(), exclude=(),
            describe: bool = True, jacobian: np.ndarray | None = None) -> Identifiability:
    """Identifiability of ``model``'s parameters from ``data`` at ``params`` (default nominal).

    ``describe=False``: no dependencies (``dependencies`` is empty); with ``describe`` they are
    named when first read (a least-squares fit per parameter left out, which a fit does not need),
    as are the chosen set's singular values. ``jacobian``: :func:`weighted_jacobian` at ``params``
    when the caller already has it.
    """
    names = model.param_names
    for n in (*prefer, *fix, *exclude):
        model.param_index(n)
    J = weighted_jacobian(model, data, params) if jacobian is None else jacobian
    # Everything below depends only on inner products of columns, which the triangular factor
    # R of J = QR keeps: work on the (P, P) factor instead of the (rows, P) Jacobian.
    if J.shape[0] > J.shape[1]:
        J = np.linalg.qr(J, mode="r")  # type: ignore[assignment]  # numpy stubs: mode="r" returns R alone, not QRResult
    norms = np.linalg.norm(J, axis=0)
    zero = norms <= ZERO_COLUMN_RTOL * norms.max()
    held = set(fix) | set(exclude)
    is_zero = zero.tolist()
    cand = [i for i in range(len(names)) if not is_zero[i] and names[i] not in held]
    Js = J[:, cand] / norms[cand]
    rank, s = _rank(Js)
    # Preference order: the user's list, then column-pivoted QR order (strongest first); then every
    # set-up parameter left out is exchanged into the set (issue 36): a list that puts the head
    # first (K.z ≡ R.z on a SCARA) would otherwise let the robot take the set-up's error into its
    # base frame.
    piv = _pivot_order(Js)
    index = {n: i for i, n in enumerate(names)}
    in_cand = set(cand)
    pref = [index[n] for n in prefer if index[n] in in_cand]
    taken = set(pref)
    order = pref + [cand[k] for k in piv if cand[k] not in taken]
    chosen = _setup_first(J, norms, _greedy(J, norms, order, rank), [i for i in range(6) if i in in_cand],
                          pref)
    nc = norms[chosen]
    Jc = J[:, chosen] / nc
    cond = float(s[0] / s[rank - 1]) if rank else float("inf")
    locked = gimbal_locked(model, params)
    chain_rank = None
    if locked:  # the count of the chain, to tell what the lock costs (only then: it is one more chain)
        chain_rank = _scaled_rank(chain_jacobian(model, data, params), held, names)
    return Identifiability(
        param_names=names,
        candidates=tuple(names[i] for i in cand),
        zero_effect=tuple(names[i] for i, z in enumerate(is_zero) if z),
        held=tuple(n for n in names if n in held),
        rank=rank,
        singular_values=s,
        condition=cond,
        chosen=tuple(names[i] for i in chosen),
        chosen_columns=Jc,
        # a partial, not a closure: the result pickles like any other
        find_dependencies=functools.partial(_dependencies, names, J, norms, zero, chosen, Jc, nc) if describe else tuple,
        gimbal_locked=locked,
        chain_rank=chain_rank,
    )


def _dependencies(names: tuple[str, ...], J: np.ndarray, norms: np.ndarray, zero: np.ndarray, chosen: list[int],
                  Jc: np.ndarray, nc: np.ndarray) -> tuple[Dependency, ...]:
    """:func:`analyze`'s dependencies: every parameter left out, with the chosen ones its unit
    column is a combination of (none: no effect)."""
    deps = []
    chosen_set = set(chosen)
    left = [i for i in range(len(names)) if i not in chosen_set and not zero[i]]
    fits: dict[int, tuple[float, list[float], list[bool]]] = {}
    if left:
        # Solve on unit columns (mm and rad comparable), all left-out columns at once; report
        # in physical units (column l: cs · norms[i] / norms[chosen], term k kept where |cs_k| > 1e-6).
        B = J[:, left] / norms[left]
        CS = np.linalg.lstsq(Jc, B, rcond=None)[0]
        resid = np.linalg.norm(Jc @ CS - B, axis=0).tolist()
        coef = (CS * norms[left] / nc[:, None]).T.tolist()
        keep = (np.abs(CS) > 1e-6).T.tolist()
        fits = {i: (resid[k], coef[k], keep[k]) for k, i in enumerate(left)}
    chosen_names = [names[c] for c in chosen]
    for i in range(len(names)):
        if i in chosen_set:
            continue
        if zero[i]:
            deps.append(Dependency(names[i], ()))
            continue
        res_i, coef_i, keep_i = fits[i]
        if res_i > 1e-6:
            continue  # held by the user but not a combination: identifiable, just not chosen
        deps.append(Dependency(names[i], tuple((n, c) for n, c, k in zip(chosen_names, coef_i, keep_i) if k)))
    return tuple(deps)


def require_parameters(model: RobotModel, names) -> list[int]:
    """Indices of explicitly chosen parameters, with a clear error for unknown names."""
    if not names:
        raise ConfigError("an empty parameter set cannot be identified")
    return model.param_indices(names)
