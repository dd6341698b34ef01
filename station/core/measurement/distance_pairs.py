"""Which pairs of measured points become distances (distance objective, chapter eq. 7.4–7.6).

n points carry at most 3n − 6 independent pieces of distance information (brief §10), yet all
pairs are n(n−1)/2: 499 500 for 1000 poses. Three strategies:

* ``all`` — every pair. Fine for tens of points; the pairs share points and are correlated,
  which the uncertainty accounts for (:func:`station.core.measurement.uncertainty.distance_sandwich`).
* ``independent`` — as in the chapter: every point is used in exactly one pair (n // 2
  distances, no shared point, so the distances are independent). Wastes information.
* ``cap`` — every point is paired with the same number of partners (a random, seeded
  circulant design) so that at most ``cap`` pairs are formed; all pairs when fewer exist.
  The default, with ``DEFAULT_CAP``: linear in the number of points, and far more pairs than
  the 3n − 6 pieces of information, so almost nothing is lost.
"""

from __future__ import annotations

import numpy as np

from station.errors import ConfigError

STRATEGIES = ("all", "independent", "cap")
DEFAULT_STRATEGY = "cap"
DEFAULT_CAP = 20_000
# "all" refuses more pairs than this (memory: a Jacobian row per pair).
MAX_ALL_PAIRS = 2_000_000


def make_pairs(n: int, strategy: str = DEFAULT_STRATEGY, cap: int | None = None, seed: int = 0,
               groups: np.ndarray | None = None) -> np.ndarray:
    """``(k, 2)`` index pairs (i < j) of ``n`` points.

    ``groups``: optional ``(n,)`` labels; pairs within one group (e.g. the same measuring point
    of a calibration body) are left out.
    """
    if n < 2:
        raise ConfigError("a distance needs at least two measured points")
    if strategy not in STRATEGIES:
        raise ConfigError(f"unknown pair strategy {strategy!r}; use one of {', '.join(STRATEGIES)}")
    rng = np.random.default_rng(seed)
    total = n * (n - 1) // 2
    cap = DEFAULT_CAP if cap is None else int(cap)
    if cap < 1:
        raise ConfigError("the pair cap must be a positive number of distances")
    if strategy == "all" or (strategy == "cap" and total <= cap):
        if total > MAX_ALL_PAIRS:
            raise ConfigError(
                f"{n} points make {total} pairs, more than {MAX_ALL_PAIRS} fit in memory; use the "
                f"pair strategy 'cap' (default) or 'independent'")
        pairs = np.array(np.triu_indices(n, 1)).T
    elif strategy == "independent":
        perm = rng.permutation(n)
        pairs = perm[: 2 * (n // 2)].reshape(-1, 2)
    else:
        m = max(1, min(cap // n, (n - 1) // 2))
        perm = rng.permutation(n)
        offsets = np.arange(1, m + 1)
        a = np.repeat(np.arange(n), m)
        b = (a + np.tile(offsets, n)) % n
        pairs = np.stack([perm[a], perm[b]], axis=1)
    pairs = np.sort(pairs, axis=1)
    if groups is not None:
        g = np.asarray(groups)
        pairs = pairs[g[pairs[:, 0]] != g[pairs[:, 1]]]
    pairs = np.unique(pairs, axis=0)
    if len(pairs) == 0:
        raise ConfigError("no pair of different measured points is left to form a distance")
    return pairs


def distances(points: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """``(..., k)`` distances between ``points`` ``(..., n, 3)`` of every pair."""
    p = np.asarray(points, dtype=float)
    return np.linalg.norm(p[..., pairs[:, 0], :] - p[..., pairs[:, 1], :], axis=-1)


def shares_points(pairs: np.ndarray) -> bool:
    """Whether some point takes part in more than one pair (the distances are then correlated)."""
    flat = np.asarray(pairs).reshape(-1)
    return bool(len(np.unique(flat)) < flat.size)


#: two nominal points closer than this [mm] are the same point: a distance between them has no
#: direction (its Jacobian is undefined) and carries nothing of the geometry; far below any
#: instrument's noise, far above round-off
COINCIDENT_MM = 1e-6


def coincident_pairs(points: np.ndarray, pairs: np.ndarray, tol_mm: float = COINCIDENT_MM) -> np.ndarray:
    """``(k,)`` mask of the pairs whose two ``points`` ``(n, 3)`` coincide (a repeated pose, or
    joints that differ by a full turn, such as q6 and q6 + 360°)."""
    return distances(points, np.asarray(pairs, dtype=int)) < tol_mm
