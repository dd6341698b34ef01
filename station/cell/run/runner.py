"""The runner: one place that owns time, device I/O, pause/abort and the run database.

Measurement procedures are generators of small messages (``MoveJoints``, ``ReadProbes`` …);
they decide *what* to do and receive each result back through ``send``. The :class:`Runner`
decides *how*: it checks every motion against the soft limits before commanding it, waits on
status objects with timeouts, averages and spread-checks probe readings, and stops at safe points
for pause and abort. The CLI and the terminal UI both drive this one implementation.

Every finished measurement is committed to the run database before the next motion starts.
"""

from __future__ import annotations

import dataclasses
import functools
import time
from collections import Counter, deque
from collections.abc import Callable, Collection, Generator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from station.cell.config.cell_config import CellConfig
from station.cell.limits.motion_guard import MotionGuard
from station.cell.plan.measurement_plan import above_offset, approach_pose, cartesian_above, retract_offset, retracted
from station.cell.plan.steps import PlannedStep, StepKind
from station.cell.plan.via_memo import memo_travel_vias
from station.cell.records.rundb import RunDB
from station.cell.run.devices import CellController, ProbeHead, Snapshot
from station.cell.run.facts.events import DeviceSnapshot, Event, MeasurementRecorded, Notice, StepMeasured, StepStarted
from station.cell.run.facts.progress import RunProgress
from station.cell.run.facts.recorder import RunRecorder
from station.cell.run.facts.stream import RunStream
from station.cell.run.recentring import displacement
from station.cell.run.runcontrol import RunControl
from station.cell.run.stuck_probes import StuckLog, still_stuck, usable_head
from station.core.kinematics.forward import scara_ik
from station.core.kinematics.transforms import invert, matrix_to_pose, pose_to_matrix
from station.core.probe.geometry import ProbeHeadGeometry, default_probe_head
from station.errors import ConfigError, MeasurementFault

# --- messages -------------------------------------------------------------------------------

@dataclass(frozen=True)
class Checkpoint:
    """A safe point: the robot stands still; pause and abort take effect here."""


@dataclass(frozen=True)
class MoveJoints:
    q: np.ndarray | None  # None: retract to travel height from where the robot stands
    why: str


@dataclass(frozen=True)
class Travel(MoveJoints):
    """Travel to ``q`` through the via poses from where the robot stands: an articulated arm's head
    lifted to the travel height and lowered over the next target
    (:func:`station.cell.plan.vias.travel_vias`, the ones the plan's collision check checked). A
    move: an executor that knows no vias (a test's) moves straight to ``q``."""


@dataclass(frozen=True)
class AboveCartesian(MoveJoints):
    """The pose a SCARA's Cartesian touch comes down from, ``q`` around the nominal joints
    (:func:`~station.cell.plan.measurement_plan.cartesian_above`). The runner moves its revolute
    joints by the active table's correction at ``pose`` (its guard's, the controller's own rule):
    the touch's last move then sweeps the planned share of the approach offset from the approach
    side whatever the correction's sign and size, as the identification's touches arrived. A move:
    an executor that knows no table moves to ``q``."""

    pose: np.ndarray | None = None  # (6,) base frame [mm, rad]: the touch's Cartesian target
    elbow: int = 1
    expected_q: np.ndarray | None = None  # the target's nominal IK


@dataclass(frozen=True)
class MoveCartesian:
    pose: np.ndarray  # (6,) base frame [mm, rad]
    elbow: int
    expected_q: np.ndarray  # nominal IK; the guard adds the active table's correction and checks it
    why: str


@dataclass(frozen=True)
class Settle:
    seconds: float


@dataclass(frozen=True)
class ReadProbes:
    pass


@dataclass(frozen=True)
class TouchInserted:
    """A touch the plan does not hold was made (a search touch of locating the body): it counts in
    the run's progress, total and done alike (:mod:`station.cell.run.facts.progress`)."""

    label: str


@dataclass(frozen=True)
class ReadJoints:
    pass


@dataclass(frozen=True)
class RecentReadings:
    """Ask the runner for the channel values of the last touches (most recent first, this
    touch's included): a stuck probe repeats its reading from touch to touch."""


@dataclass(frozen=True)
class StuckProbes(RecentReadings):
    """Ask the runner which probes earlier readings showed to be stuck: a mapping probe index
    (head order) -> frozen reading [mm]. A question about recent readings: an executor that
    keeps no such record answers it as a :class:`RecentReadings` (any non-mapping: none known)."""


@dataclass(frozen=True)
class Reading:
    """What one measurement produced."""

    joints_commanded: np.ndarray
    joints_read: np.ndarray | None
    raw: bytes
    readings_mm: np.ndarray | None
    status: tuple | None
    pose: np.ndarray | None  # (4,4) MPKS in MKKS
    residual_um: float | None
    ok: bool
    message: str
    #: the probe left out of the pose ("P3 (channel 4)"), when a redundant head excluded one
    excluded: str | None = None
    #: (probe id, channel) of each entry of readings_mm / status (head order); () : channel order
    probes: tuple[tuple[str, int], ...] = ()
    #: a re-centred reading: the move from the first commanded head pose to the one read, in the
    #: first one's head frame (x, y, z [mm], roll, pitch, yaw [rad]; :mod:`station.cell.run.recentring`)
    recentring: np.ndarray | None = None
    #: (probe index, frozen reading [mm]) of the probes left out of this reading as stuck
    stuck: tuple[tuple[int, float], ...] = ()
    #: probes known to be stuck that read elsewhere again at this reading (used again)
    freed: tuple[int, ...] = ()


Procedure = Generator[Any, Any, Reading]


# --- procedures -----------------------------------------------------------------------------

def head_of(cfg: CellConfig) -> ProbeHeadGeometry:
    """The configured probe head (``[head]``; the built-in reference head without one)."""
    head = cfg.head
    return head if head is not None else default_probe_head(cube_edge_mm=cfg.cube_edge_mm)


def probe_readings(geom: ProbeHeadGeometry, values_mm: np.ndarray, status: Sequence[Any]) -> tuple[np.ndarray, tuple[str, ...]]:
    """The interface's channel values -> each probe's reading [mm] (head order, certificate
    scale applied) and its channel status ('ok', 'over_range', …)."""
    v = np.asarray(values_mm, dtype=float)
    ch = geom.probe_channels - 1
    if ch.max() >= v.shape[0]:
        k = int(np.argmax(ch))
        raise ConfigError(f"the probe interface reports {v.shape[0]} channels, but the head file gives probe "
                          f"{geom.label(k)}: check the channel numbers in the head file against the interface's wiring")
    out = v[ch] * geom.probe_scales
    st = tuple(str(getattr(status[c], "value", status[c])) for c in ch)
    # Whatever the interface's dialect calls valid, a value beyond the probe's own stroke (head
    # file) is no measurement: a unit whose range exceeds the probe's, or a sentinel a manual
    # does not spell out, must never reach the pose solve.
    beyond = np.isfinite(out) & (np.abs(out) > geom.strokes / 2)
    if np.any(beyond):
        st = tuple(("over_range" if out[i] > 0 else "under_range") if beyond[i] else s for i, s in enumerate(st))
        out = np.where(beyond, np.nan, out)
    return out, st


def approach_and_read(cfg: CellConfig, q_target: np.ndarray, direction: int = 1,
                      cartesian: tuple[np.ndarray, int] | None = None, cycle: int = 0) -> Procedure:
    """Retract, approach ``q_target`` so that every joint arrives from the same side, settle,
    read; re-centre (bounded) when a probe is near the end of its stroke or out of range.

    ``cartesian``: ``(pose6_base, elbow)`` to make the final move a Cartesian one (corrected by
    the controller's active table), as verification does. ``cycle`` (ISO 9283 repetitions)
    varies the approach a little from cycle to cycle, from the same side, as a real path would.

    A head with more than six probes tests every touch (:mod:`station.core.probe.check`): when
    the probes disagree the touch is measured again (``[plan] remeasure_attempts``); when the
    same probe still disagrees and the others fix the pose and agree, the pose is solved without
    it and the reading says so (``excluded``); otherwise the reading is invalid with the reason.

    A re-centred reading carries the displacement from the first command to where it was read
    (``recentring``): verification adds it back, so that the re-centring hides no error.

    A probe that repeats its reading while the others show the head moving is stuck: it is left
    out at once (no re-measure: a re-touch would repeat the frozen value), and the runner passes
    it to later readings (:class:`StuckProbes`), which solve without it from the start while it
    keeps its frozen value (:mod:`station.cell.run.stuck_probes`).

    Each touch is its moves (:func:`_touch`), the pose solved from its readings (:func:`_solve`),
    a redundant head's diagnosis of a disagreement (:func:`_diagnose`) and the judgement of the
    solved pose (:func:`_judge`); each of them ends the visit, touches again, or hands on.
    """
    full = head_of(cfg)
    stuck: dict[int, float] = {}
    if full.n_probes > 6:
        known = yield StuckProbes()
        if isinstance(known, Mapping):
            stuck = {int(k): float(v) for k, v in known.items()}
    q = np.asarray(q_target, dtype=float)
    visit = _Visit(full, full.nominal_contact_pose(), q, None if cartesian is None else np.asarray(cartesian[0], dtype=float),
                   stuck)
    q_first, pose_first = visit.q, visit.pose_cmd
    while True:
        snap, q_read = yield from _touch(cfg, visit, direction, cycle, cartesian)
        touch = visit.readings(snap, q_read)
        solved = _solve(cfg, visit, touch)
        if isinstance(solved, _Solved) and touch.redundant and solved.excluded is None:
            solved = yield from _diagnose(cfg, visit, touch, solved)
        if isinstance(solved, _Solved):
            solved = _judge(cfg, visit, touch, solved)
        if solved == "done":
            break
    yield MoveJoints(None, "retract after reading")  # None: retract from where we stand
    return _finish(cfg, visit, q_first, pose_first)


#: what a step of a touch decides: touch again (a re-centring or a re-measure), or end the visit
_Next = Literal["again", "done"]


@dataclass
class _Visit:
    """One visit to a point as it goes: where the touches are commanded, what they found (the
    stuck probes, the re-centrings and re-measures, the notes) and the latest reading."""

    full: ProbeHeadGeometry
    M_nom: np.ndarray
    q: np.ndarray
    pose_cmd: np.ndarray | None
    stuck: dict[int, float]
    raw: bytes = b""
    recentred: int = 0
    remeasured: int = 0
    first_suspect: int | None = None
    notes: list[str] = field(default_factory=list)
    freed: list[int] = field(default_factory=list)
    found: dict[int, float] = field(default_factory=dict)  # probes this reading showed stuck
    keep: np.ndarray | None = None  # the probes the latest touch solved with
    last: Reading | None = None

    def readings(self, snap: Snapshot, q_read: Any) -> _TouchReadings:
        """A touch's probe values, without the probes that are (still) stuck."""
        full = self.full
        self.raw += snap.raw
        all_values, all_status = probe_readings(full, snap.values_mm, snap.status)
        self.stuck, gone = still_stuck(full, all_values, self.stuck)
        self.freed += gone
        # the pose is solved by the probes that are not stuck (the whole head when none is)
        geom, keep = usable_head(full, self.stuck)
        self.keep = keep
        kept = np.flatnonzero(keep)
        names = tuple((pid, int(c)) for pid, c in zip(full.probe_ids, full.probe_channels))
        return _TouchReadings(geom, keep, kept, all_values[keep], tuple(all_status[i] for i in kept),
                              functools.partial(_reading, self.q, q_read, self.raw, all_values, all_status, names,
                                                self.notes))

    def recentre(self, cfg: CellConfig, M: np.ndarray) -> None:
        self.q, self.pose_cmd = _recentre(cfg, self.q, self.pose_cmd, M, self.M_nom)


@dataclass(frozen=True)
class _TouchReadings:
    geom: ProbeHeadGeometry  # the head without its stuck probes
    keep: np.ndarray  # which of the full head's probes that is
    kept: np.ndarray  # their indices in the full head
    values: np.ndarray
    status: tuple[str, ...]
    reading: Callable[..., Reading]  # (pose, shown residual, ok, message[, excluded]) -> Reading

    @property
    def redundant(self) -> bool:
        return self.geom.n_probes > 6


@dataclass(frozen=True)
class _Solved:
    """A solved pose, the probe it left out (None: none) and what the reading says first."""

    sol: Any  # station.core.probe.geometry.PoseSolution
    excluded: int | None
    lead: str
    residuals: np.ndarray


def _touch(cfg: CellConfig, visit: _Visit, direction: int, cycle: int,
           cartesian: tuple[np.ndarray, int] | None) -> Generator[Any, Any, tuple[Snapshot, Any]]:
    """The moves of one touch, the settling and the reading: (probe snapshot, joints read)."""
    q, pose_cmd = visit.q, visit.pose_cmd
    # a re-measure approaches a little differently (3.7 % more offset, a path no other visit
    # or cycle takes): a fresh touch, not a replay of the one that disagreed
    r = above_offset(cfg, cycle, visit.remeasured)
    yield Checkpoint()
    yield MoveJoints(None, "retract to travel height")
    approach = approach_pose(cfg, q, direction, cycle, visit.remeasured)
    yield Travel(approach, "approach")
    if pose_cmd is None or cartesian is None:
        yield MoveJoints(q + r, "above the point")
        yield MoveJoints(q, "touch")
    else:
        # Straight from the offset approach pose: the controller's corrected joints differ
        # from q by the table's Δq, whose sign must not decide the direction of arrival.
        if not cfg.model.is_scara:  # an articulated arm stands short of q (its joints) first
            yield MoveJoints(q + r, "above the point")
        else:  # a SCARA comes down from above the point, on the approach side (cartesian_above)
            yield AboveCartesian(cartesian_above(cfg, q, direction, cycle, visit.remeasured), "above the point",
                                 pose_cmd, cartesian[1], q)
        yield MoveCartesian(pose_cmd, cartesian[1], q, "touch (Cartesian)")
    yield Settle(cfg.plan.settle_s)
    snap = yield ReadProbes()
    q_read = yield ReadJoints()
    return snap, q_read


def _solve(cfg: CellConfig, visit: _Visit, t: _TouchReadings) -> _Solved | _Next:
    """The pose from the touch's readings. A redundant head whose pose does not solve from all of
    them may solve it from its probes that read: a re-centring direction when the silent probes
    are near their stroke end there; else (one probe silent where it should read well inside its
    stroke: a dead channel) the pose without it, when the others fix the pose and agree."""
    from station.core.probe.geometry import PoseSolveError, readings_from_pose, solve_pose

    geom, values = t.geom, t.values
    try:
        sol = solve_pose(geom, values, noise_mm=cfg.plan.max_residual_um * 1e-3 / 3, check_residuals=not t.redundant)
        return _Solved(sol, None, "", sol.residuals_mm)
    except PoseSolveError as exc:
        visit.last = t.reading(None, None, False, f"pose not solved: {exc}")
    guide = _pose_from_finite(geom, values) if t.redundant else None
    if guide is None:
        # Without a pose there is no safe re-centre direction: report and move on.
        if not t.keep.all() and not np.isfinite(values).all():  # the solver's probe numbers count the probes left, not the head's
            silent = ", ".join(geom.label(int(i)) for i in np.flatnonzero(~np.isfinite(values)))
            out = ", ".join(visit.full.label(int(k)) for k in np.flatnonzero(~t.keep))
            visit.last = t.reading(None, None, False, f"pose not solved: probe {silent} without a reading while "
                                                      f"probe {out} is stuck: the other {int(np.isfinite(values).sum())} "
                                                      f"probes cannot fix the pose")
        return "done"
    missing = np.flatnonzero(~np.isfinite(values))
    expect = readings_from_pose(geom, guide[0].M)[missing]
    half = geom.strokes / 2
    off_stroke = ~np.isfinite(expect) | (np.abs(expect) > half[missing] - cfg.plan.recenter_margin_mm)
    if np.any(off_stroke) and visit.recentred < cfg.plan.recenter_attempts:
        visit.recentred += 1
        visit.notes.append(f"touch {visit.recentred + visit.remeasured}: {missing.size} probe(s) without a reading; "
                           f"re-centred on the pose of the others")
        visit.recentre(cfg, guide[0].M)
        return "again"
    if missing.size != 1 or np.any(off_stroke) or not guide[1].passed:
        return "done"
    excluded = int(missing[0])
    lead = (f"probe {geom.label(excluded)} gave no reading ({t.status[excluded].replace('_', ' ')}) where it "
            f"should read {expect[0]:+.3f} mm: excluded; solved from the other {geom.n_probes - 1} probes, "
            f"residual test passed")
    return _Solved(guide[0], excluded, lead, guide[0].residuals_mm)


def _diagnose(cfg: CellConfig, visit: _Visit, t: _TouchReadings,
              solved: _Solved) -> Generator[Any, Any, _Solved | _Next]:
    """A redundant head's residual test of the solved pose; when the probes disagree, which one:
    stuck (left out at once), or measured again, then left out when the same one disagrees again
    and the others fix the pose and agree."""
    from station.core.probe.check import diagnose, residual_test

    geom, values = t.geom, t.values
    test = residual_test(geom, values, solved.sol.M)
    if test.passed:
        if visit.remeasured and "the re-measured touch agrees" not in visit.notes:
            visit.notes.append("the re-measured touch agrees")
        return solved
    recent = yield RecentReadings()
    previous = [probe_readings(visit.full, v, ["ok"] * len(v))[0][t.keep] for v in list(recent)[1:]]
    diag = diagnose(geom, values, test, previous)
    if diag.stuck and diag.suspect is not None and diag.solution is not None:
        i = int(t.kept[diag.suspect])
        visit.found[i] = visit.stuck[i] = float(values[diag.suspect])
    elif visit.remeasured < cfg.plan.remeasure_attempts:
        visit.remeasured += 1
        visit.first_suspect = diag.suspect
        visit.notes.append(f"touch {visit.recentred + visit.remeasured}: {diag.reason}; measured again")
        return "again"
    first = visit.first_suspect
    agree = diag.stuck or first is None or first == diag.suspect
    if diag.suspect is None or diag.solution is None or not agree:
        why = diag.reason if agree else f"{diag.reason} (the touch before pointed at probe {geom.label(first or 0)})"
        visit.last = t.reading(None, test.rms_um, False, why)
        return "done"
    residuals = diag.test.residuals_mm if diag.test is not None else diag.solution.residuals_mm
    lead = (f"probe {geom.label(diag.suspect)} excluded from the pose ({diag.reason}); solved from "
            f"the other {geom.n_probes - 1} probes, residual test passed")
    return _Solved(diag.solution, diag.suspect, lead, residuals)


def _judge(cfg: CellConfig, visit: _Visit, t: _TouchReadings, s: _Solved) -> _Next:
    """The reading of a solved pose: valid when its residual is within the bound; re-centred
    (bounded) when a probe is near the end of its stroke."""
    from station.core.probe.geometry import readings_from_pose

    geom, values, full, stuck = t.geom, t.values, visit.full, visit.stuck
    res_um = float(np.sqrt(np.mean(s.residuals**2)) * 1e3)
    # Six probes fix the six degrees of freedom exactly: their residual is zero by
    # construction and says nothing about the touch, so it is not reported as a figure.
    shown = res_um if t.redundant else None
    used = np.ones(geom.n_probes, dtype=bool)
    if s.excluded is not None:
        used[s.excluded] = False
    half = geom.strokes / 2
    near = bool(np.any(np.abs(values[used]) > half[used] - cfg.plan.recenter_margin_mm))
    lead = s.lead
    if stuck and not t.keep.all():
        # a stuck probe's plunger is where the pose puts it: keep that inside its stroke too
        off = ~t.keep
        expect = readings_from_pose(full, s.sol.M)[off]
        near |= bool(np.any(~np.isfinite(expect) | (np.abs(expect) > full.strokes[off] / 2
                                                     - cfg.plan.recenter_margin_mm)))
        left_out = "; ".join(f"probe {full.label(k)} excluded: stuck at {v:.4f} mm" for k, v in stuck.items()
                             if not t.keep[k])
        lead = "; ".join(m for m in (f"{left_out}; solved from the other {geom.n_probes} probes", lead) if m)
    ok = res_um <= cfg.plan.max_residual_um
    label = None if s.excluded is None else geom.label(s.excluded)
    visit.last = t.reading(s.sol.M, shown, ok, lead if ok else f"plane residual {res_um:.1f} µm exceeds "
                                                               f"{cfg.plan.max_residual_um} µm", label)
    if not near or visit.recentred == cfg.plan.recenter_attempts:
        if near:
            visit.last = t.reading(s.sol.M, shown, ok, "; ".join(m for m in ("probes near the end of their stroke "
                                                                             "after re-centring", lead) if m), label)
        return "done"
    visit.recentred += 1
    visit.recentre(cfg, s.sol.M)
    return "again"


def _finish(cfg: CellConfig, visit: _Visit, q_first: np.ndarray, pose_first: np.ndarray | None) -> Reading:
    """The visit's reading with its re-centring's move and the probes it found stuck or freed."""
    last = visit.last
    assert last is not None and visit.keep is not None  # every touch sets both on every path
    if visit.recentred:
        d = _displacement(cfg, q_first, pose_first, visit.q, visit.pose_cmd)
        moved = (f"re-centred {visit.recentred}× to bring the probes into their stroke, "
                 f"{np.linalg.norm(d[:3]) * 1e3:.0f} µm from the commanded pose")
        last = dataclasses.replace(last, recentring=d, message="; ".join(m for m in (last.message, moved) if m))
    keep = visit.keep
    now = {k: v for k, v in visit.stuck.items() if not keep[k] or k in visit.found}
    if now or visit.freed:
        last = dataclasses.replace(last, stuck=tuple(now.items()), freed=tuple(visit.freed))
    return last


def _displacement(cfg: CellConfig, q_first: np.ndarray, pose_first: np.ndarray | None, q: np.ndarray,
                  pose_cmd: np.ndarray | None) -> np.ndarray:
    """The re-centring's move: from the first command to the last (Cartesian poses as commanded,
    else the nominal head pose of the joints)."""
    if pose_first is not None and pose_cmd is not None:
        return displacement(pose_to_matrix(pose_first), pose_to_matrix(pose_cmd))
    return displacement(_fk_base(cfg, q_first), _fk_base(cfg, q))


def _recentre(cfg: CellConfig, q: np.ndarray, pose_cmd: np.ndarray | None, M: np.ndarray,
              M_nom: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """Re-centre on the measured contact pose ``M``: the joints (and the Cartesian command)."""
    if not cfg.model.is_scara:  # all six: back to the contact q was planned for (head tilted)
        from station.cell.plan.arm_motion import recentred as recentre

        q, T_new = recentre(cfg, q, M)
        return q, (None if pose_cmd is None else matrix_to_pose(T_new))
    # The head frame must move by D = M_measured · M_nominal⁻¹ (SCARA: x, y, z, yaw).
    D = matrix_to_pose(M @ invert(M_nom))
    D[3:5] = 0.0
    T_new = _fk_base(cfg, q) @ pose_to_matrix(D)
    q = scara_ik(cfg.model, T_new[None], 1 if q[1] > 0 else -1, setup=False, check_limits=False)[0]
    return q, (None if pose_cmd is None else matrix_to_pose(T_new))


def _pose_from_finite(geom: ProbeHeadGeometry, values: np.ndarray) -> tuple[Any, Any] | None:
    """The pose solution and its residual test from the probes that read, when they still fix
    the pose (else None)."""
    from station.core.probe.check import fixes_pose, residual_test
    from station.core.probe.geometry import PoseSolveError, solve_pose

    ok = np.isfinite(values)
    if ok.sum() < 6 or ok.all():
        return None
    sub = geom.subset(ok)
    if not fixes_pose(sub):
        return None
    try:
        sol = solve_pose(sub, values[ok], check_residuals=False)
    except PoseSolveError:
        return None
    return sol, residual_test(sub, values[ok], sol.M)


def _reading(q: np.ndarray, q_read: Any, raw: bytes, values: np.ndarray, status: tuple, names: tuple,
             notes: list[str], pose: np.ndarray | None, shown: float | None, ok: bool, message: str,
             excluded: str | None = None) -> Reading:
    # the final word first (its head is the failure's cause), then what the earlier touches showed
    text = "; ".join([m for m in (message, *notes) if m])
    return Reading(q, q_read, raw, values, status, pose, shown, ok, text, excluded, names)


def _fk_base(cfg: CellConfig, q) -> np.ndarray:
    from station.core.kinematics.forward import forward

    return forward(cfg.model, np.asarray(q)[None], setup=False)[0]


# --- the runner -----------------------------------------------------------------------------

class Runner:
    """Executes procedures on real (or simulated) devices."""

    def __init__(self, cfg: CellConfig, probe: ProbeHead, controller: CellController,
                 emit: Callable[[Event], None], control: RunControl | None = None,
                 sleep: Callable[[float], None] = time.sleep):
        self.cfg = cfg
        self.probe = probe
        self.controller = controller
        #: the runner's events: the caller's ``emit``, and while steps are measured the run database's
        #: writer before it (station/cell/run/facts/recorder.py)
        self.stream = RunStream(emit)
        self.emit = self.stream
        self.control = control or RunControl()
        self._sleep = sleep
        self._last_q: np.ndarray | None = None
        # Every motion passes this guard; the pipeline tells it which table the controller applies.
        self.guard = MotionGuard(cfg.soft_limits, elbows=cfg.plan.elbows, joint_types=cfg.model.joint_types)
        self._last_snapshot: Snapshot | None = None
        self._stroke_mm = float(np.min(head_of(cfg).strokes))
        #: channel values of the last touches, most recent first (a stuck probe repeats its reading)
        self._touches: deque[np.ndarray] = deque(maxlen=8)
        self._touch_steps: deque[int] = deque(maxlen=8)  # the step of each of those touches
        #: the probes found stuck (a redundant head): later readings solve without them
        self.stuck = StuckLog(head_of(cfg), self.emit)
        #: k of n touches: the one count the progress bars show (started with the run)
        self.progress = RunProgress(self.emit)
        #: how often each probe was left out of a reading ("P3 (channel 4)" -> count)
        self.exclusions: Counter[str] = Counter()
        # Where the wall time goes: waiting for motions, settling, sampling the probes, and the
        # rest (the station's own computation and bookkeeping). benchmarks/ reads this.
        self.timing = {"motion": 0.0, "settle": 0.0, "sampling": 0.0}
        #: per plan step, its moves' clearance as the plan's collision check found it, streamed when
        #: the step starts (station/cell/run/facts/next_move.py; none: the views show none)
        self.next_moves: Mapping[int, Event] = {}

    def execute(self, proc: Procedure, index: int = 0) -> Reading:
        """Run one procedure to its end and return its result."""
        value = None
        while True:
            try:
                msg = proc.send(value)
            except StopIteration as stop:
                return stop.value
            value = self._do(msg, index)

    def _do(self, msg, index: int):
        cfg = self.cfg
        if isinstance(msg, Checkpoint):
            self.control.checkpoint(emit=self.emit, index=index)
            return None
        if isinstance(msg, StuckProbes):  # before RecentReadings: it is one
            return self.stuck.known()
        if isinstance(msg, RecentReadings):
            return tuple(self._touches)
        if isinstance(msg, TouchInserted):
            self.progress.inserted(msg.label)
            return None
        if isinstance(msg, ReadJoints):
            q = np.asarray(self.controller.read_joints(), dtype=float)
            self._last_q = q
            self._report_devices(q)
            return q
        if isinstance(msg, Travel):  # the vias depend on where the robot stands: the last command, else read
            here = self._last_q if self._last_q is not None else np.asarray(self.controller.read_joints(), dtype=float)
            target = np.asarray(msg.q, dtype=float)
            for q, name in memo_travel_vias(cfg, here, target):
                self._do(MoveJoints(q, f"{msg.why}: {name}"), index)
            return self._do(MoveJoints(target, msg.why), index)
        if isinstance(msg, AboveCartesian):
            return self._do(MoveJoints(self._above_corrected(msg), msg.why), index)
        if isinstance(msg, MoveJoints):
            if msg.q is None:  # retract: lift the quill to travel height from where the robot stands
                q = retracted(cfg, np.asarray(self.controller.read_joints(), dtype=float))
            else:
                q = np.asarray(msg.q, dtype=float)
            if self._last_q is not None and np.allclose(q, self._last_q, atol=1e-9, rtol=0):
                return None
            q = self.guard.check_joints(q, msg.why)
            t0 = time.perf_counter()
            status = self.controller.move_joints(q, speed=cfg.plan.speed)
            status.wait(timeout=cfg.devices.motion_timeout_s)
            self.timing["motion"] += time.perf_counter() - t0
            self._last_q = q
            return None
        if isinstance(msg, MoveCartesian):
            self.guard.check_cartesian(msg.pose, msg.elbow, msg.expected_q, msg.why)
            t0 = time.perf_counter()
            status = self.controller.move_cartesian(msg.pose, elbow=msg.elbow, speed=cfg.plan.speed)
            status.wait(timeout=cfg.devices.motion_timeout_s)
            self.timing["motion"] += time.perf_counter() - t0
            self._last_q = None
            return None
        if isinstance(msg, Settle):
            if msg.seconds > 0:
                t0 = time.perf_counter()
                self._sleep(msg.seconds)
                self.timing["settle"] += time.perf_counter() - t0
            return None
        if isinstance(msg, ReadProbes):
            t0 = time.perf_counter()
            before = _link_counts(self.probe)
            snap = self.probe.read_averaged(cfg.plan.samples, cfg.plan.max_spread_um * 1e-3)
            self.timing["sampling"] += time.perf_counter() - t0
            after = _link_counts(self.probe)
            if before is not None and after is not None and after != before:
                # A retried or resynchronised read is a fresh reading: say so, because a repeat of
                # this run (same seed, same cell) differs from here on.
                d = [a - b for a, b in zip(after, before)]
                self.emit(Notice("warning", f"step {index + 1}: probe link: {d[0]} timeout(s), {d[1]} retry(ies), "
                                            f"{d[2]} stale frame(s) discarded; the step's readings are fresh ones"))
            self._last_snapshot = snap
            self._touches.appendleft(np.array(snap.values_mm, dtype=float))
            self._touch_steps.appendleft(index)
            return snap
        raise TypeError(f"unknown runner message {msg!r}")

    def _above_corrected(self, msg: AboveCartesian) -> np.ndarray:
        """An :class:`AboveCartesian`'s joints moved, in its revolute joints, by the correction the
        controller will add at its Cartesian target: the planned offset from the approach side is
        then kept to the joints it commands there (without it a correction larger than the share,
        0.19° at a point of the built-in cell's seed 4, made joints 1 and 2 arrive from the other
        side, by the backlash: the oracle's after 9.1 -> 56.4 µm)."""
        q = np.asarray(msg.q, dtype=float)
        if msg.pose is None or msg.expected_q is None:
            return q
        nominal = np.asarray(msg.expected_q, dtype=float)
        dq = self.guard.commanded_joints(msg.pose, msg.elbow, nominal) - nominal
        return q + np.where(retract_offset(self.cfg) > 0, 0.0, dq)  # the quill keeps its height above the point

    def _excluded(self, probe: str, label: str) -> None:
        """Count a probe left out of a reading; say so when it happens again (at the 2nd, then
        every 10th time): one exclusion is a speck of dust, repeated ones a probe to check."""
        self.exclusions[probe] += 1
        k = self.exclusions[probe]
        if self.stuck.is_stuck(probe):  # said already, and more plainly ("is stuck")
            return
        if k == 2 or (k > 2 and k % 10 == 0):
            self.emit(Notice("warning", f"probe {probe} stuck? check it: left out of {k} readings (the last: {label}) "
                                        f"because it disagreed with the other probes or gave no reading; those "
                                        f"readings stay valid, solved from the other probes"))

    def _report_devices(self, q: np.ndarray) -> None:
        """The device panel's view after a reading: probes, joints, controller state."""
        snap = self._last_snapshot
        if snap is None:
            return
        st = self.controller.status()
        state = ("e-stop" if st.estop else f"error: {st.error_message}" if st.error
                 else "moving" if getattr(st, "moving", False) else "ready" if st.ready else "not ready")
        age = getattr(self.controller, "heartbeat_age_s", None)
        geom = head_of(self.cfg)
        # the head's probes by id, as the pose solve sees them: an unwired channel is no probe
        values, status = probe_readings(geom, snap.values_mm, snap.status)
        self.emit(DeviceSnapshot(
            probe_mm=tuple(float(v) for v in values), probe_status=status,
            stroke_mm=self._stroke_mm, joints=tuple(float(v) for v in q),
            joint_types=tuple(self.cfg.model.joint_types), controller=state,
            heartbeat_age_s=None if age is None else float(age), probe_ids=geom.probe_ids))

    def measure_steps(self, db: RunDB, run_id: int, steps: Sequence[PlannedStep], kinds: Collection[StepKind],
                      total: int, make_proc: Callable[[PlannedStep], Procedure]) -> int:
        """Measure every step of ``steps`` of the given kinds that has no valid measurement in the
        database yet; each is committed before the next motion. A step stored as invalid (from
        an earlier attempt) is measured again and replaces it, so a resumed run repairs what a
        fixed fault spoiled. Raises :class:`MeasurementFault` when readings fail with the same
        cause :data:`MAX_REPEATED_FAILURES` times in a row. Returns the number measured now."""
        valid = db.completed_steps(run_id, ok_only=True)
        stored = db.completed_steps(run_id)
        failures: list[tuple[str, str]] = []  # (cause, label) of the consecutive failed steps
        if not self.progress.started:  # a runner used without a run's start (a test's): the plan's count
            self.progress.start(total, len(valid))
        # the run database's writer, first: each measurement is on disk before a view hears of it and
        # before the next motion; its failure raises here and stops the run (station/cell/run/facts/recorder.py)
        token = self.stream.subscribe(RunRecorder(db, run_id), StepMeasured, first=True)
        n = 0
        try:
            for st in steps:
                if st.kind not in kinds or st.index in valid:
                    continue
                self.emit(StepStarted(st.index, total, f"{st.kind.caption}: {st.label}"))
                if st.index in self.next_moves:
                    self.emit(self.next_moves[st.index])
                reading = self.execute(make_proc(st), st.index)
                self._measured(run_id, st, reading, total, replace=st.index in stored)
                n += 1
                self._judge_failures(st.label, reading, failures)
        finally:
            self.stream.unsubscribe(token)
        return n

    def _measured(self, run_id: int, st: PlannedStep, reading: Reading, total: int, replace: bool) -> None:
        """Stream the step's reading (stored by the recorder, then counted and shown) and keep
        track of the probes it left out or found stuck."""
        label = st.label
        self.emit(StepMeasured(
            run_id, st.index, kind=st.kind.value, point_id=st.point_id, label=label,
            joints_commanded=reading.joints_commanded, joints_read=reading.joints_read, raw=reading.raw,
            readings_mm=reading.readings_mm, channel_status=reading.status, pose=reading.pose,
            residual_um=reading.residual_um, ok=reading.ok, message=reading.message,
            recentring=reading.recentring, replace=replace))
        self.progress.measured(st.index, f"{st.kind.caption}: {label}")  # on disk: counted
        residual = float("nan") if reading.residual_um is None else float(reading.residual_um)
        self.emit(MeasurementRecorded(st.index, total, label, reading.ok, residual, reading.message))
        if reading.stuck or reading.freed:
            geom = head_of(self.cfg)
            touches = [(s, probe_readings(geom, v, ["ok"] * len(v))[0])
                       for s, v in zip(self._touch_steps, self._touches)]
            self.stuck.update(reading.stuck, reading.freed, st.index, label, touches)
        if reading.excluded is not None:
            self._excluded(reading.excluded, label)

    def _judge_failures(self, label: str, reading: Reading, failures: list[tuple[str, str]]) -> None:
        """Raises :class:`MeasurementFault` at :data:`MAX_REPEATED_FAILURES` failed readings in a
        row with the same cause."""
        if reading.ok:
            failures.clear()
            return
        cause = failure_cause(reading)
        self.emit(Notice("warning", f"{label}: {cause}: {reading.message}"))
        if failures and failures[-1][0] != cause:
            failures.clear()
        failures.append((cause, label))
        if len(failures) >= MAX_REPEATED_FAILURES:
            raise MeasurementFault(
                f"{cause} on {len(failures)} steps in a row ({', '.join(lb for _, lb in failures)}); the run "
                f"stopped at a safe point instead of measuring more invalid data. Check that probe "
                f"(cable, stroke, debris, a stuck tip) with 'station check', then resume: the invalid "
                f"steps are measured again")


def _link_counts(probe: object) -> tuple[int, int, int] | None:
    """(timeouts, retries, discarded frames) of a driver that counts them (the serial driver's
    ``stats``); None for one that does not."""
    stats = getattr(probe, "stats", None)
    if stats is None:
        return None
    return (int(getattr(stats, "timeouts", 0)), int(getattr(stats, "retries", 0)),
            int(getattr(stats, "discarded_frames", 0)))


#: consecutive failed readings with the same cause that stop a run
MAX_REPEATED_FAILURES = 3


def failure_cause(reading: Reading) -> str:
    """What made a reading invalid, as an operator names it: the probes whose channel did not
    read (numbered from 1, as on the head's drawing), else the kind of failure."""
    if reading.status is not None:
        names = reading.probes or tuple((str(i + 1), i + 1) for i in range(len(reading.status)))
        bad = [f"probe {pid} {s.replace('_', ' ')}" + ("" if pid == str(ch) else f" (channel {ch})")
               for (pid, ch), s in zip(names, reading.status) if s != "ok"]
        if bad:
            return ", ".join(bad)
    return reading.message.split(":")[0] or "invalid reading"
