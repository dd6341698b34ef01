"""The simulated probe head: channels from the head's geometry, certificate scale, and the
per-probe faults (a stuck plunger, debris on a tip for N touches or for good)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from drivers.probe_head import ProbeHead
from simulators.probe_head_sim import ProbeHeadPhysics, ProbeHeadServer
from station.core.kinematics.transforms import pose_to_matrix
from station.core.probe.geometry import default_probe_head, readings_from_pose
from station.io.head_file import load_head

SEVEN = Path(__file__).resolve().parents[2] / "examples" / "heads" / "seven-probe.toml"


def poses(geom, n, seed=0):
    rng = np.random.default_rng(seed)
    return [geom.nominal_contact_pose() @ pose_to_matrix(np.r_[rng.uniform(-0.5, 0.5, 3), rng.uniform(-0.003, 0.003, 3)])
            for _ in range(n)]


def test_channels_follow_the_head_and_undo_the_certificate_scale():
    geom = load_head(SEVEN).geometry
    phys = ProbeHeadPhysics(geometry=geom, noise_mm=0.0, quantum_mm=0.0)
    assert phys.n_channels == 8  # channels 2 … 8 used, channel 1 free
    M = poses(geom, 1)[0]
    ch = phys.channel_values(M)
    assert ch.shape == (8,) and np.isnan(ch[0])
    exact = readings_from_pose(geom, M)
    # what the unit shows times the probe's scale is the displacement
    np.testing.assert_allclose(ch[geom.probe_channels - 1] * geom.probe_scales, exact, atol=1e-12)
    assert ch[3] != pytest.approx(exact[2], abs=1e-7)  # P3 (channel 4) carries a scale of 1.0004


def test_default_head_serves_its_six_probes_in_order():
    phys = ProbeHeadPhysics(noise_mm=0.0, quantum_mm=0.0)
    M = poses(default_probe_head(), 1)[0]
    np.testing.assert_array_equal(phys.channel_values(M), phys.readings(M))


def test_a_stuck_probe_freezes_at_its_next_reading_and_others_move_on():
    geom = load_head(SEVEN).geometry
    phys = ProbeHeadPhysics(geometry=geom, seed=3)
    Ms = poses(geom, 4)
    first = phys.readings(Ms[0])
    phys.inject_stuck("P3")
    frozen = phys.readings(Ms[1])[2]
    later = np.array([phys.readings(M) for M in Ms[2:]])
    assert np.all(later[:, 2] == frozen)
    assert np.all(np.abs(later[:, [0, 1, 3]] - first[[0, 1, 3]]) > 1e-3)  # the others follow the pose
    phys.inject_stuck(1, value_mm=0.25)
    assert phys.readings(Ms[0])[1] == pytest.approx(0.25)
    phys.clear_faults()
    assert phys.readings(Ms[3])[2] != frozen


def test_debris_offsets_one_probe_for_n_touches():
    geom = load_head(SEVEN).geometry
    phys = ProbeHeadPhysics(geometry=geom, noise_mm=0.0, quantum_mm=0.0)
    Ms = poses(geom, 5)
    phys.readings(Ms[0])
    phys.inject_debris("P6", 0.02, touches=2)
    got = []
    for M in Ms[1:]:
        a = phys.readings(M)
        b = phys.readings(M)  # a second snapshot of the same touch
        np.testing.assert_array_equal(a, b)
        got.append(a - readings_from_pose(geom, M))
    got = np.array(got)
    np.testing.assert_allclose(got[:2, 5], 0.02, atol=1e-12)   # touches 1 and 2
    np.testing.assert_allclose(got[2:, 5], 0.0, atol=1e-12)    # gone from touch 3
    np.testing.assert_allclose(np.delete(got, 5, axis=1), 0.0, atol=1e-12)
    phys.inject_debris(0, -0.01)  # for good
    assert all(phys.readings(M)[0] - readings_from_pose(geom, M)[0] == pytest.approx(-0.01) for M in Ms)


def test_fault_arguments_are_checked():
    phys = ProbeHeadPhysics()
    with pytest.raises(ValueError, match="no probe 'P9'"):
        phys.inject_stuck("P9")
    with pytest.raises(ValueError, match="outside 0 … 5"):
        phys.inject_debris(6, 0.01)
    with pytest.raises(ValueError, match="touches"):
        phys.inject_debris(0, 0.01, touches=0)


def test_the_driver_reads_the_seven_probe_heads_channels_over_the_wire():
    geom = load_head(SEVEN).geometry
    phys = ProbeHeadPhysics(geometry=geom, noise_mm=0.0)
    M = poses(geom, 1)[0]
    with ProbeHeadServer(lambda: phys.channel_values(M), pace=False) as srv, ProbeHead(srv.port, timeout=2.0) as head:
        assert head.identify().channels == 8
        snap = head.read_all()
    assert str(snap.status[0].value) != "ok"  # the unused channel
    np.testing.assert_allclose(np.asarray(snap.values_mm)[geom.probe_channels - 1] * geom.probe_scales,
                               readings_from_pose(geom, M), atol=1e-4)  # the protocol's 0.1 µm
