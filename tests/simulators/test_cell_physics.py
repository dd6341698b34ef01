"""Cell physics and the `python -m simulators` entry point."""

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from simulators.cell import ARCMIN, CalibrationBody, CellTruth, SimulatedCell
from station.core.kinematics.forward import forward, scara_ik

ROOT = Path(__file__).resolve().parents[2]


def test_true_robot_differs_from_nominal_by_configured_magnitudes():
    t = CellTruth.generate(seed=5)
    e = t.errors.reshape(-1, 6)
    lengths, angles = e[1:, :3].ravel(), e[1:, 3:].ravel()
    assert 0.015 < np.std(lengths) < 0.1          # several 10 µm
    assert 1 * ARCMIN < np.std(angles) < 5 * ARCMIN  # several arc minutes
    assert 0.3 < np.linalg.norm(e[0, :3]) < 10.0   # set-up: a few mm
    assert np.all(np.abs(e[0, 3:]) < np.deg2rad(1.0))
    q = np.array([[0.3, 0.8, -100.0, 0.2]])
    d = forward(t.model, q, t.params) [0, :3, 3] - forward(t.model, q)[0, :3, 3]
    assert 0.1 < np.linalg.norm(d) < 10.0
    assert not np.allclose(CellTruth.generate(seed=6).params, t.params)


def test_body_true_geometry_deviates_by_micrometres():
    b = CalibrationBody.generate(seed=1)
    assert b.n_points == 24 and len({z for z in np.round(b.nominal[:, 2, 3])}) == 3
    dp = np.linalg.norm(b.true[:, :3, 3] - b.nominal[:, :3, 3], axis=1)
    assert 0.0005 < np.median(dp) < 0.01
    # corners of one cube: 90° apart, one edge apart
    c0, c1 = b.nominal[0], b.nominal[1]
    assert np.linalg.norm(c1[:3, 3] - c0[:3, 3]) == pytest.approx(40.0)
    assert np.allclose(c0[:3, :3] @ np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]]), c1[:3, :3])


def test_backlash_depends_on_approach_direction():
    truth = CellTruth.generate(seed=2, repeatability_mm=0.0)
    cell = SimulatedCell(truth=truth, seed=2)
    target = np.array([0.2, 0.5, -100.0, 0.3])
    cell.command_joints(target - 0.05)
    enc = cell.command_joints(target)
    from_below = cell.joints_physical
    cell.command_joints(target + 0.05)
    cell.command_joints(target)
    from_above = cell.joints_physical
    np.testing.assert_allclose(from_above - from_below, truth.backlash, rtol=1e-9)
    assert truth.backlash[0] == pytest.approx(0.1 / 450) and truth.backlash[2] == pytest.approx(0.02)
    np.testing.assert_allclose(enc, target, atol=1e-6)  # the encoder does not see the backlash
    # the backlash moves the head by about 0.1 mm
    d = np.linalg.norm(truth.head_pose(from_above)[0, :3, 3] - truth.head_pose(from_below)[0, :3, 3])
    assert 0.05 < d < 0.5


def test_head_at_nominal_contact_pose_reads_in_stroke():
    cell = SimulatedCell(seed=3)
    t = cell.truth
    for j in (0, 9, 23):
        T = cell.nominal_head_target(j, nominal_body=False)
        q = scara_ik(t.model, T[None], elbow=1, params=t.params, setup=True)[0]
        cell.command_joints(q)
        idx, M = cell.contact()
        assert idx == j
        v = cell.probe_values()
        assert v.shape == (6,) and np.all(np.isfinite(v))
        assert np.max(np.abs(v)) < 0.5  # backlash and noise only: far inside the ±5 mm stroke
    # away from every cube: no contact, all channels invalid
    cell.command_joints(np.array([0.0, 0.0, -199.0, 0.0]))
    assert cell.contact() == (None, None)
    assert np.all(cell.probe_values() == np.inf)  # free plungers at their extended stops: over range


def test_python_m_simulators_serves_both_endpoints():
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    p = subprocess.Popen([sys.executable, "-m", "simulators", "--seed", "4"], cwd=ROOT, env=env,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = p.stdout.readline()
        ep = json.loads(line)
        assert ep["seed"] == 4 and ep["probe_head"].startswith("/dev/")
        host, port = ep["controller"].split(":")
        from drivers.controller import ModbusController
        with ModbusController(host, int(port), heartbeat_period=None) as c:
            c.move_joints([0.1, 0.2, -100.0, 0.0]).wait(2.0)
            np.testing.assert_allclose(c.read_joints(), [0.1, 0.2, -100.0, 0.0], atol=1e-5)
        import serial
        with serial.Serial(ep["probe_head"], 9600, timeout=2.0) as s:  # a DL-RS1A at its factory 9600 8N1
            s.write(b"M0\r\n")
            reply = s.read_until(b"\r\n")
        assert reply.startswith(b"M0,") and reply.endswith(b"\r\n")
        p.send_signal(signal.SIGTERM)
        assert p.wait(timeout=60) == 0  # a guard against a hang, not a speed bound (the suite loads 2 cores)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
