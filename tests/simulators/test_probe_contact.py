"""The simulated head's contact physics (simulators/probe_contact.py) against the station's solver
(station/core/probe/geometry.py): two derivations of docs/probe-head.md, held to each other on
random poses of every head in the examples, and to the document's own statements. A slip in one
(a face normal, the tip radius's side, a frame) fails here instead of cancelling end to end."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from simulators.probe_contact import touch_readings
from station.core.kinematics.transforms import pose_to_matrix
from station.core.probe.geometry import default_probe_head, readings_from_pose, solve_pose
from station.io.head_file import load_head

HEADS = sorted((Path(__file__).resolve().parents[2] / "examples" / "heads").glob("*.toml"))


def _sim(geom, M):
    return touch_readings(geom.mount_points, geom.directions, geom.faces, geom.tip_radii, geom.strokes,
                          geom.cube_edge_mm, M)


def _heads():
    return [default_probe_head(), default_probe_head(cube_edge_mm=30.0, tip_radius_mm=1.5)] + [
        load_head(str(h)).geometry for h in HEADS]


def test_the_reference_head_reads_zero_at_its_nominal_touch():
    # default_probe_head: every tip-sphere centre one radius off its face at the nominal pose
    # (station/core/probe/geometry.py), so every plunger reads 0 there
    g = default_probe_head()
    assert np.allclose(_sim(g, g.nominal_contact_pose()), 0.0, atol=1e-12)
    # moving the cube 0.3 mm down (−z of MKKS, the head's z pointing away from the cube's top)
    # takes the top face away from the three top probes by 0.3 mm: they extend 0.3 mm further
    M = g.nominal_contact_pose().copy()
    M[:3, 3] += M[:3, :3] @ np.array([0.0, 0.0, -0.3])
    r = _sim(g, M)
    assert np.allclose(r[g.faces == 0], 0.3, atol=1e-12) and np.allclose(r[g.faces != 0], 0.0, atol=1e-12)


@pytest.mark.parametrize("k", range(4))
def test_the_simulator_and_the_station_agree_on_random_poses(k):
    geoms = _heads()
    geom = geoms[k % len(geoms)]
    rng = np.random.default_rng(100 + k)
    M0 = geom.nominal_contact_pose()
    agree = finite = 0
    for _ in range(400):
        scale = rng.choice([0.2, 2.0, 8.0])  # near the touch, across the strokes, off the faces
        d = pose_to_matrix(np.concatenate([rng.normal(0, scale, 3), rng.normal(0, 0.02 * scale, 3)]))
        M = M0 @ d
        a, b = _sim(geom, M), readings_from_pose(geom, M)
        same_kind = (np.isnan(a) == np.isnan(b)) & (np.isposinf(a) == np.isposinf(b)) & (np.isneginf(a) == np.isneginf(b))
        # a tangent point on a face's edge may fall either side of it by rounding: only exact ties differ
        assert same_kind.sum() >= len(a) - 1, (a, b)
        ok = same_kind & np.isfinite(a)
        assert np.allclose(a[ok], b[ok], rtol=0, atol=1e-9)
        agree += int(same_kind.all())
        finite += int(np.isfinite(a).all())
    assert agree >= 398 and finite >= 50  # the draws reach both the valid and the invalid cases


def test_the_station_solves_the_pose_the_simulator_touched():
    g = default_probe_head()
    rng = np.random.default_rng(7)
    for _ in range(50):
        M = g.nominal_contact_pose() @ pose_to_matrix(np.concatenate([rng.normal(0, 0.5, 3), rng.normal(0, 0.005, 3)]))
        sol = solve_pose(g, _sim(g, M), noise_mm=1e-6)
        assert np.allclose(sol.M, M, atol=1e-9)
