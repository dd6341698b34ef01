"""Robot models: a serial chain of six-parameter transforms (brief §3).

A model is the chain ``R · A1(q1) · … · Ag(qg) · K``:

* ``R`` — the set-up transform: pose of the robot base in the measurement frame (the
  calibration body, or a laser tracker). Not part of the robot; identified with pose data.
* ``A1 … Ag`` — one transform per joint. Each is ``Trans(x,y,z)·Rz(yaw)·Ry(pitch)·Rx(roll)``
  followed by the joint motion about (revolute) or along (prismatic) the *new* local z axis.
* ``K`` — the tool (probe head) transform from the last joint frame to the tool frame.

Every transform has six parameters named ``<transform>.<x|y|z|roll|pitch|yaw>``, so a model
with g joints has ``6 (g + 2)`` parameters, deliberately redundant; :mod:`station.core.identification.identifiability`
chooses the minimal set. Units inside: mm and rad. Robot files (TOML, see ``docs/robot-file.md``)
hold lengths in mm and angles in degrees or radians as their header says.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from station.core.kinematics.transforms import pose_to_matrix
from station.errors import ConfigError

JointType = Literal["revolute", "prismatic"]
PARAM_SUFFIXES = ("x", "y", "z", "roll", "pitch", "yaw")
_LENGTH = (0, 1, 2)
_ANGLE = (3, 4, 5)


@dataclass(frozen=True)
class TransformSpec:
    """One link of the chain. ``joint`` is None for the set-up and tool transforms."""

    name: str
    joint: JointType | None = None


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class RobotModel:
    """A robot description: chain structure, nominal parameters and joint limits.

    ``nominal``: ``(n_params,)`` [mm, rad], ordered transform by transform, each as
    x, y, z, roll, pitch, yaw. ``joint_limits``: ``(n_joints, 2)`` [rad or mm].
    """

    name: str
    transforms: tuple[TransformSpec, ...]
    nominal: np.ndarray
    joint_limits: np.ndarray
    description: str = ""
    # Minimal-set preferences a robot file may carry (see identifiability.choose_parameters).
    prefer: tuple[str, ...] = field(default=())
    #: ``(n_joints,)`` [rad/s or mm/s] the joints' maximum speeds from the robot file (None: not
    #: given); the plan preview estimates the motion time from them
    max_speed: np.ndarray | None = field(default=None, compare=False)
    #: [mm] the data sheet's ISO 9283 pose repeatability RP from the robot file (None: not given);
    #: the noise model adds it to every measured position (station.core.measurement.repeatability)
    repeatability_mm: float | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "nominal", _readonly(self.nominal))
        object.__setattr__(self, "joint_limits", _readonly(self.joint_limits))
        if self.max_speed is not None:
            object.__setattr__(self, "max_speed", _readonly(self.max_speed))
            if self.max_speed.shape != (self.n_joints,) or not np.all(np.isfinite(self.max_speed) & (self.max_speed > 0)):
                raise ConfigError(f"robot {self.name!r}: max_speed must give one finite speed > 0 per joint")
        names = [t.name for t in self.transforms]
        if len(set(names)) != len(names):
            raise ConfigError(f"robot {self.name!r}: transform names must be unique, got {names}")
        if self.transforms[0].joint is not None or self.transforms[-1].joint is not None:
            raise ConfigError(
                f"robot {self.name!r}: the first (set-up) and last (tool) transforms carry no joint"
            )
        if self.nominal.shape != (6 * len(self.transforms),):
            raise ConfigError(
                f"robot {self.name!r}: expected {6 * len(self.transforms)} nominal parameters, "
                f"got {self.nominal.shape}"
            )
        if self.joint_limits.shape != (self.n_joints, 2):
            raise ConfigError(
                f"robot {self.name!r}: joint_limits must have shape ({self.n_joints}, 2)"
            )
        for j, (lo, hi) in enumerate(self.joint_limits):
            if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):  # NaN fails every comparison
                raise ConfigError(f"robot {self.name!r}: joint {j + 1} has limits [{lo}, {hi}]; every joint "
                                  f"limit must be finite with lower < upper")

    # --- structure -----------------------------------------------------------------------
    @property
    def transform_names(self) -> tuple[str, ...]:
        return tuple(t.name for t in self.transforms)

    @property
    def joint_transforms(self) -> tuple[int, ...]:
        """Indices into ``transforms`` of the transforms that carry a joint."""
        return tuple(i for i, t in enumerate(self.transforms) if t.joint is not None)

    @functools.cached_property  # derived from frozen fields; the hot loops read it often
    def joint_types(self) -> tuple[JointType, ...]:
        return tuple(t.joint for t in self.transforms if t.joint is not None)

    @property
    def is_scara(self) -> bool:
        """The joint sequence of a SCARA (R R P R): closed-form IK and an x, y, z, yaw table apply."""
        return self.joint_types == ("revolute", "revolute", "prismatic", "revolute")

    @functools.cached_property  # derived from frozen fields; the hot loops read it often
    def n_joints(self) -> int:
        return sum(t.joint is not None for t in self.transforms)

    @functools.cached_property  # derived from the read-only nominal; every nominal forward chain reads it
    def nominal_matrices(self) -> np.ndarray:
        """``(n_transforms, 4, 4)`` each transform's constant part at the nominal parameters (read-only)."""
        m = pose_to_matrix(self.nominal.reshape(len(self.transforms), 6))
        m.setflags(write=False)
        return m

    @property
    def n_params(self) -> int:
        return 6 * len(self.transforms)

    @functools.cached_property  # derived from frozen fields; the hot loops read it often
    def param_names(self) -> tuple[str, ...]:
        return tuple(f"{t.name}.{s}" for t in self.transforms for s in PARAM_SUFFIXES)

    @property
    def n_revolute(self) -> int:
        return sum(j == "revolute" for j in self.joint_types)

    @property
    def n_prismatic(self) -> int:
        return sum(j == "prismatic" for j in self.joint_types)

    @property
    def minimal_param_count(self) -> int:
        """4R + 2P + 6 (Everett/Hollerbach; chapter eq. 7.1)."""
        return 4 * self.n_revolute + 2 * self.n_prismatic + 6

    def is_angle(self) -> np.ndarray:
        """``(n_params,)`` bool: which parameters are angles (rad) rather than lengths (mm)."""
        return np.tile(np.array([False, False, False, True, True, True]), len(self.transforms))

    def param_index(self, name: str) -> int:
        try:
            return self.param_names.index(name)
        except ValueError:
            raise ConfigError(
                f"unknown parameter {name!r} for robot {self.name!r}; parameters are named "
                f"<transform>.<x|y|z|roll|pitch|yaw> with transforms {', '.join(self.transform_names)}"
            ) from None

    def param_indices(self, names) -> list[int]:
        return [self.param_index(n) for n in names]

    def setup_slice(self) -> slice:
        return slice(0, 6)

    def with_params(self, params: np.ndarray) -> "RobotModel":
        """The same robot with ``params`` as its nominal parameters (e.g. an identified model)."""
        params = np.asarray(params, dtype=float)
        if params.shape != self.nominal.shape:
            raise ValueError(f"expected {self.nominal.shape} parameters, got {params.shape}")
        return dataclasses.replace(self, nominal=params)  # every other field kept, a new one too

    def with_setup(self, pose: np.ndarray) -> "RobotModel":
        """The same robot with the set-up transform R set to ``pose`` (6,) [mm, rad]."""
        p = np.array(self.nominal)
        p[0:6] = pose
        return self.with_params(p)

    def with_tool(self, pose: np.ndarray) -> "RobotModel":
        """The same robot with the tool transform K (the last one) set to ``pose`` (6,) [mm, rad]
        (a probe-head file's frame in the flange)."""
        p = np.array(self.nominal)
        p[-6:] = pose
        return self.with_params(p)

    def check_joints(self, joints: np.ndarray) -> np.ndarray:
        """Validate a joint array ``(n, g)``: shape, finiteness. Returns it as float."""
        q = np.asarray(joints, dtype=float)
        if q.ndim == 1:
            q = q[None, :]
        if q.shape[-1] != self.n_joints:
            raise ConfigError(
                f"robot {self.name!r} has {self.n_joints} joints but joint values have "
                f"{q.shape[-1]} columns"
            )
        if not np.all(np.isfinite(q)):
            raise ConfigError("joint values contain NaN or infinity; remove or repair those rows")
        return q

    def within_limits(self, joints: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """``(n,)`` bool: joints inside the limits, shrunk by ``margin`` on each side."""
        q = np.asarray(joints, dtype=float)
        lo, hi = self.joint_limits[:, 0] + margin, self.joint_limits[:, 1] - margin
        return np.all((q >= lo) & (q <= hi), axis=-1)


# --- robot files ------------------------------------------------------------------------------

#: an arm that repeats worse than 10 mm is no robot a station calibrates (and likely a unit mistake)
MAX_REPEATABILITY_MM = 10.0


def check_repeatability(value: object, source: str) -> float | None:
    """The robot file's ``repeatability_mm`` as a float [mm] (None where absent), or a
    :class:`ConfigError` with its fix."""
    if value is None:
        return None
    hint = ("give the data sheet's ISO 9283 pose repeatability RP in mm, e.g. repeatability_mm = 0.02 for "
            "±0.02 mm, or leave the key out when the data sheet states none")
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(f"{source}: [robot].repeatability_mm must be a finite number, got {value!r}; {hint}")
    if not 0.0 < float(value) <= MAX_REPEATABILITY_MM:
        raise ConfigError(f"{source}: [robot].repeatability_mm = {value!r} is outside (0, {MAX_REPEATABILITY_MM:g}] mm; {hint}")
    return float(value)


def robot_from_dict(data: dict, source: str = "<dict>") -> RobotModel:
    """Build a model from the parsed TOML of a robot file (format in docs/robot-file.md)."""
    head = data.get("robot") if isinstance(data, dict) else None
    if not isinstance(head, dict) or not isinstance(head.get("name"), str) or not head["name"]:
        raise ConfigError(f"{source}: missing [robot] table with a 'name' (a string)")
    name = head["name"]
    angle_unit = head.get("angle_unit", "deg")
    length_unit = head.get("length_unit", "mm")
    if angle_unit not in ("deg", "rad"):
        raise ConfigError(f"{source}: [robot].angle_unit must be 'deg' or 'rad', got {angle_unit!r}")
    if length_unit not in ("mm", "m"):
        raise ConfigError(f"{source}: [robot].length_unit must be 'mm' or 'm', got {length_unit!r}")
    a_scale = math.pi / 180.0 if angle_unit == "deg" else 1.0
    l_scale = 1000.0 if length_unit == "m" else 1.0
    entries = data.get("transform")
    if not isinstance(entries, list) or len(entries) < 3:
        raise ConfigError(
            f"{source}: need [[transform]] entries: a set-up transform, one per joint, and a tool"
        )
    specs, params, limits = [], [], []
    speeds: list[float] = []
    for k, e in enumerate(entries):
        if not isinstance(e, dict) or not isinstance(e.get("name"), str) or not e["name"]:
            raise ConfigError(f"{source}: [[transform]] number {k + 1} needs a 'name' (a string)")
        unknown = set(e) - {"name", "joint", "limits", "max_speed", *PARAM_SUFFIXES}
        if unknown:
            raise ConfigError(
                f"{source}: transform {e['name']!r} has unknown keys {sorted(unknown)}; "
                f"allowed: name, joint, limits, max_speed, {', '.join(PARAM_SUFFIXES)}"
            )
        joint = e.get("joint")
        if joint not in (None, "revolute", "prismatic"):
            raise ConfigError(
                f"{source}: transform {e['name']!r}: joint must be 'revolute' or 'prismatic'"
            )
        vals = []
        for i, s in enumerate(PARAM_SUFFIXES):
            v = e.get(s, 0.0)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ConfigError(f"{source}: {e['name']}.{s} must be a finite number, got {v!r}")
            vals.append(float(v) * (a_scale if i in _ANGLE else l_scale))
        specs.append(TransformSpec(str(e["name"]), joint))
        params.extend(vals)
        if joint is not None:
            lim = e.get("limits")
            if not (isinstance(lim, list) and len(lim) == 2):
                raise ConfigError(
                    f"{source}: joint transform {e['name']!r} needs limits = [lower, upper]"
                )
            if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in lim):
                raise ConfigError(
                    f"{source}: transform {e['name']!r}: limits must be two finite numbers [lower, upper]")
            if not float(lim[0]) < float(lim[1]):
                raise ConfigError(
                    f"{source}: transform {e['name']!r}: limits {lim!r} must be [lower, upper] with lower < upper")
            scale = a_scale if joint == "revolute" else l_scale
            limits.append([float(lim[0]) * scale, float(lim[1]) * scale])
            v = e.get("max_speed")
            if v is not None:
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
                    raise ConfigError(f"{source}: transform {e['name']!r}: max_speed must be a finite number > 0 "
                                      f"({'deg/s' if joint == 'revolute' and angle_unit == 'deg' else 'per s'}), got {v!r}")
                speeds.append(float(v) * scale)
        elif "limits" in e or "max_speed" in e:
            raise ConfigError(f"{source}: transform {e['name']!r} has no joint, so no limits or max_speed")
    prefer_raw = head.get("prefer", [])
    if not (isinstance(prefer_raw, list) and all(isinstance(p, str) for p in prefer_raw)):
        raise ConfigError(f"{source}: [robot].prefer must be a list of parameter names such as [\"K.x\"], "
                          f"got {prefer_raw!r}")
    prefer = tuple(prefer_raw)
    model = RobotModel(name, tuple(specs), np.array(params), np.array(limits).reshape(-1, 2),
                       str(head.get("description", "")), prefer,
                       repeatability_mm=check_repeatability(head.get("repeatability_mm"), source))
    if speeds:
        if len(speeds) != model.n_joints:
            raise ConfigError(f"{source}: max_speed is given for {len(speeds)} of {model.n_joints} joints; give it "
                              f"for every joint or for none")
        model = dataclasses.replace(model, max_speed=np.array(speeds))
    for p in prefer:
        model.param_index(p)
    return model


def robot_to_toml(model: RobotModel, params: np.ndarray | None = None, angle_unit: str = "deg") -> str:
    """Serialise a model (with ``params`` in place of its nominal, if given) to a robot file.

    Values are written with ``repr`` so that reading the file back reproduces the fitted
    parameters to the last bit in radians-mode and to ~1e-16 rad in degree mode.
    """
    import tomli_w

    p = model.nominal if params is None else np.asarray(params, dtype=float)
    a_scale = 180.0 / math.pi if angle_unit == "deg" else 1.0
    doc: dict = {
        "robot": {
            "name": model.name,
            "description": model.description,
            "angle_unit": angle_unit,
            "length_unit": "mm",
        },
        "transform": [],
    }
    if model.prefer:
        doc["robot"]["prefer"] = list(model.prefer)
    if model.repeatability_mm is not None:
        doc["robot"]["repeatability_mm"] = model.repeatability_mm
    li = 0
    for t_i, spec in enumerate(model.transforms):
        e: dict = {"name": spec.name}
        if spec.joint:
            e["joint"] = spec.joint
        for i, s in enumerate(PARAM_SUFFIXES):
            v = float(p[6 * t_i + i])
            e[s] = v * a_scale if i in _ANGLE else v
        if spec.joint:
            scale = a_scale if spec.joint == "revolute" else 1.0
            e["limits"] = [float(model.joint_limits[li, 0]) * scale, float(model.joint_limits[li, 1]) * scale]
            if model.max_speed is not None:
                e["max_speed"] = float(model.max_speed[li]) * scale
            li += 1
        doc["transform"].append(e)
    return tomli_w.dumps(doc)
