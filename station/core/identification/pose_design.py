"""Choosing measurement poses for the accuracy where it is wanted (issue 22): greedy I-optimal
design selection and spread-out held-out poses. Pure numerics: arrays in, frozen results out.

I-optimality: the identified parameters' covariance ``C = (Σ J_iᵀ J_i)⁻¹`` (``J_i``: the
noise-weighted Jacobian rows of candidate ``i`` over the minimal parameter set) propagates to the
predicted pose error at a working pose ``k`` as ``G_k C G_kᵀ`` (``G_k``: its pose Jacobian [mm per
parameter unit]). The criterion is the mean predicted variance over the working poses,
``trace(C · W) / m`` with ``W = Σ_k G_kᵀ G_k``, which serves the verification's RMS error
directly; D-optimality (``log det C``) serves the parameters and may leave the working poses'
directions weak. Each greedy step adds the candidate that lowers the criterion most (Woodbury
update of ``C``, every candidate at once).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["IOptimalDesign", "select_i_optimal", "spread_indices"]


@dataclass(frozen=True)
class IOptimalDesign:
    """``chosen``: candidate indices in the order taken; ``mean_variance``: the criterion
    ``trace(C·W)/m`` [mm²] after each addition ``(len(chosen),)``; ``sigma``: predicted σ [mm]
    (root of ``G_k C G_kᵀ``'s trace) at each working pose ``(m,)`` of the final design."""

    chosen: tuple[int, ...]
    mean_variance: np.ndarray
    sigma: np.ndarray


def select_i_optimal(J: np.ndarray, G: np.ndarray, n: int, start: tuple[int, ...] = (),
                     prior: float = 1e-9, enough: float = 0.0) -> IOptimalDesign:
    """Greedy I-optimal subset of ``n`` candidates.

    ``J``: ``(c, r, p)`` noise-weighted Jacobian rows of each candidate (dimensionless per
    parameter unit); ``G``: ``(m, s, p)`` Jacobian of the quantity wanted accurate at each working
    pose [mm per parameter unit]; ``start``: candidates taken first (kept); ``prior``: the
    information ``prior · I`` added so that the first steps are defined (they then fill the
    unobserved directions first). The first ``⌈2p/r⌉`` are taken D-optimally, so that the
    covariance the I-criterion weighs is the data's, not the prior's. ``enough`` [mm²]: the
    stopping rule; no candidate is added once the criterion is at or below it (fewer than ``n``
    then; the greedy order makes this the same as the first poses of the ``n``-pose design)."""
    J = np.asarray(J, dtype=float)
    G = np.asarray(G, dtype=float)
    c, r, p = J.shape
    W = np.einsum("msp,msq->pq", G, G)
    m = max(len(G), 1)
    info = prior * np.eye(p)
    taken: list[int] = []
    for i in start:
        info = info + J[i].T @ J[i]
        taken.append(int(i))
    avail = np.ones(c, dtype=bool)
    avail[taken] = False
    JtJ = np.swapaxes(J, -1, -2) @ J
    # D-optimal until the design determines every parameter twice over: before that C is the
    # prior's and the trace criterion would weigh round-off
    while len(taken) < min(n, c, -(-2 * p // r)):
        sign, val = np.linalg.slogdet(info[None] + JtJ)
        val = np.where((sign > 0) & avail, val, -np.inf)
        best = int(np.argmax(val))
        if not np.isfinite(val[best]):
            break
        info = info + JtJ[best]
        taken.append(best)
        avail[best] = False
    C = np.linalg.inv(info)
    crit: list[float] = []
    eye = np.eye(r)
    while len(taken) < min(n, c) and not (crit and crit[-1] <= enough):
        JC = J @ C                                   # (c, r, p)
        S = eye + JC @ np.swapaxes(J, -1, -2)        # (c, r, r)
        Q = JC @ W @ np.swapaxes(JC, -1, -2)         # (c, r, r)
        drop = np.trace(np.linalg.solve(S, Q), axis1=-2, axis2=-1)
        drop = np.where(avail, drop, -np.inf)
        best = int(np.argmax(drop))
        if not np.isfinite(drop[best]) or drop[best] <= 0.0:  # nothing left that helps
            break
        u = JC[best]
        C = C - u.T @ np.linalg.solve(S[best], u)
        C = 0.5 * (C + C.T)
        taken.append(best)
        avail[best] = False
        crit.append(float(np.trace(C @ W)) / m)
    var = np.einsum("msp,pq,msq->m", G, C, G)
    return IOptimalDesign(tuple(taken), np.array(crit), np.sqrt(np.maximum(var, 0.0)))


def spread_indices(x: np.ndarray, n: int, groups: np.ndarray | None = None, group_gap: float = 1e6) -> tuple[int, ...]:
    """``n`` rows of ``x (c, d)`` spread out by greedy farthest-point sampling (the first: the row
    farthest from the mean), rows of different ``groups (c,)`` counted ``group_gap`` apart so that
    each group is visited before any is visited twice. Returns sorted row indices."""
    x = np.asarray(x, dtype=float)
    c = len(x)
    n = min(int(n), c)
    if n <= 0:
        return ()
    g = np.zeros(c) if groups is None else np.asarray(groups)

    def dist(i: int) -> np.ndarray:
        return np.linalg.norm(x - x[i], axis=1) + np.where(g == g[i], 0.0, group_gap)

    first = int(np.argmax(np.linalg.norm(x - x.mean(axis=0), axis=1)))
    chosen = [first]
    d = dist(first)
    d[first] = -np.inf
    while len(chosen) < n:
        # nearest chosen point per row: a new group is always farther than group_gap
        best = int(np.argmax(d))
        chosen.append(best)
        d = np.minimum(d, dist(best))
        d[chosen] = -np.inf
    return tuple(sorted(chosen))
