"""The body is found, not assumed (issue 37 §1).

Before the identification poses the station touches the first :data:`N_LOCATE` measuring points of
the plan at the guess (``[robot].setup``). Where a face's probes read out of stroke it searches
(:func:`search_and_read`): it touches again with the head moved along that face's normal by the
step of :mod:`station.cell.plan.locating`, towards the face when its probes are extended beyond
their stroke (over range: the face is farther) and away from it when they are pushed in (under
range), within the set-up's uncertainty and the clearance, ``[plan] locate_steps`` times per face
at most. Every search touch is the runner's ordinary touch (retract, approach, touch, read), so
every motion passes the motion guard.

The touches found are the first identification measurements (they are valid measurements like any
other: the joints read go with the pose measured). From them the set-up is re-estimated
(:mod:`station.core.identification.setup_locate`) and stored with the run (result :data:`RESULT_KEY`); when it
moves a measuring point by more than half a touch's window from where the guess put it, the rest
of the identification poses are commanded on the located set-up (:func:`located_joints`); else the
plan's joints are kept (the re-centring takes care of the rest). A resumed run reads the stored
set-up and does not locate again.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from station.cell.config.cell_config import CellConfig
from station.cell.plan.first_moves import N_LOCATE, face_directions, locate_steps
from station.cell.plan.locating import FACE_NAMES, Coverage, coverage
from station.cell.plan.steps import PlannedStep, StepKind
from station.cell.records.rundb import RunDB
from station.cell.run.facts.events import Event, Notice, PhaseChanged
from station.cell.run.runner import Procedure, Reading, Runner, TouchInserted, approach_and_read, head_of
from station.core.identification.setup_locate import point_shift_mm, setup_from_contacts
from station.core.kinematics.transforms import invert, pose_to_matrix
from station.core.units import DEG
from station.errors import MeasurementFault, UnreachableError

__all__ = ["N_LOCATE", "RESULT_KEY", "SearchLog", "search_and_read", "located_joints", "locate_body",
           "stored_located_setup", "located_config"]

#: the run database's result with the located set-up (units in its keys)
RESULT_KEY = "located_setup"


@dataclass
class SearchLog:
    """What the search did, by step index: the search touches and the final offset per face [mm]."""

    steps: dict[int, int] = field(default_factory=dict)
    offsets: dict[int, tuple[float, float, float]] = field(default_factory=dict)


def _face_directions(cfg: CellConfig) -> np.ndarray:
    """``(3, 3)`` per face (top, x, y) the mean direction of its probes in MKKS: the normals the plan's
    check moved the head along (:func:`station.cell.plan.first_moves.face_directions`)."""
    return face_directions(cfg)


def _face_moves(cfg: CellConfig, reading: Reading) -> np.ndarray:
    """``(3,)`` per face: +1 where its probes are extended beyond their stroke (over range: the face
    lies farther along their direction), −1 where they are pushed in (under range), 0 where the
    face is read or the probes disagree (no direction to search in)."""
    faces = np.asarray(head_of(cfg).faces, dtype=int)
    status = tuple(reading.status or ())
    out = np.zeros(3)
    if len(status) != len(faces):
        return out
    for f in range(3):
        mine = {status[i] for i in np.flatnonzero(faces == f)}
        if "over_range" in mine and "under_range" not in mine:
            out[f] = 1.0
        elif "under_range" in mine and "over_range" not in mine:
            out[f] = -1.0
    return out


def shifted_joints(cfg: CellConfig, q: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The joints that put the head ``t`` (3,) [mm, head frame MKKS] from where ``q`` puts it."""
    from station.cell.run.runner import _fk_base

    T = _fk_base(cfg, q) @ pose_to_matrix(np.array([*t, 0.0, 0.0, 0.0]))
    return _ik_near(cfg, T, q, "a search touch")


def _ik_near(cfg: CellConfig, T_base: np.ndarray, q: np.ndarray, what: str) -> np.ndarray:
    """Joints for base←head ``T_base`` in ``q``'s configuration (its elbow; an arm: followed from ``q``)."""
    if cfg.model.is_scara:
        from station.core.kinematics.forward import scara_ik

        out = scara_ik(cfg.model, T_base[None], 1 if q[1] > 0 else -1, setup=False, check_limits=False)[0]
        ok = bool(np.all(np.isfinite(out)))
    else:
        from station.cell.plan.arm_motion import follow_ik

        sol, good = follow_ik(cfg.model, T_base[None], np.asarray(q, dtype=float)[None])
        out, ok = sol[0], bool(good[0])
    if not ok:
        raise UnreachableError(f"{what} needs a pose the inverse kinematics does not reach; the motion was not "
                               f"commanded. Check [robot].setup and the body's points")
    return out


def search_and_read(cfg: CellConfig, step: PlannedStep, cov: Coverage, log: SearchLog) -> Procedure:
    """Touch ``step`` at the guess; while a face's probes read out of stroke, touch again with the
    head moved along that face's normal (bounded, see the module's text). Returns the last reading,
    its message naming the search."""
    q0 = step.q
    dirs = _face_directions(cfg)
    offset = np.zeros(3)
    used = np.zeros(3, dtype=int)
    q = q0
    notes: list[str] = []
    while True:
        reading: Reading = yield from approach_and_read(cfg, q, step.direction, cycle=step.cycle)
        if reading.ok:
            break
        move = _face_moves(cfg, reading)
        move[used >= cov.steps] = 0.0  # this face's steps are spent
        target = np.clip(offset + move * cov.step, -cov.limit, cov.limit)
        if np.allclose(target, offset):  # nothing to search in, or the uncertainty's bound is reached
            break
        changed = [FACE_NAMES[f] for f in range(3) if target[f] != offset[f]]
        yield TouchInserted(f"locating the body: {step.label}, searched")  # the touch just made, beyond the plan
        used += (target != offset).astype(int)
        offset = target
        q = shifted_joints(cfg, q0, dirs.T @ offset)
        notes.append(f"{'/'.join(changed)} face out of stroke: searched {int(used.sum())}, offset "
                     + ", ".join(f"{n} {o:+.2f} mm" for n, o in zip(FACE_NAMES, offset)))
    if used.any():
        log.steps[step.index] = int(used.sum())
        log.offsets[step.index] = (float(offset[0]), float(offset[1]), float(offset[2]))
        found = "located" if reading.ok else "not found"
        text = f"body {found} after {int(used.sum())} search touch(es) ({'; '.join(notes)})"
        reading = replace(reading, message="; ".join(m for m in (reading.message, text) if m))
    return reading


def located_joints(cfg: CellConfig, step: PlannedStep, setup: np.ndarray) -> np.ndarray:
    """The joints of ``step``'s head pose (its planned pose in the body frame) on the located
    ``setup`` (world←base pose, mm and rad)."""
    from station.cell.run.runner import _fk_base

    head_world = pose_to_matrix(cfg.model.nominal[:6]) @ _fk_base(cfg, step.q)
    T_base = invert(pose_to_matrix(np.asarray(setup, dtype=float))) @ head_world
    return _ik_near(cfg, T_base, step.q, f"{step.label} on the located set-up")


def stored_located_setup(db: RunDB, run_id: int) -> tuple[np.ndarray, bool] | None:
    """The run's located set-up (mm, rad) and whether its poses are commanded on it; None before it
    was located (or for a run from before issue 37)."""
    rec = db.load_result(run_id, RESULT_KEY, default=None)
    if not isinstance(rec, dict):
        return None
    s = rec["setup_located_mm_deg"]
    return np.array([*s[:3], *(np.asarray(s[3:], dtype=float) * DEG)]), bool(rec["replanned"])


def located_config(cfg: CellConfig, db: RunDB, run_id: int) -> CellConfig:
    """The configuration run ``run_id`` identified in: ``cfg`` (its stored configuration) with the
    located set-up where the identification poses were commanded on it, as the pipeline continues
    after locating; ``cfg`` itself otherwise. What recomputes the run's identification from its
    measurements (the report) starts from the same set-up, so that it gets the run's parameters and
    its table the same CRC-32."""
    stored = stored_located_setup(db, run_id)
    if stored is None or not stored[1]:
        return cfg
    return replace(cfg, model=cfg.model.with_setup(stored[0]))


def _locate_steps(cfg: CellConfig, steps: Sequence[PlannedStep]) -> list[PlannedStep]:
    """The steps that locate the body: the ones whose search touches the plan's check checked
    (:func:`station.cell.plan.first_moves.locate_steps`)."""
    return locate_steps(cfg, steps)


def locate_body(cfg: CellConfig, runner: Runner, db: RunDB, run_id: int, steps: Sequence[PlannedStep],
                emit: Callable[[Event], None]) -> np.ndarray | None:
    """Locate the body at the plan's first points; store and return the located set-up when the
    rest of the identification poses are to be commanded on it (None: the plan's joints stand)."""
    stored = stored_located_setup(db, run_id)
    if stored is not None:
        return stored[0] if stored[1] else None
    cov = coverage(cfg)
    first = _locate_steps(cfg, steps)
    emit(PhaseChanged("measure", "locating the body"))
    log = SearchLog()
    try:
        runner.measure_steps(db, run_id, first, {StepKind.IDENTIFICATION}, len(steps),
                             lambda st: search_and_read(cfg, st, cov, log))
    except MeasurementFault as exc:
        raise MeasurementFault(_not_found(cfg, cov, str(exc))) from None
    index = {st.index: st for st in first}
    recs = [r for r in db.measurements(run_id, kind=StepKind.IDENTIFICATION.value)
            if r.step_index in index and r.ok and r.pose is not None and r.joints_read is not None]
    if not recs:
        raise MeasurementFault(_not_found(cfg, cov, f"none of {', '.join(s.label for s in first)} was found"))
    return _keep(cfg, db, run_id, recs, index, cov, log, emit)


def _keep(cfg: CellConfig, db: RunDB, run_id: int, recs: list, index: dict[int, PlannedStep], cov: Coverage,
          log: SearchLog, emit: Callable[[Event], None]) -> np.ndarray | None:
    """The set-up from the located records: stored, said, returned where the plan follows it."""
    from station.cell.run.runner import _fk_base

    P = cfg.body_points[[index[r.step_index].point for r in recs]]
    T = np.stack([_fk_base(cfg, r.joints_read) for r in recs])
    guess = np.asarray(cfg.model.nominal[:6], dtype=float)
    setup = setup_from_contacts(P, T, np.stack([r.pose for r in recs]), (float(guess[3]), float(guess[4])))
    shift = float(point_shift_mm(cfg.body_points, guess, setup).max())
    replanned = shift > 0.5 * cov.window
    searched = sum(log.steps.values())

    def mm_deg(p: np.ndarray) -> list[float]:
        return [*(float(v) for v in p[:3]), *(float(v) / DEG for v in p[3:])]

    db.save_result(run_id, RESULT_KEY, {
        "setup_guess_mm_deg": mm_deg(guess), "setup_located_mm_deg": mm_deg(setup), "max_point_shift_mm": shift,
        "points": [r.point_id for r in recs], "search_touches": searched, "replanned": replanned,
        "window_mm": cov.window, "step_mm": cov.step})
    where = "; the identification poses are commanded on the located set-up" if replanned else \
        f"; within ±{0.5 * cov.window:.2f} mm of the guess, the plan's joints are kept"
    note = (f"body located at {', '.join(r.point_id for r in recs)} ({searched} search touch(es)): the measuring "
            f"points lie up to {shift:.2f} mm from where [robot].setup puts them{where}")
    emit(Notice("info", note))
    db.log(run_id, "info", note)
    if not replanned:
        return None
    stored = stored_located_setup(db, run_id)  # as stored (mm, deg and back): bit for bit what a resume
    assert stored is not None                  # and the report read
    return stored[0]


def _not_found(cfg: CellConfig, cov: Coverage, why: str) -> str:
    return (f"the body was not found within ±{cov.limit:g} mm of [robot].setup ({why}); the search moved each face "
            f"up to {cov.steps} step(s) of {cov.step:.2f} mm. Measure where the robot stands and correct "
            f"[robot].setup, or raise [robot] setup_uncertainty_mm and [plan] locate_steps (station plan checks "
            f"them against the probes' stroke), then start a new run")
