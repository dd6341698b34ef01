"""The simulated controller's screen (simulators/collision_check.py, issue 40): the lower bound of
every pair's distance, computed for all pairs of a batch of samples at once (bounding spheres, a
segment boxed in the other part's frame where they come within NEAR_MM), never exceeds the
distance fcl measures, so the conservative advancement of check_move skips nothing it should see."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from station.cell.config.cell_config import load_config

pytest.importorskip("fcl")

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


@pytest.mark.parametrize("cell", ["puma560_obstacles", "scara600_column"])
def test_the_screen_is_a_lower_bound_of_every_pairs_distance(cell):
    import fcl

    from simulators.collision_check import NEAR_MM, CellCollision

    cfg = load_config(EXAMPLES / cell / "cell.toml")
    cc = CellCollision.from_config(cfg)
    lim = np.asarray(cfg.soft_limits, dtype=float)
    Q = np.random.default_rng(40).uniform(lim[:, 0], lim[:, 1], (40, len(lim)))
    W = cc._placed(Q)
    gaps = cc._gaps(W)
    pairs = [(cc.moving[i], cc.moving[j], i, j) for i, j in cc._mm]
    pairs += [(cc.moving[i], cc.fixed[j], i, len(cc.moving) + j) for i, j in cc._mf]
    assert gaps.shape == (len(Q), len(pairs))
    near = 0
    for k in range(len(Q)):
        for p, (a, b, i, j) in enumerate(pairs):
            oa, ob = cc._objs[i], cc._objs[j]
            oa.setTransform(cc._tf(W[k, i]))
            ob.setTransform(cc._tf(W[k, j] if j < len(cc.moving) else b.local))
            d = fcl.distance(oa, ob, fcl.DistanceRequest(), fcl.DistanceResult())
            if d > 0:  # overlapping pairs: fcl's distance is no distance; the bound must be <= 0 there
                assert gaps[k, p] <= d + 1e-6, (a.name, b.name, gaps[k, p], d)
            else:
                assert gaps[k, p] <= 1e-6, (a.name, b.name, gaps[k, p])
            near += bool(0 < d < NEAR_MM)
    assert near > 0  # the draws reached pairs within NEAR_MM, where the box bound is used
