"""The simulated cell's judge (issue 42): what the simulator knows of its robot, handed to a run
through ``station.ui.simulated_cell`` (``station.cell.records.judge.RunJudge`` is its Protocol;
the cell never imports this module).

* the true parameters, reversal error, repeatability and joint errors, from which the run builds
  the reference correction it verifies with (the station folds the reversal error into the
  parameters by its own convention);
* :meth:`CellJudge.figures`: the corrected robot judged in its true base frame
  (:func:`simulators.base_frame.base_frame_check`, issue 36 §2) at ``N_TARGETS`` targets drawn
  over the table's region.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from simulators.base_frame import base_frame_check, targets_in_box
from simulators.cell import CellTruth
from station.core.kinematics.model import RobotModel

#: targets of the base-frame check per run (the benchmark's 400 halve its RMS's scatter once more)
N_TARGETS = 200
#: salt of the base-frame targets' draws (apart from the cell's other draws of the same seed)
_TARGET_SALT = 0xBA5E


def joint_delta_of(robot: Any) -> Callable[[np.ndarray], np.ndarray] | None:
    """The simulated robot's joint errors ``Δq(q)`` at the commanded joints, or None without them
    (a simulated arm with ``joint_errors = "none"``, or no robot)."""
    if robot is None or getattr(robot, "joint_errors", None) is None:
        return None
    fn: Callable[[np.ndarray], np.ndarray] = robot.joint_delta
    return fn


class CellJudge:
    """The judge of a simulated cell whose robot is ``robot`` (see the module)."""

    def __init__(self, robot: CellTruth) -> None:
        self.robot = robot
        self.params = robot.params
        self.backlash = robot.backlash
        self.repeatability = robot.repeatability
        self.seed = int(robot.seed)

    @classmethod
    def of(cls, cell: Any) -> CellJudge:
        """The judge of a running :class:`simulators.cell.SimulatedCell`."""
        return cls(cell.truth)

    def reference_delta(self) -> Callable[[np.ndarray], np.ndarray] | None:
        return joint_delta_of(self.robot)

    def figures(self, model: RobotModel, reference: np.ndarray, params: np.ndarray, chosen: Sequence[str],
                objective: str, region: tuple[np.ndarray, np.ndarray]) -> Mapping[str, tuple[float, str, str]]:
        rng = np.random.default_rng([self.seed, _TARGET_SALT])
        targets = targets_in_box(model, region[0], region[1], N_TARGETS, rng)
        c = base_frame_check(model, np.asarray(reference, dtype=float), np.asarray(params, dtype=float), tuple(chosen),
                             objective, targets)
        where = f"RMS of the head frame's origin in the robot's true base frame over {c.n_targets} targets"
        return {
            "base_frame_nominal_um": (c.nominal_um, "µm", f"commanded through the robot file's model; {where}"),
            "base_frame_corrected_um": (c.corrected_um, "µm", f"commanded through the identified model; {where}"),
            "base_frame_reference_um": (c.reference_um, "µm", "the best a body calibration can reach there (what the "
                                                              "body cannot tell from the set-up handed to it)"),
            "base_frame_ratio": (c.ratio, "×", "corrected ÷ reference: 1 is the best a body calibration can do"),
        }
