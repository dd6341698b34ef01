"""What both planners share (the SCARA's :mod:`station.cell.plan.measurement_plan` and the articulated arm's
:mod:`station.cell.plan.articulated`): the target and plan types, where the head touches a
measuring point, and how a plan is put together from its candidates: the held-out verification
targets, the optional greedy D-optimal selection, the repeats and reversals.

Both planners import this module and it imports neither, so the planners form no circle.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from station.cell.config.cell_config import CellConfig
from station.cell.plan.steps import PlannedStep, StepKind
from station.core.kinematics.transforms import invert

__all__ = ["Target", "Plan", "nominal_contact", "head_targets_world", "assemble_plan", "hold_out",
           "select_d_optimal"]


@dataclass(frozen=True)
class Target:
    """One (point, elbow) pose. ``head_world``: KKS←MKKS (4,4) where the head must be;
    ``joints``: nominal-model joints reaching it with the nominal set-up."""

    point: int
    point_id: str
    elbow: int
    head_world: np.ndarray
    joints: np.ndarray

    @property
    def label(self) -> str:
        return f"{self.point_id} elbow {'+' if self.elbow > 0 else '-'}"


def _step(index: int, kind: StepKind, t: Target, direction: int = 1, cycle: int = 0) -> PlannedStep:
    return PlannedStep(index, kind, t.point, t.point_id, t.elbow, direction, cycle,
                       tuple(float(v) for v in t.joints))


@dataclass(frozen=True)
class Plan:
    """``identification``: the identification (and reversal) steps, ordered for short travel;
    ``verification``: the held-out targets; ``rejected``: (point id, elbow, reason) of every
    candidate that cannot be measured within the limits."""

    identification: tuple[PlannedStep, ...]
    verification: tuple[Target, ...]
    rejected: tuple[tuple[str, int, str], ...]

    def run_steps(self, cycles: int, with_oracle: bool, with_upload: bool = True) -> tuple[PlannedStep, ...]:
        """Every step of a run: identification, then verification before / after (/ with the
        oracle's table) × ``cycles`` × held-out targets; without the upload, before only."""
        steps = list(self.identification)
        kinds = [StepKind.VERIFY_BEFORE]
        if with_upload:
            kinds += [StepKind.VERIFY_AFTER] + ([StepKind.REFERENCE] if with_oracle else [])
        for kind in kinds:
            for cycle in range(cycles):
                for t in self.verification:
                    steps.append(_step(len(steps), kind, t, 1, cycle))
        return tuple(steps)


def nominal_contact(cfg: CellConfig) -> np.ndarray:
    """MPKS in MKKS (4,4) at the nominal touch: the configured head's (``[head]``)."""
    from station.core.probe.geometry import default_probe_head

    head = cfg.head if cfg.head is not None else default_probe_head(cube_edge_mm=cfg.cube_edge_mm)
    return head.nominal_contact_pose()


def head_targets_world(cfg: CellConfig) -> np.ndarray:
    """KKS←MKKS (n, 4, 4): the head at mid-stroke on every measuring point."""
    return cfg.body_points @ invert(nominal_contact(cfg))



def assemble_plan(cfg: CellConfig, ident: list[Target], verification: tuple[Target, ...],
                  rejected: list[tuple[str, int, str]], order: Callable[[list[Target]], list[Target]]) -> Plan:
    """The plan from its identification candidates: optionally the ``select`` most informative
    (D-optimal), ordered by ``order`` for short travel, visited ``repeats`` times (every other
    pass backwards), each with its reverse approach when ``both_directions``."""
    if cfg.plan.select and cfg.plan.select < len(ident):
        ident = select_d_optimal(cfg, ident, cfg.plan.select)
    ident = order(ident)
    steps: list[PlannedStep] = []
    for rep in range(cfg.plan.repeats):
        for t in (ident if rep % 2 == 0 else ident[::-1]):
            steps.append(_step(len(steps), StepKind.IDENTIFICATION, t, 1, rep))
            if cfg.plan.both_directions:
                steps.append(_step(len(steps), StepKind.REVERSAL, t, -1, rep))
    return Plan(tuple(steps), verification, tuple(rejected))


def hold_out(cands: list[Target], every: int, elbows: tuple[int, ...]) -> set[int]:
    """Indices of the candidates held out for verification: every ``every``-th of each elbow's
    candidates (in point order, so they spread over the body), the elbows shifted against each
    other so that they do not all fall on the same points."""
    held: set[int] = set()
    shift = max(1, every // max(len(elbows), 1))
    for j, elbow in enumerate(elbows):
        mine = [i for i, c in enumerate(cands) if c.elbow == elbow]
        held.update(i for n, i in enumerate(mine) if (n + j * shift) % every == every - 1)
    return held


def select_d_optimal(cfg: CellConfig, targets: list[Target], n: int) -> list[Target]:
    """Greedy D-optimal subset: maximise log det of the information matrix of the minimal set."""
    from station.core.identification.identifiability import analyze
    from station.core.measurement.measurements import synthetic_set

    q = np.array([t.joints for t in targets])
    sig = cfg.identification.pose_sigma()
    data = synthetic_set(cfg.model, "pose", q, cfg.model.nominal, sigma=sig)
    a = analyze(cfg.model, data, prefer=cfg.identification.prefer, fix=cfg.identification.fix,
                exclude=cfg.identification.exclude, describe=False)
    from station.core.measurement.measurements import residuals_and_jacobian

    _, J = residuals_and_jacobian(cfg.model, data, cfg.model.nominal)
    J = (J / data.sigma[:, None])[:, a.chosen_indices()].reshape(len(targets), 6, -1)
    p = J.shape[-1]
    info = 1e-9 * np.eye(p)
    chosen: list[int] = []
    JtJ = np.swapaxes(J, -1, -2) @ J  # (n, p, p): each candidate's information
    for _ in range(n):
        # every candidate at once (the same log det per candidate; the first best wins ties)
        sign, val = np.linalg.slogdet(info[None] + JtJ)
        val = np.where(sign > 0, val, -np.inf)
        val[chosen] = -np.inf
        best = int(np.argmax(val))
        if not np.isfinite(val[best]):  # no candidate adds information: the rest cannot help either
            break
        chosen.append(best)
        info = info + J[best].T @ J[best]
    return [targets[i] for i in sorted(chosen)]
