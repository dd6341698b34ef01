"""Warm-up before measuring (``[warmup]``, for ``calibrate`` and ``recheck``).

A hard-run arm moves by up to about 1 mm while it warms up (brief §10). The warm-up runs cycles
of a motion program over the workspace (lateral moves at travel height, through the same runner
and motion guard as every measurement); each cycle ends with a measurement of one reference
pose. With ``until = "converged"`` it stops when the reference pose's *remaining* drift,
extrapolated from the last three measurements (a geometric tail: the warm-up curve is an
exponential, so successive changes shrink by a constant ratio r and what is left is
d·r/(1−r)), is below ``converged_um``; with ``until = "time"`` after ``minutes``. Either stops
at ``max_cycles`` or ``minutes``. Progress is emitted as events; the state is stored with the
run (result ``warmup``).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from station.cell.config.cell_config import CellConfig
from station.cell.plan.measurement_plan import approach_pose, build_plan
from station.cell.plan.steps import PlannedStep
from station.cell.records.rundb import RunDB
from station.cell.run.facts.events import Event, Notice, PhaseChanged
from station.cell.run.recentring import head_as_commanded
from station.cell.run.runner import Checkpoint, MoveJoints, Procedure, Runner, TouchInserted, Travel, approach_and_read
from station.core.kinematics.transforms import invert


def remaining_drift_um(positions_mm: Sequence[np.ndarray]) -> float:
    """Extrapolated drift still to come [µm] from the last three positions of the reference pose:
    with d1, d2 the last two changes and r = d2·d1 / |d1|² (the ratio of an exponential tail),
    d2·r/(1−r) for 0 < r < 1, else |d2| (no trend: noise). ``inf`` with fewer than three."""
    if len(positions_mm) < 3:
        return float("inf")
    x0, x1, x2 = (np.asarray(p, dtype=float) for p in positions_mm[-3:])
    d1, d2 = x1 - x0, x2 - x1
    n1 = float(d1 @ d1)
    r = float(d2 @ d1) / n1 if n1 > 0 else 0.0
    rem = np.linalg.norm(d2) * (r / (1.0 - r) if 0.0 < r < 0.999 else 1.0)
    return float(max(rem, np.linalg.norm(d2))) * 1e3


def program_joints(cfg: CellConfig, reference: PlannedStep) -> list[np.ndarray]:
    """The motion program: ``program_poses`` measuring poses of the reference's elbow spread
    over the body, visited at travel height (approach poses, never touching)."""
    assert cfg.warmup is not None
    plan = build_plan(cfg)
    cands = {(st.point, st.elbow): st.q for st in plan.identification if st.elbow == reference.elbow}
    cands.update({(t.point, t.elbow): t.joints for t in plan.verification if t.elbow == reference.elbow})
    qs = [cands[k] for k in sorted(cands)]
    n = min(cfg.warmup.program_poses, len(qs))
    pick = np.linspace(0, len(qs) - 1, n).round().astype(int)
    return [approach_pose(cfg, qs[i]) for i in pick]


def _cycle(cfg: CellConfig, program: Sequence[np.ndarray], reference: PlannedStep) -> Procedure:
    yield Checkpoint()
    yield MoveJoints(None, "warm-up: retract to travel height")
    for q in program:
        yield Travel(q, "warm-up motion")  # lifted over the body between its targets (issue 40)
    reading = yield from approach_and_read(cfg, reference.q, reference.direction)
    yield TouchInserted(f"warm-up: {reference.label}")  # a touch beyond the plan: counted in the run's progress
    return reading


def run_warmup(cfg: CellConfig, runner: Runner, db: RunDB | None, run_id: int | None, reference: PlannedStep,
               emit: Callable[[Event], None], clock: Callable[[], float] = time.monotonic) -> dict[str, Any]:
    """Warm the robot up (see the module); returns the state stored as the run's ``warmup``
    result: ``until``, ``cycles``, ``converged``, ``remaining_um``, ``reference`` (the pose's
    label), ``moved_um`` (the reference position after each cycle against the first, µm)."""
    w = cfg.warmup
    assert w is not None
    emit(PhaseChanged("measure", f"warm-up ({'until converged' if w.until == 'converged' else f'{w.minutes:g} min'})"))
    program = program_joints(cfg, reference)
    heads: list[np.ndarray] = []
    t0 = clock()
    remaining = float("inf")
    converged = False
    cycles = 0
    for cycles in range(1, w.max_cycles + 1):
        reading = runner.execute(_cycle(cfg, program, reference), reference.index)
        if reading.ok and reading.pose is not None:
            # where the robot stood as commanded: a re-centring's move is part of the drift watched
            T = head_as_commanded(cfg.body_points[reference.point] @ invert(reading.pose), reading.recentring)
            heads.append(T[:3, 3])
        remaining = remaining_drift_um(heads)
        elapsed_min = (clock() - t0) / 60.0
        moved = np.linalg.norm(heads[-1] - heads[0]) * 1e3 if heads else float("nan")
        emit(Notice("info", f"warm-up cycle {cycles}: reference {reference.label} moved {moved:.1f} µm since "
                            f"the first cycle, remaining drift ≈ {remaining:.2f} µm"))
        if w.until == "converged" and remaining < w.converged_um:
            converged = True
            break
        if elapsed_min >= w.minutes:
            converged = w.until == "time"
            break
    state = {"until": w.until, "cycles": cycles, "converged": converged,
             "remaining_um": None if not np.isfinite(remaining) else remaining,
             "converged_um": w.converged_um, "reference": reference.label,
             "moved_um": [float(np.linalg.norm(h - heads[0]) * 1e3) for h in heads]}
    if not converged:
        emit(Notice("warning", f"warm-up ended after {cycles} cycles without meeting its criterion "
                               f"(remaining drift ≈ {remaining:.2f} µm > {w.converged_um:g} µm)"))
    else:
        emit(Notice("info", f"warm-up done after {cycles} cycles"))
    if db is not None and run_id is not None:
        db.save_result(run_id, "warmup", state)
    return state
