"""A model as the kinematics YAML of UR's ROS 2 description (issue 41 §2).

What UR's driver reads (Universal_Robots_ROS2_Driver, ur_calibration: ``calibration_correction``
writes it, ``README.md`` and ``doc/usage.rst``; Universal_Robots_ROS2_Description,
``config/<type>/default_kinematics.yaml``): one mapping ``kinematics`` holding the six frames
``shoulder``, ``upper_arm``, ``forearm``, ``wrist_1``, ``wrist_2``, ``wrist_3``, each
``x, y, z`` [m] and ``roll, pitch, yaw`` [rad], and ``hash``. The description uses each frame as
the ``<origin xyz rpy>`` of joints ``shoulder_pan_joint`` … ``wrist_3_joint``, each about its
``<axis xyz="0 0 1"/>``, from ``base_link_inertia`` (the controller's base frame) to
``wrist_3_link`` (``urdf/ur_macro.xacro``). URDF's origin is ``Trans(xyz)·Rz(yaw)·Ry(pitch)·Rx(roll)``
and the joint turns about z after it: exactly the station's transform ``A_k`` then ``Rz(q_k)``,
so frame k is the model's ``A_k`` (robot base frame), in metres.

What the file cannot hold: the set-up R (the robot's base in the measurement frame; the file
starts at the controller's base) and the tool K (the description fixes ``flange`` and ``tool0``
on ``wrist_3_link`` by constant rotations; a tool is the controller's TCP). Both are named in the
file's header and by the caller on stderr, with K's value, never dropped silently.

The hash (the policy, docs/exports.md): the driver compares ``hash`` with the controller's
``calib_<n>`` (``KinematicsInfo::toHash``: ``std::hash`` of the controller's DH values) and,
when they differ, logs an error and runs on (``ur_client_library``, ``CalibrationChecker``).
This file is not the controller's calibration, so it never carries the controller's hash: that
would silence the one check that tells the ROS side and the controller apart. It carries
``station-sha256-`` and the first 16 hex digits of the SHA-256 of its six frames as written, so
the driver logs the mismatch at every start (expected, and said in the header) and two files
with the same hash hold the same kinematics.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np
import yaml

from station.core.kinematics.model import RobotModel
from station.errors import ConfigError

#: the six frames of UR's kinematics file, shoulder_pan_joint … wrist_3_joint (ur_macro.xacro)
UR_FRAMES = ("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3")
HASH_PREFIX = "station-sha256-"


@dataclass(frozen=True)
class UrCalibration:
    """The YAML text, its hash and what it leaves out."""

    text: str
    hash: str
    notes: tuple[str, ...]


def ur_frames(model: RobotModel, params=None) -> dict[str, dict[str, float]]:
    """The six frames [m, rad] of the model (``params``, default its own) in UR's names; a model
    that is not six revolute joints is refused."""
    if model.joint_types != ("revolute",) * 6:
        raise ConfigError(f"robot {model.name!r} has {model.n_joints} joints ({', '.join(model.joint_types)}): "
                          f"UR's kinematics file holds six revolute joints (shoulder … wrist_3); export this robot "
                          f"with --format toml, or --format urdf into its own URDF")
    p = np.asarray(model.nominal if params is None else params, dtype=float)
    frames = {}
    for name, t in zip(UR_FRAMES, model.joint_transforms):
        x, y, z, roll, pitch, yaw = (float(v) for v in p[6 * t: 6 * t + 6])
        frames[name] = {"x": x / 1000.0, "y": y / 1000.0, "z": z / 1000.0, "roll": roll, "pitch": pitch, "yaw": yaw}
    return frames


def frames_hash(frames: dict[str, dict[str, float]]) -> str:
    """``station-sha256-`` and 16 hex digits of the SHA-256 of the frames' shortest round-trip
    decimals, in UR's order (the file's own numbers: YAML writes floats the same way)."""
    text = ";".join(f"{n}:" + ",".join(repr(frames[n][k]) for k in ("x", "y", "z", "roll", "pitch", "yaw"))
                    for n in UR_FRAMES)
    return HASH_PREFIX + hashlib.sha256(text.encode()).hexdigest()[:16]


def ur_calibration_yaml(model: RobotModel, params=None, not_held: tuple[str, ...] = ()) -> UrCalibration:
    """The kinematics YAML of the model; ``not_held``: what the caller knows the file lacks
    (the set-up, the tool, error terms), written into the header."""
    frames = ur_frames(model, params)
    h = frames_hash(frames)
    header = [f"{model.name}: kinematics for UR's ROS 2 description (kinematics_params_file), written by the "
              "station from its identified model",
              "frames: origin of shoulder_pan_joint ... wrist_3_joint from base_link_inertia (the controller's base),",
              "  x y z [m], roll pitch yaw [rad], URDF origin = Trans(xyz)·Rz(yaw)·Ry(pitch)·Rx(roll), joint about z",
              f"hash: {h} is the SHA-256 of these frames, NOT the controller's calib_ checksum: the driver",
              "  logs that the calibration does not match the robot's at every start; expected (docs/exports.md)"]
    header += [f"NOT HELD: {n}" for n in not_held]
    body = yaml.safe_dump({"kinematics": {**frames, "hash": h}}, sort_keys=False, default_flow_style=False)
    text = "".join(f"# {line}\n" for line in header) + body
    return UrCalibration(text, h, tuple(not_held))


def reload_frames(text: str) -> dict[str, dict[str, float]]:
    """The six frames [m, rad] of a kinematics YAML, read back (a missing frame or key is refused)."""
    data = yaml.safe_load(text)
    try:
        kin = data["kinematics"]
        return {n: {k: float(kin[n][k]) for k in ("x", "y", "z", "roll", "pitch", "yaw")} for n in UR_FRAMES}
    except (KeyError, TypeError, ValueError) as exc:
        raise ConfigError(f"not a UR kinematics file: {exc!r} missing or not a number") from None


def frames_params(model: RobotModel, frames: dict[str, dict[str, float]]) -> np.ndarray:
    """The model's parameters [mm, rad] with its joint transforms from ``frames``, R and K zero:
    what the kinematics file holds, in the station's form (robot base to the wrist_3 frame)."""
    p = np.zeros(model.n_params)
    for name, t in zip(UR_FRAMES, model.joint_transforms):
        f = frames[name]
        p[6 * t: 6 * t + 6] = [f["x"] * 1000.0, f["y"] * 1000.0, f["z"] * 1000.0, f["roll"], f["pitch"], f["yaw"]]
    for t in range(len(model.transforms)):  # fixed transforms between joints (none for a UR) are kept
        if model.transforms[t].joint is None and 0 < t < len(model.transforms) - 1:
            p[6 * t: 6 * t + 6] = model.nominal[6 * t: 6 * t + 6]
    return p
