"""ISO 9283 figures and verification summaries on hand-computed examples (station.core.accuracy.iso9283)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from station.core.accuracy.iso9283 import iso9283_pose
from station.core.units import ARCSEC
from station.errors import ConfigError


def test_ap_and_rp_two_cycles():
    s = iso9283_pose([0.0, 0.0, 0.0], [[1.0, 0.0, 0.0], [3.0, 0.0, 0.0]])
    np.testing.assert_allclose(s.barycentre, [2.0, 0.0, 0.0])
    assert (s.AP, s.APx, s.APy, s.APz) == pytest.approx((2.0, 2.0, 0.0, 0.0))
    # l = [1, 1]: l̄ = 1, S_l = 0 -> RP = 1
    assert (s.l_mean, s.S_l, s.RP) == pytest.approx((1.0, 0.0, 1.0))
    assert s.APa is None and s.n_cycles == 2


def test_ap_and_rp_three_cycles():
    s = iso9283_pose([0.0, 0.0, 1.0], [[0.0, 0.0, 0.0], [0.0, 0.0, 2.0], [0.0, 0.0, 4.0]])
    # barycentre (0, 0, 2): AP = APz = 1; l = [2, 0, 2], l̄ = 4/3,
    # S_l = sqrt(((2/3)² + (4/3)² + (2/3)²) / 2) = sqrt(4/3); RP = 4/3 + 3 sqrt(4/3)
    assert s.AP == pytest.approx(1.0) and s.APz == pytest.approx(1.0)
    assert s.l_mean == pytest.approx(4 / 3)
    assert s.S_l == pytest.approx(math.sqrt(4 / 3))
    assert s.RP == pytest.approx(4 / 3 + 3 * math.sqrt(4 / 3))


def test_ap_three_dimensional():
    s = iso9283_pose([1.0, 2.0, 3.0], [[1.3, 2.4, 3.0], [1.3, 2.4, 3.0]])
    assert s.AP == pytest.approx(0.5) and s.RP == pytest.approx(0.0)
    assert s.as_dict()["AP_um"] == pytest.approx(500.0)


def test_orientation_accuracy_wraps_angles():
    c = [0.0, 0.0, math.pi - 0.001]
    att = [[0.001, 0.0, -math.pi + 0.001], [0.003, 0.0, math.pi - 0.001]]
    s = iso9283_pose([0, 0, 0], [[0, 0, 0], [0, 0, 0]], c, att)
    assert s.APa == pytest.approx(0.002)
    assert s.APc == pytest.approx(0.001)  # differences 0.002 and 0 -> mean 0.001, not ~π
    assert s.RPa == pytest.approx(3 * np.std([0.001, 0.003], ddof=1))
    assert s.RPc == pytest.approx(3 * np.std([0.002, 0.0], ddof=1))
    assert s.as_dict()["APa_arcsec"] == pytest.approx(0.002 / ARCSEC)


@pytest.mark.parametrize("cmd, att, msg", [
    ([0, 0], [[0, 0, 0], [0, 0, 0]], "shape"),
    ([0, 0, 0], [[0, 0, 0]], "at least 2"),
    ([0, 0, 0], [[0, 0], [0, 0]], "shape"),
    ([0, 0, float("nan")], [[0, 0, 0], [0, 0, 0]], "NaN"),
])
def test_iso9283_input_errors(cmd, att, msg):
    with pytest.raises(ConfigError, match=msg):
        iso9283_pose(cmd, att)


def test_orientation_needs_both():
    with pytest.raises(ConfigError, match="both"):
        iso9283_pose([0, 0, 0], [[0, 0, 0], [0, 0, 0]], commanded_orientation=[0, 0, 0])
