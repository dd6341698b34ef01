"""The tool-mount frame after the head comes off (station/core/kinematics/tool_frame.py, chapter §7.2)."""

from __future__ import annotations

import numpy as np
import pytest

from station.core.kinematics.forward import forward
from station.core.kinematics.tool_frame import (
    derive_tool,
    flange_frame,
    head_K,
    nominal_head_in_flange,
    tool_model,
    tool_params,
    tool_transform,
)
from station.core.kinematics.transforms import invert, matrix_to_pose, pose_to_matrix, rot_z
from station.io.robot.files import load_robot

DEG = np.pi / 180


@pytest.fixture(scope="module")
def sr800():
    return load_robot("sr800")


def _identified(model, seed=3):
    rng = np.random.default_rng(seed)
    p = np.array(model.nominal, dtype=float)
    p[6:] += np.tile([0.05, 0.05, 0.05, 1e-3, 1e-3, 1e-3], model.n_params // 6 - 1) * rng.normal(size=model.n_params - 6)
    p[:6] = [-450.0, 3.0, -170.0, 1e-3, -2e-3, 0.01]
    return p


def _joints(model, n=40, seed=5):
    rng = np.random.default_rng(seed)
    lo, hi = model.joint_limits[:, 0], model.joint_limits[:, 1]
    return lo + (hi - lo) * rng.random((n, model.n_joints))


def _tcp(x, y, z, roll=0.0, pitch=0.0, yaw=0.0):
    return pose_to_matrix(np.array([x, y, z, roll * DEG, pitch * DEG, yaw * DEG]))


#: a head file's flange frame that is not the last joint frame: turned over and shifted
H_FILE = _tcp(-4.0, -4.5, -125.0, 180.0, 0.0, 30.0)


def test_a_tool_equal_to_the_head_is_exactly_the_head(sr800):
    p = _identified(sr800)
    for H in (nominal_head_in_flange(sr800), H_FILE):
        K = head_K(sr800, p)
        assert np.array_equal(tool_transform(K, H, H.copy()), K)
        assert np.array_equal(tool_params(sr800, p, H, H.copy()), p)
        kin = derive_tool(sr800, p, H, H.copy())
        assert np.array_equal(kin.params, p)
        assert np.array_equal(forward(sr800, _joints(sr800), kin.params), forward(sr800, _joints(sr800), p))
        assert np.array_equal(kin.nominal.nominal, sr800.nominal)


def test_the_tool_is_the_head_times_the_mount(sr800):
    """FK_tool(q) = FK_head(q) · H⁻¹ · T for any parameters, nominal and identified."""
    p = _identified(sr800)
    T = _tcp(50.0, 0.0, -200.0, 0.0, 0.0, 15.0)
    q = _joints(sr800)
    for H in (nominal_head_in_flange(sr800), H_FILE):
        X = invert(H) @ T
        for params in (sr800.nominal, p):
            got = forward(sr800, q, tool_params(sr800, params, H, T))
            np.testing.assert_allclose(got, forward(sr800, q, params) @ X, atol=1e-9)
        np.testing.assert_allclose(forward(tool_model(sr800, H, T), q), forward(sr800, q) @ X, atol=1e-9)


def _resplit(model, p, dz, dyaw):
    """The same forward kinematics with another split of A4 and K: A4's constant gets
    D = Trans(0, 0, dz)·Rz(dyaw), which commutes with A4's joint rotation, and K gets D⁻¹."""
    q = np.array(p, dtype=float)
    a4 = 6 * model.joint_transforms[-1]
    D = np.eye(4)
    D[:3, :3] = rot_z(dyaw)
    D[2, 3] = dz
    q[a4:a4 + 6] = matrix_to_pose(pose_to_matrix(p[a4:a4 + 6]) @ D)
    q[-6:] = matrix_to_pose(invert(D) @ pose_to_matrix(p[-6:]))
    return q


def test_the_tool_does_not_depend_on_how_the_minimal_set_splits_a4_and_k(sr800):
    p_a = _identified(sr800)
    p_b = _resplit(sr800, p_a, dz=0.8, dyaw=0.01)
    q = _joints(sr800)
    # the two parameter vectors are the same robot for the head ...
    np.testing.assert_allclose(forward(sr800, q, p_b), forward(sr800, q, p_a), atol=1e-9)
    # ... but K differs, and so does the flange frame each derives (K absorbed the split)
    assert np.linalg.norm(p_b[-6:-3] - p_a[-6:-3]) > 0.5
    T = _tcp(50.0, 0.0, -200.0)
    for H in (None, H_FILE):
        ka, kb = derive_tool(sr800, p_a, H, T), derive_tool(sr800, p_b, H, T)
        assert np.linalg.norm(ka.flange_identified[:3, 3] - kb.flange_identified[:3, 3]) > 0.5
        # the tool's TCP is the same wherever the robot goes
        np.testing.assert_allclose(forward(sr800, q, kb.params), forward(sr800, q, ka.params), atol=1e-9)
    # putting the nominal tool on the identified chain in place of K (ignoring what K absorbed)
    # would put the TCP elsewhere: the test above could fail
    naive = np.array(p_a)
    naive[-6:] = matrix_to_pose(tool_transform(head_K(sr800), nominal_head_in_flange(sr800), T))
    miss = forward(sr800, q, naive)[:, :3, 3] - forward(sr800, q, derive_tool(sr800, p_a, None, T).params)[:, :3, 3]
    assert np.max(np.linalg.norm(miss, axis=1)) > 0.05


def test_without_a_head_file_the_nominal_flange_is_the_last_joint_frame(sr800):
    p = np.array(sr800.nominal)
    d = np.array([0.012, -0.007, 0.3])
    p[-6:] = matrix_to_pose(pose_to_matrix(sr800.nominal[-6:]) @ _tcp(*d))
    kin = derive_tool(sr800, p, None, _tcp(0.0, 0.0, -200.0))
    np.testing.assert_allclose(kin.flange_nominal, np.eye(4), atol=1e-12)
    # K = K_nom · Trans(d) (K_nom has no rotation): the flange moved by d, the TCP too
    np.testing.assert_allclose(kin.flange_shift_mm, d, atol=1e-12)
    np.testing.assert_allclose(kin.tcp_shift_mm, d, atol=1e-12)
    assert kin.flange_shift_um == pytest.approx(np.linalg.norm(d) * 1e3)
    assert kin.flange_rotation_arcsec == pytest.approx(0.0, abs=1e-6)
    # the nominal tool: K_nom · K_nom⁻¹ · T = T
    np.testing.assert_allclose(head_K(kin.nominal), _tcp(0.0, 0.0, -200.0), atol=1e-12)


def test_a_tilted_head_frame_turns_the_tool_lever(sr800):
    """A K rotation the identification found moves a long tool's TCP by rotation × lever."""
    p = np.array(sr800.nominal)
    tilt = 1e-3
    p[-6:] = matrix_to_pose(pose_to_matrix(sr800.nominal[-6:]) @ _tcp(0, 0, 0, roll=tilt / DEG))
    kin = derive_tool(sr800, p, None, _tcp(0.0, 0.0, -200.0))
    # flange = K_nom·Rx(tilt)·K_nom⁻¹: rotated by the tilt about an axis through the head origin
    assert kin.flange_rotation_arcsec == pytest.approx(tilt / (DEG / 3600), rel=1e-9)
    # the TCP moves by ω × (lever from the head origin to the TCP), ~72 mm here
    lever = np.array([0.0, 0.0, -200.0]) - sr800.nominal[-6:-3]
    np.testing.assert_allclose(np.linalg.norm(kin.tcp_shift_mm), np.linalg.norm(np.cross([tilt, 0, 0], lever)),
                               rtol=1e-6)
    assert np.linalg.norm(kin.tcp_shift_mm) > 0.07


def test_frames_that_are_not_rigid_are_refused(sr800):
    bad = np.eye(4)
    bad[0, 0] = 2.0
    with pytest.raises(ValueError, match="rigid"):
        flange_frame(head_K(sr800), bad)
    with pytest.raises(ValueError, match="finite"):
        tool_transform(head_K(sr800), np.eye(4), np.full((4, 4), np.nan))
    with pytest.raises(ValueError, match="parameters"):
        derive_tool(sr800, np.zeros(3), None, np.eye(4))
