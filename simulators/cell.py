"""Physics of the simulated calibration cell (brief §3, §8): the true robot, the calibration
body, and what the probe head touches.

* :class:`CellTruth` - the robot model (nominal, with the configured nominal set-up R) and the
  TRUE parameter vector = nominal + seeded errors, plus repeatability, reversal error (backlash)
  and encoder resolution. This is the oracle the station's identification is judged against.
* :class:`CalibrationBody` - cubes on a plate at several heights; each top corner is a measuring
  point with an MPKS frame (origin at the top corner, cube locally in x>=0, y>=0, z<=0). Nominal
  geometry (the CMM report the station gets) and true geometry (nominal + manufacturing
  deviations of a few µm / arc seconds).
* :class:`SimulatedCell` - the actual joint state: commanded joints -> encoder reading and
  physical joints (backlash by approach direction, repeatability noise), the true probe-head
  pose world<-MKKS = R_true A(q_phys) K_true, the measuring point in capture range and the true
  contact pose ``M_true = inv(world<-MKKS) I_true_j`` fed to the probe-head physics.
  Optionally a thermal model (``simulators/thermal.py``) drifts the true parameters along a
  warm-up curve over the robot's simulated motion time (:attr:`SimulatedCell.motion_time_s`).

"World" is the calibration-body frame KKS. Units mm and rad.
"""

from __future__ import annotations

import dataclasses
import threading
from dataclasses import dataclass
from typing import Any

import numpy as np

from simulators.truth_kinematics import inverse, matrix_pose, pose_matrix, rotation_angle, true_forward
from station.core.kinematics.model import RobotModel
from station.core.units import ARCMIN, ARCSEC
from station.io.robot.files import load_robot

__all__ = ["CellTruth", "CubeSpec", "CalibrationBody", "SimulatedCell", "DEFAULT_SETUP",
           "ARCMIN", "ARCSEC"]

#: Nominal pose of the robot base in the calibration-body frame: the robot stands 450 mm in -x
#: (every corner well inside the 800 mm reach, away from the stretched-arm singularity)
#: of the body origin and 170 mm below the plate surface, so every cube corner, with 20 mm of
#: retract clearance above it, lies within the stroke of
#: the SR 800's prismatic axis.
DEFAULT_SETUP = np.array([-450.0, 0.0, -170.0, 0.0, 0.0, 0.0])


def _readonly(a) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.flags.writeable = False
    return a


@dataclass(frozen=True, eq=False)
class CellTruth:
    """The true robot of the cell.

    ``model``: the station's robot model whose nominal R is the configured nominal set-up.
    ``params``: true parameters (n_params,). ``repeatability`` (g,) σ of the physical joint
    position per move; ``backlash`` (g,) full reversal error per joint; ``encoder_resolution``
    (g,). Units rad or mm per joint type.
    """

    model: RobotModel
    params: np.ndarray
    repeatability: np.ndarray
    backlash: np.ndarray
    encoder_resolution: np.ndarray
    seed: int = 0
    #: simulators.joint_errors.JointErrors of the arm (None: none): the oracle must know them too
    joint_errors: Any = None

    def __post_init__(self) -> None:
        for name in ("params", "repeatability", "backlash", "encoder_resolution"):
            object.__setattr__(self, name, _readonly(getattr(self, name)))
        if self.params.shape != self.model.nominal.shape:
            raise ValueError(f"params must have shape {self.model.nominal.shape}")
        for name in ("repeatability", "backlash", "encoder_resolution"):
            if getattr(self, name).shape != (self.model.n_joints,):
                raise ValueError(f"{name} must have one entry per joint ({self.model.n_joints})")

    @property
    def errors(self) -> np.ndarray:
        """True minus nominal parameters."""
        return self.params - self.model.nominal

    @property
    def setup(self) -> np.ndarray:
        """True pose (6,) of the robot base in the calibration-body frame."""
        return self.params[self.model.setup_slice()].copy()

    @classmethod
    def generate(cls, model: RobotModel | None = None, seed: int = 0,
                 setup_nominal: np.ndarray = DEFAULT_SETUP,
                 length_sigma_mm: float = 0.04, angle_sigma_rad: float = 2.5 * ARCMIN,
                 setup_sigma_mm: float = 1.5, setup_yaw_sigma_rad: float = np.deg2rad(0.2),
                 setup_tilt_sigma_rad: float = np.deg2rad(0.03),
                 repeatability_mm: float = 0.005, backlash_mm: float = 0.1,
                 prismatic_backlash_mm: float = 0.02, lever_mm: float = 450.0,
                 encoder_resolution: float = 1e-6, offset_sigma_rad: float | None = None,
                 tilt_sigma_rad: float | None = None,
                 joint_backlash_mm: np.ndarray | None = None,
                 setup_error: np.ndarray | None = None) -> "CellTruth":
        """Seeded true robot: lengths of A1..Ag and K with σ ``length_sigma_mm``, angles with
        σ ``angle_sigma_rad``; set-up R = ``setup_nominal`` + σ ``setup_sigma_mm`` in x, y, z,
        ``setup_yaw_sigma_rad`` in yaw and ``setup_tilt_sigma_rad`` in roll, pitch.
        Revolute joints get backlash ``backlash_mm/lever_mm`` rad and repeatability
        ``repeatability_mm/lever_mm`` rad; prismatic joints the mm values directly.
        ``offset_sigma_rad`` (the revolute joints' encoder offsets: the yaw of their transforms)
        and ``tilt_sigma_rad`` (roll and pitch of every transform) replace ``angle_sigma_rad``
        where given; ``joint_backlash_mm`` (g,) gives each joint its own backlash (revolute at
        ``lever_mm``). ``setup_error`` (6,) [mm, rad]: the set-up's error planted exactly instead
        of the draw (which is still made, so that a seed's robot is the same either way). The same
        seed draws the same numbers whatever the σ."""
        model = load_robot("sr800") if model is None else model
        model = model.with_setup(np.asarray(setup_nominal, dtype=float))
        rng = np.random.default_rng(seed)
        n_t = model.n_params // 6
        err = np.zeros((n_t, 6))
        err[1:, :3] = rng.normal(0.0, length_sigma_mm, (n_t - 1, 3))
        ang = np.full((n_t, 3), float(angle_sigma_rad))
        if tilt_sigma_rad is not None:
            ang[:, :2] = tilt_sigma_rad
        if offset_sigma_rad is not None:
            for t, kind in zip(model.joint_transforms, model.joint_types):
                if kind == "revolute":
                    ang[t, 2] = offset_sigma_rad
        err[1:, 3:] = rng.normal(0.0, 1.0, (n_t - 1, 3)) * ang[1:]
        err[0, :3] = rng.normal(0.0, setup_sigma_mm, 3)
        err[0, 3:5] = rng.normal(0.0, setup_tilt_sigma_rad, 2)
        err[0, 5] = rng.normal(0.0, setup_yaw_sigma_rad)
        if setup_error is not None:
            err[0] = np.asarray(setup_error, dtype=float).reshape(6)
        rev = np.array([t == "revolute" for t in model.joint_types])
        rep = np.where(rev, repeatability_mm / lever_mm, repeatability_mm)
        bl = np.where(rev, backlash_mm / lever_mm, prismatic_backlash_mm)
        if joint_backlash_mm is not None:
            jb = np.asarray(joint_backlash_mm, dtype=float)
            if jb.shape != (model.n_joints,):
                raise ValueError(f"joint_backlash_mm needs one value per joint ({model.n_joints}), got {jb.shape}")
            bl = np.where(rev, jb / lever_mm, jb)
        enc = np.full(model.n_joints, float(encoder_resolution))
        return cls(model, model.nominal + err.ravel(), rep, bl, enc, seed)

    def head_pose(self, joints_physical: np.ndarray, delta: np.ndarray | None = None) -> np.ndarray:
        """True world<-MKKS ``(n, 4, 4)`` for physical joints ``(n, g)``; ``delta``: a drift
        (n_params,) added to the true parameters (the thermal state)."""
        q = np.atleast_2d(np.asarray(joints_physical, dtype=float))
        p = self.params if delta is None else self.params + delta
        # the truth's own kinematics, not the station's: a fault in station.core cannot hide
        return true_forward([t.joint for t in self.model.transforms], p, q, setup=True)

    def with_change(self, delta: np.ndarray) -> "CellTruth":
        """The same robot after a step change ``delta`` (n_params,) of its parameters."""
        return CellTruth(self.model, self.params + np.asarray(delta, dtype=float), self.repeatability,
                         self.backlash, self.encoder_resolution, self.seed, self.joint_errors)

    def joint_delta(self, q_commanded: np.ndarray) -> np.ndarray:
        """``(n, g)`` [rad] how far the joints stand from the commanded ``(n, g)`` beyond the
        backlash: the joint errors (compliance, gear harmonics; zeros without)."""
        q = np.atleast_2d(np.asarray(q_commanded, dtype=float))
        if self.joint_errors is None:
            return np.zeros(q.shape)
        return self.joint_errors.delta(self.model, self.params, q)


@dataclass(frozen=True)
class CubeSpec:
    """A cube on the plate: centre (x, y) [mm] in KKS, pillar height [mm] (plate at z=0), yaw."""

    x: float
    y: float
    pillar: float
    yaw: float


DEFAULT_CUBES = (
    CubeSpec(0.0, -300.0, 0.0, np.deg2rad(10.0)),
    CubeSpec(150.0, -150.0, 60.0, np.deg2rad(-20.0)),
    CubeSpec(0.0, 0.0, 120.0, np.deg2rad(30.0)),
    CubeSpec(150.0, 150.0, 0.0, np.deg2rad(5.0)),
    CubeSpec(0.0, 300.0, 60.0, np.deg2rad(-15.0)),
    CubeSpec(-150.0, 0.0, 0.0, np.deg2rad(45.0)),
)


@dataclass(frozen=True, eq=False)
class CalibrationBody:
    """Measuring points of the body: ``nominal (n,4,4)`` KKS<-MPKS from the CMM report,
    ``true (n,4,4)`` as manufactured, ``labels`` ``(cube, corner)`` per point."""

    cube_edge_mm: float
    cubes: tuple[CubeSpec, ...]
    nominal: np.ndarray
    true: np.ndarray
    labels: tuple[tuple[int, int], ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "nominal", _readonly(self.nominal))
        object.__setattr__(self, "true", _readonly(self.true))

    @property
    def n_points(self) -> int:
        return len(self.labels)

    @staticmethod
    def corner_frames(cube: CubeSpec, edge: float) -> np.ndarray:
        """(4,4,4) KKS<-MPKS of the four top corners, each rotated 90° about z from the last."""
        E = edge
        c, s = np.cos(cube.yaw), np.sin(cube.yaw)
        Rz = np.array([[c, -s], [s, c]])
        origin = np.array([cube.x, cube.y]) - Rz @ np.array([E / 2, E / 2])
        top = cube.pillar + E
        out = []
        for k, (cx, cy) in enumerate(((0, 0), (E, 0), (E, E), (0, E))):
            p = origin + Rz @ np.array([cx, cy])
            out.append(pose_matrix(np.array([p[0], p[1], top, 0.0, 0.0, cube.yaw + k * np.pi / 2])))
        return np.stack(out)

    @classmethod
    def generate(cls, cubes: tuple[CubeSpec, ...] = DEFAULT_CUBES, cube_edge_mm: float = 40.0,
                 corners: tuple[int, ...] = (0, 1, 2, 3), seed: int = 0,
                 position_sigma_mm: float = 0.002, angle_sigma_rad: float = 3 * ARCSEC) -> "CalibrationBody":
        rng = np.random.default_rng(seed + 7919)
        corner_list: list[np.ndarray] = []
        labels: list[tuple[int, int]] = []
        for i, cube in enumerate(cubes):
            frames = cls.corner_frames(cube, cube_edge_mm)
            for k in corners:
                corner_list.append(frames[k])
                labels.append((i, k))
        nominal = np.stack(corner_list)
        dev = np.concatenate([rng.normal(0, position_sigma_mm, (len(labels), 3)),
                              rng.normal(0, angle_sigma_rad, (len(labels), 3))], axis=1)
        true = nominal @ pose_matrix(dev)
        return cls(cube_edge_mm, tuple(cubes), nominal, true, tuple(labels))

    @classmethod
    def from_frames(cls, nominal: np.ndarray, cube_edge_mm: float, sigma: np.ndarray,
                    seed: int = 0) -> "CalibrationBody":
        """A body known only by its measuring points (a user's CMM report): ``nominal (n,4,4)``
        KKS<-MPKS, ``sigma (n,2)`` (or ``(2,)`` for every point) the σ of each point's true
        deviation: position [mm], angle [rad]. No cube layout: ``cubes`` is empty and point
        ``i`` is labelled ``(i, 0)``. The deviations are drawn as :meth:`generate` draws them."""
        nominal = np.asarray(nominal, dtype=float)
        if nominal.ndim != 3 or nominal.shape[1:] != (4, 4) or len(nominal) == 0:
            raise ValueError(f"nominal must be (n, 4, 4) with n >= 1, got {nominal.shape}")
        n = len(nominal)
        s = np.broadcast_to(np.asarray(sigma, dtype=float), (n, 2))
        if not np.all(np.isfinite(s)) or np.any(s < 0):
            raise ValueError("sigma must be finite and >= 0")
        rng = np.random.default_rng(seed + 7919)
        dev = np.concatenate([rng.normal(0.0, 1.0, (n, 3)) * s[:, :1],
                              rng.normal(0.0, 1.0, (n, 3)) * s[:, 1:]], axis=1)
        true = nominal @ pose_matrix(dev)
        return cls(float(cube_edge_mm), (), nominal, true, tuple((i, 0) for i in range(n)))


class SimulatedCell:
    """The cell's state. Thread-safe: the controller simulator moves it, the probe-head
    simulator reads it."""

    def __init__(self, truth: CellTruth | None = None, body: CalibrationBody | None = None,
                 probe=None, seed: int = 0, capture_mm: float = 8.0,
                 capture_angle_rad: float = np.deg2rad(10.0), probe_noise_mm: float = 0.0005,
                 initial_joints: np.ndarray | None = None, thermal=None, step: np.ndarray | None = None,
                 joint_errors=None):
        """``thermal``: a :class:`simulators.thermal.ThermalModel` (None: no drift with
        warm-up); ``step``: a step change (n_params,) of the true parameters (a re-mastered axis,
        a bumped tool) applied before the first move."""
        from simulators.probe_head_sim import ProbeHeadPhysics  # the other simulator's physics

        self.truth = truth if truth is not None else CellTruth.generate(seed=seed)
        if step is not None and np.any(np.asarray(step) != 0):
            self.truth = self.truth.with_change(step)
        self.thermal = thermal if thermal is not None and thermal.active else None
        # joints that bend under gravity and err once per turn (simulators/joint_errors.py; issue 30)
        self.joint_errors = joint_errors if joint_errors is not None and joint_errors.active else None
        if self.joint_errors is not None:  # the truth the oracle is built from carries them
            self.truth = dataclasses.replace(self.truth, joint_errors=self.joint_errors)
        self._motion_time_s = 0.0
        self.body = body if body is not None else CalibrationBody.generate(seed=seed)
        self.probe = probe if probe is not None else ProbeHeadPhysics(noise_mm=probe_noise_mm, seed=seed + 1)
        self.capture_mm = float(capture_mm)
        self.capture_angle_rad = float(capture_angle_rad)
        self._rng = np.random.default_rng(seed + 104729)
        self._lock = threading.Lock()
        g = self.truth.model.n_joints
        if initial_joints is None:
            lim = self.truth.model.joint_limits
            initial_joints = np.clip(np.zeros(g), lim[:, 0], lim[:, 1])
            if self.truth.model.joint_types[2:3] == ("prismatic",):
                initial_joints[2] = 0.5 * (lim[2, 0] + lim[2, 1])
        self._cmd = np.array(initial_joints, dtype=float)
        self._prev_cmd = self._cmd.copy()
        self._reads_since_move = 0
        self._direction = np.ones(g)
        self._phys = self._physical(self._cmd, noise=False)
        # what the head must see at a contact: pose of MPKS in MKKS at mid-stroke
        self._M_nominal = np.asarray(self.probe.geometry.nominal_contact_pose(), dtype=float)

    # ----------------------------------------------------------------- joints
    def _keyed_rng(self, salt: int) -> np.random.Generator:
        """Noise keyed to the last two commands (the path into the pose) rather than to a
        stream position: a station that crashes and repeats a measurement's command sequence
        gets the same physics, so a resumed run reproduces an uninterrupted one exactly."""
        key = np.round(np.concatenate([self._prev_cmd, self._cmd]) * 1e9).astype(np.int64)
        words = [int(k) & 0xFFFFFFFFFFFFFFFF for k in key]
        return np.random.default_rng(np.random.SeedSequence([self.truth.seed, salt, *words]))

    def _physical(self, cmd: np.ndarray, noise: bool = True) -> np.ndarray:
        t = self.truth
        q = cmd - 0.5 * t.backlash * self._direction
        if self.joint_errors is not None:
            q = q + self.joint_errors.delta(t.model, t.params, cmd)[0]
        if noise:
            q = q + self._keyed_rng(0).normal(0.0, 1.0, q.shape) * t.repeatability
        return q

    def command_joints(self, q_cmd: np.ndarray) -> np.ndarray:
        """The servo reaches ``q_cmd`` (motor side); the physical joints lag by half the
        backlash against the direction of approach plus repeatability noise. Returns the
        encoder reading (``q_cmd`` quantised to the encoder resolution)."""
        q_cmd = np.asarray(q_cmd, dtype=float).ravel()
        with self._lock:
            if self.thermal is not None:
                from simulators.thermal import motion_seconds

                self._motion_time_s += motion_seconds(self.truth.model, q_cmd - self._cmd)
            d = np.sign(q_cmd - self._cmd)
            self._direction = np.where(d != 0, d, self._direction)
            self._prev_cmd = self._cmd
            self._cmd = q_cmd.copy()
            self._reads_since_move = 0
            self._phys = self._physical(q_cmd)
            return self._encoder()

    def _encoder(self) -> np.ndarray:
        res = self.truth.encoder_resolution
        return np.round(self._cmd / res) * res

    def encoder_joints(self) -> np.ndarray:
        with self._lock:
            return self._encoder()

    @property
    def joints_commanded(self) -> np.ndarray:
        with self._lock:
            return self._cmd.copy()

    @property
    def joints_physical(self) -> np.ndarray:
        with self._lock:
            return self._phys.copy()

    @property
    def approach_direction(self) -> np.ndarray:
        with self._lock:
            return self._direction.copy()

    # ----------------------------------------------------------------- thermal state
    @property
    def motion_time_s(self) -> float:
        """Seconds of simulated motion since the cell started cold (counted with a thermal model)."""
        with self._lock:
            return self._motion_time_s

    def set_motion_time(self, seconds: float) -> None:
        """Set the thermal clock (a test: ``inf`` is the steady state, 0 cold)."""
        with self._lock:
            self._motion_time_s = float(seconds)

    def drift(self) -> np.ndarray:
        """The thermal change (n_params,) of the true parameters now."""
        if self.thermal is None:
            return np.zeros(self.truth.model.n_params)
        return self.thermal.delta(self.motion_time_s)

    # ----------------------------------------------------------------- head and contact
    def head_pose(self) -> np.ndarray:
        """True world(KKS)<-MKKS (4,4) at the current physical joints (with the thermal drift)."""
        return self.truth.head_pose(self.joints_physical, None if self.thermal is None else self.drift())[0]

    def contact_for_head_pose(self, T_head: np.ndarray) -> tuple[int | None, np.ndarray | None]:
        """Measuring point in capture range of a head at ``T_head`` and the true contact pose
        ``M_true`` (pose of MPKS in MKKS), or ``(None, None)``."""
        T_head = np.asarray(T_head, dtype=float)
        expected = T_head @ self._M_nominal  # where the head expects MPKS (world)
        frames = self.body.true
        d = np.linalg.norm(frames[:, :3, 3] - expected[:3, 3], axis=1)
        j = int(np.argmin(d))
        if d[j] > self.capture_mm:
            return None, None
        rel = expected[:3, :3].T @ frames[j, :3, :3]
        if rotation_angle(rel) > self.capture_angle_rad:
            return None, None
        return j, inverse(T_head) @ frames[j]

    def contact(self) -> tuple[int | None, np.ndarray | None]:
        return self.contact_for_head_pose(self.head_pose())

    def probe_values(self) -> np.ndarray:
        """The probe unit's channel values [mm] with +inf/-inf/NaN markers at the current state,
        in channel order (the head's channel numbers; a 3-2-1 head: its six probes in order)."""
        _j, M = self.contact()
        with self._lock:
            self._reads_since_move += 1
            rng = self._keyed_rng(self._reads_since_move)
        by_channel = getattr(self.probe, "channel_values", None)
        return by_channel(M, rng=rng) if by_channel is not None else self.probe.readings(M, rng=rng)

    def nominal_head_target(self, point: int, nominal_body: bool = True) -> np.ndarray:
        """World<-MKKS that puts the head at mid-stroke on measuring point ``point``."""
        frames = self.body.nominal if nominal_body else self.body.true
        return frames[point] @ inverse(self._M_nominal)

    def describe(self) -> dict:
        """Summary of the truth for reports (parameters as names -> error)."""
        m = self.truth.model
        return {"seed": self.truth.seed, "setup_true": matrix_pose(pose_matrix(self.truth.setup)).tolist(),
                "errors": dict(zip(m.param_names, self.truth.errors.tolist())),
                "n_points": self.body.n_points}
