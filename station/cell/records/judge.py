"""What a simulated cell adds to a run besides its devices (issue 42): a judge who knows the robot
the devices play. A real cell has none, and its run works only from what it measures.

The run asks a judge (:class:`RunJudge`) for two things and reports them as the simulation's:

* the *reference robot*: the parameters the robot really has, its reversal error (half of it is
  a constant joint offset under the station's one-sided approach:
  :func:`station.cell.pipeline.results.reference_params` folds it in), its joint errors beyond
  geometry, its repeatability and the seed of its scatter. The run builds the reference
  correction from it and measures the held-out poses once more with
  that correction active (``StepKind.REFERENCE``). Both verifications go through the same probes,
  so ``after_vs_oracle`` (after ÷ reference) compares like with like: 1.0 is the best any
  identification could do with the cell's noise;
* after verification, :meth:`RunJudge.figures`: named figures with their units computed by the
  judge from the identified model, e.g. the base-frame check (the corrected robot judged in
  its true base frame, ``simulators/base_frame.py``).

``simulators.judge.CellJudge`` is the one implementation; ``station.ui.simulated_cell`` hands it
to the session. The cell never imports the simulators (an import contract); the judge returns
plain numbers, which :func:`judge_figures` types.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from station.core.kinematics.model import RobotModel

#: ``q ↦ Δq(q)``: the joint error ``(…, g)`` a robot stands with at commanded joints ``(…, g)``
JointDeltaFn = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class JudgeFigure:
    """One figure of a judge: ``name`` (a JSON key), ``value`` in ``unit``, what it is (``caption``)."""

    name: str
    value: float
    unit: str
    caption: str


class RunJudge(Protocol):
    """A simulated cell's judge (see the module)."""

    #: the robot's parameters ``(n_params,)`` [mm, rad]
    params: np.ndarray
    #: full reversal error per joint ``(g,)`` [rad, mm]
    backlash: np.ndarray
    #: σ of the physical joint position per move ``(g,)`` [rad, mm]
    repeatability: np.ndarray
    #: the seed of the judge's draws (its scatter, its targets)
    seed: int

    def reference_delta(self) -> JointDeltaFn | None:
        """The robot's joint errors beyond geometry (None: a rigid robot)."""
        ...

    def figures(self, model: RobotModel, reference: np.ndarray, params: np.ndarray, chosen: Sequence[str],
                objective: str, region: tuple[np.ndarray, np.ndarray]) -> Mapping[str, tuple[float, str, str]]:
        """Figures of the identified ``params`` (``chosen`` fitted with ``objective``) against the
        ``reference`` parameters over the box ``region`` (lo, hi) [mm, base frame]:
        name → (value, unit, caption)."""
        ...


def judge_figures(raw: Mapping[str, tuple[float, str, str]]) -> tuple[JudgeFigure, ...]:
    """A judge's plain figures, typed, in the judge's order."""
    return tuple(JudgeFigure(str(k), float(v), str(u), str(c)) for k, (v, u, c) in raw.items())
