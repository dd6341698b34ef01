"""The map between a controller's joint values and the model's: sign, zero offset, coupling.

Controllers do not all count joints the way a kinematic model does. A joint may turn the other
way (sign), have its zero elsewhere (offset), or be measured against another joint: a Fanuc
reports J3 against the horizontal, so the model's elbow angle is J3 minus J2 (coupling). Each
joint j of the model is

    q_model[j] = sign[j] * q_controller[j] + offset[j] + k[j] * q_controller[other[j]]

a linear map ``q_model = q_controller · Mᵀ + offset``. Joint values coming from a controller
(data files) go through :meth:`JointMap.to_model`; values going back to a controller (a
compensated program) through :meth:`JointMap.to_controller`. Arrays are ``(n, n_joints)``
[rad or mm], each joint in its own unit; ``k`` is this joint's unit per the other joint's.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from station.errors import ConfigError


@dataclass(frozen=True)
class JointMap:
    """``sign`` (g,) of ±1, ``offset`` (g,) [rad or mm], ``other`` (g,) the index of the
    joint each joint is coupled to (None: no coupling), ``k`` (g,) the coupling factors
    (0 where there is none), ``names`` the joints' names for messages."""

    sign: tuple[float, ...]
    offset: tuple[float, ...]
    other: tuple[int | None, ...]
    k: tuple[float, ...]
    names: tuple[str, ...]

    def __post_init__(self) -> None:
        g = len(self.names)
        if not (len(self.sign) == len(self.offset) == len(self.other) == len(self.k) == g):
            raise ConfigError(f"joint map: sign, offset, coupling and names must have one entry per joint ({g})")
        for j, name in enumerate(self.names):
            if self.sign[j] not in (1.0, -1.0):
                raise ConfigError(f"joint map: {name}: sign must be 1 or -1, got {self.sign[j]!r}")
            if not np.isfinite(self.offset[j]):
                raise ConfigError(f"joint map: {name}: offset must be a finite number, got {self.offset[j]!r}")
            o = self.other[j]
            if o is None:
                if self.k[j] != 0.0:
                    raise ConfigError(f"joint map: {name}: a coupling factor needs the joint it couples to")
                continue
            if not 0 <= o < g or o == j:
                raise ConfigError(f"joint map: {name}: it can be coupled only to another of the joints "
                                  f"{', '.join(self.names)}")
            if not np.isfinite(self.k[j]):
                raise ConfigError(f"joint map: {name}: coupling factor k must be a finite number, got {self.k[j]!r}")
        self._refuse_loop()

    def _refuse_loop(self) -> None:
        """Couplings must not go round in a circle (J2 on J3 and J3 on J2): the controller's
        values would then have no unique inverse to write back."""
        for start in range(len(self.names)):
            seen = [start]
            here = self.other[start]
            while here is not None:
                if here in seen:
                    loop = " -> ".join(self.names[i] for i in [*seen[seen.index(here):], here])
                    raise ConfigError(f"joint map: the couplings go round in a loop ({loop}); couple each joint "
                                      "to a joint that is not, in turn, coupled back to it")
                seen.append(here)
                here = self.other[here]

    @classmethod
    def identity(cls, names: Sequence[str]) -> "JointMap":
        g = len(names)
        return cls((1.0,) * g, (0.0,) * g, (None,) * g, (0.0,) * g, tuple(names))

    @property
    def n_joints(self) -> int:
        return len(self.names)

    @property
    def is_identity(self) -> bool:
        return (all(s == 1.0 for s in self.sign) and all(o == 0.0 for o in self.offset)
                and all(o is None for o in self.other))

    @property
    def matrix(self) -> np.ndarray:
        """``(g, g)`` the linear part M: ``q_model = M · q_controller + offset``."""
        M = np.diag(np.asarray(self.sign, dtype=float))
        for j, o in enumerate(self.other):
            if o is not None:
                M[j, o] += self.k[j]
        return M

    def close_to(self, other: "JointMap", tol: float = 1e-12) -> bool:
        """The same map to round-off (a map read back from a written file in other units)."""
        return (self.n_joints == other.n_joints and self.other == other.other and self.sign == other.sign
                and np.allclose(self.offset, other.offset, rtol=0, atol=tol)
                and np.allclose(self.k, other.k, rtol=0, atol=tol))

    def _check(self, q: np.ndarray) -> np.ndarray:
        q = np.asarray(q, dtype=float)
        if q.shape[-1] != self.n_joints:
            raise ConfigError(f"joint map of {self.n_joints} joints, but joint values have {q.shape[-1]} columns")
        return q

    def to_model(self, q_controller: np.ndarray) -> np.ndarray:
        """``(n, g)`` model joints from the controller's ``(n, g)`` (or ``(g,)``)."""
        q = self._check(q_controller)
        return q @ self.matrix.T + np.asarray(self.offset)

    def to_controller(self, q_model: np.ndarray) -> np.ndarray:
        """``(n, g)`` controller joints from the model's: the exact inverse of :meth:`to_model`."""
        q = self._check(q_model)
        return (q - np.asarray(self.offset)) @ np.linalg.inv(self.matrix).T

    def delta_to_controller(self, dq_model: np.ndarray) -> np.ndarray:
        """A change of the model's joints (e.g. joint-zero offsets) as the controller's change:
        the linear part only, the zero offset cancels."""
        dq = self._check(dq_model)
        return dq @ np.linalg.inv(self.matrix).T

    def describe(self) -> list[str]:
        """One line per joint that the map changes, e.g. ``A3 = +q3 - 90 + 1·q2``
        (offsets in the model's unit: rad or mm)."""
        out = []
        for j, name in enumerate(self.names):
            if self.sign[j] == 1.0 and self.offset[j] == 0.0 and self.other[j] is None:
                continue
            text = f"{name} = {'+' if self.sign[j] > 0 else '-'}q{j + 1}"
            if self.offset[j]:
                text += f" {'+' if self.offset[j] > 0 else '-'} {abs(self.offset[j]):.9g}"
            o = self.other[j]
            if o is not None:
                text += f" {'+' if self.k[j] >= 0 else '-'} {abs(self.k[j]):.9g}·q{o + 1}"
            out.append(text)
        return out


def joint_map_from_file_units(names: Sequence[str], types: Sequence[str], entries: dict[int, dict],
                              angle_scale: float, length_scale: float) -> JointMap:
    """A map from a robot file's values: ``entries`` by joint index, each with optional
    ``sign``, ``offset`` (the joint's file unit), ``other`` (joint index) and ``k`` (this
    joint's file unit per the other joint's); ``*_scale``: file unit → rad / mm."""
    g = len(names)
    scale = [angle_scale if t == "revolute" else length_scale for t in types]
    sign, offset, other, k = [1.0] * g, [0.0] * g, [None] * g, [0.0] * g
    for j, e in entries.items():
        sign[j] = float(e.get("sign", 1.0))
        offset[j] = float(e.get("offset", 0.0)) * scale[j]
        o = e.get("other")
        if o is None:
            if "k" in e:
                raise ConfigError(f"joint map: {names[j]}: k is given without the joint it couples to "
                                  f"(coupled_to)")
            continue
        if "k" not in e:
            raise ConfigError(f"joint map: {names[j]}: coupled to {names[o] if 0 <= o < g else o}, but no "
                              f"factor k is given (e.g. k = -1 for a Fanuc J3 measured against J2)")
        other[j] = o
        k[j] = float(e["k"]) * scale[j] / scale[o] if 0 <= o < g else float(e["k"])
    return JointMap(tuple(sign), tuple(offset), tuple(other), tuple(k), tuple(names))
