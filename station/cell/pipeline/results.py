"""What a run's stored measurements give, recomputed the same way by the pipeline, the report and
the recheck: the identification, the verification errors, the reversal error, the correction
table on the configured grid, and (in simulation) the oracle's true parameters.

Everything here is a pure function of the configuration and the records (with the re-centring
displacements stored beside them, :mod:`station.cell.run.recentring`); nothing moves or writes, so the report of a stored run shows exactly what its run computed.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from drivers.controller_map import MAX_TABLE_VALUES
from station.cell.config.cell_config import CellConfig, correction_grid
from station.cell.correction.design import design_for
from station.cell.plan.measurement_plan import all_motion_poses, approach_offsets, head_targets_world
from station.cell.plan.steps import PlannedStep, StepKind
from station.cell.records.judge import RunJudge
from station.cell.records.missed import MissedLimit
from station.cell.records.run_records import MeasurementRecord
from station.cell.records.summary import ReversalSummary, RunSummary
from station.cell.run.recentring import head_as_commanded
from station.core.identification.identify import IdentificationResult, identify
from station.core.kinematics.transforms import invert
from station.core.measurement.measurements import MeasurementSet
from station.core.table.build import CorrectionTable, build_correction_table
from station.core.table.grid import GridSpec
from station.core.terms.error_model import TermRows
from station.errors import IdentificationError, Outcome

__all__ = ["verified_outcome", "reversal_error", "identify_run", "run_measurements", "verification_errors", "verification_orientation_errors",
           "reference_params", "grid_for", "build_table_for", "arrival_sides", "run_term_rows"]


def _kept(records: Sequence[MeasurementRecord]) -> list[MeasurementRecord]:
    """The records :func:`run_measurements` fits (:func:`_world_heads`), in their order: valid, with a
    pose and joints read."""
    return [r for r in records if r.ok and r.pose is not None and r.joints_read is not None]


def _world_heads(cfg: CellConfig, records: Sequence[MeasurementRecord]) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """Measured KKS←MKKS poses and joints of the valid identification records."""
    index = {pid: i for i, pid in enumerate(cfg.point_ids)}
    T, q, pts = [], [], []
    for r in records:
        if not r.ok or r.pose is None or r.joints_read is None:  # as _kept
            continue
        j = index[r.point_id]
        T.append(cfg.body_points[j] @ invert(r.pose))
        q.append(r.joints_read)
        pts.append(j)
    return np.array(T), np.array(q), pts


def reversal_error(cfg: CellConfig, forward_records: Sequence[MeasurementRecord],
                   reverse_records: Sequence[MeasurementRecord],
                   recentring: Mapping[int, np.ndarray] | None = None) -> ReversalSummary | None:
    """Position difference [µm] between approaching each pose from below and from above (the
    robot's reversal error, brief §8); None without reversal measurements. A re-centred reading
    is moved back to its command (``recentring``, as in :func:`verification_errors`)."""
    index = {pid: i for i, pid in enumerate(cfg.point_ids)}
    moved = recentring or {}

    def heads(records: Sequence[MeasurementRecord]) -> dict[tuple[str, str], np.ndarray]:
        # keyed by (point, label without the direction) so each reverse step meets its forward twin
        return {(r.point_id, r.label.replace(" reverse", "")):
                head_as_commanded(cfg.body_points[index[r.point_id]] @ invert(r.pose), moved.get(r.step_index))[:3, 3]
                for r in records if r.ok and r.pose is not None}

    fwd, rev = heads(forward_records), heads(reverse_records)
    d = np.array([np.linalg.norm(fwd[k] - rev[k]) for k in sorted(fwd.keys() & rev.keys())]) * 1e3
    if not d.size:
        return None
    return ReversalSummary(n=int(d.size), rms_um=float(np.sqrt(np.mean(d**2))), max_um=float(d.max()))


def identify_run(cfg: CellConfig, records: Sequence[MeasurementRecord]) -> IdentificationResult:
    """Identification from the run's stored measurements (pose or distance objective), with the
    body's CMM uncertainty (``cfg.body_sigma``) in the weights and the σ when it is not 0."""
    return identify(cfg.model, run_measurements(cfg, records), prefer=cfg.identification.prefer or None,
                    fix=cfg.identification.fix, exclude=cfg.identification.exclude)


def run_measurements(cfg: CellConfig, records: Sequence[MeasurementRecord]) -> MeasurementSet:
    """The :class:`MeasurementSet` :func:`identify_run` fits: the valid identification records in
    their order, pose or distance objective, the body's CMM σ in the weights."""
    T, q, pts = _world_heads(cfg, records)
    if len(T) < 5:
        raise IdentificationError(
            f"only {len(T)} valid measurements on disk; check the warnings of the measurement "
            f"phase (probes out of range, residuals) and re-run")
    sig = cfg.identification.pose_sigma()
    sp = sig[0]
    if cfg.identification.objective == "pose":
        data = MeasurementSet("pose", q, T, sig)
    else:
        pos = T[:, :3, 3]
        iu = np.array(np.triu_indices(len(pos), 1)).T
        iu = iu[[pts[i] != pts[j] for i, j in iu]]
        d = np.linalg.norm(pos[iu[:, 0]] - pos[iu[:, 1]], axis=1)
        data = MeasurementSet("distance", q, d, np.sqrt(2) * sp, iu)
    if cfg.body_sigma is not None and np.any(cfg.body_sigma > 0):
        # the CMM's σ of each measurement's body point: shared by all measurements of that point;
        # the lever runs from the point's origin to the measured head frame
        idx = np.asarray(pts, dtype=int)
        data = data.with_body(idx, cfg.body_sigma, T[:, :3, 3] - cfg.body_points[idx, :3, 3])
    return data


def arrival_sides(cfg: CellConfig, q: np.ndarray, direction: int = 1) -> np.ndarray:
    """The side (±1) each joint arrives at ``q`` (``(g,)``, or ``(n, g)`` for a SCARA) from, for a
    measurement approached in ``direction`` (the plan's :class:`PlannedStep` ``.direction``): the
    sign of the joint's last move in the commanded sequence (approach pose, the pose above the
    point, the touch; :func:`~station.cell.plan.measurement_plan.all_motion_poses`), negated —
    a joint that last moved up (+) arrived from below (−1). This is the sign convention of the
    backlash term (``Δq_j = ½ b_j s_j``, b > 0: the joint stands short of where it was sent) and
    of a data file's ``approach`` columns. A SCARA's revolute joints arrive against their approach
    offset (from below in direction +1, from above in −1); its quill comes down from the travel
    height in both directions (+1), so its lost motion merges with its zero. A joint that does not
    move in the sequence keeps the side of its approach offset."""
    poses = all_motion_poses(cfg, np.asarray(q, dtype=float), direction)
    side = np.broadcast_to(-np.sign(approach_offsets(cfg, direction)), np.shape(poses[-1])).copy()
    for a, b in zip(poses[:-1], poses[1:]):  # the last move that changes a joint decides its side
        step = np.sign(np.asarray(b, dtype=float) - np.asarray(a, dtype=float))
        side = np.where(step != 0, -step, side)
    return side


def run_term_rows(cfg: CellConfig, records: Sequence[MeasurementRecord]) -> TermRows:
    """The :class:`~station.core.terms.error_model.TermRows` of the records :func:`run_measurements`
    fits, row for row: ``order`` the seconds since the first of them (``t_utc``; the row order
    when a stamp does not parse), ``approach`` the side every joint arrived from
    (:func:`arrival_sides` at the commanded joints; a reversal record was approached in direction
    −1, every other in +1, as :func:`station.cell.plan.assembly.assemble_plan` plans them)."""
    from datetime import datetime

    kept = _kept(records)
    try:
        stamps = [datetime.fromisoformat(r.t_utc[:-1][:26] if r.t_utc.endswith("Z") else r.t_utc) for r in kept]
        order: np.ndarray | None = np.array([(t - stamps[0]).total_seconds() for t in stamps]) if stamps else None
    except (AttributeError, TypeError, ValueError):
        order = None
    approach = np.array([arrival_sides(cfg, np.asarray(r.joints_commanded, dtype=float),
                                       -1 if r.kind == StepKind.REVERSAL.value else 1) for r in kept])
    return TermRows(order=order, approach=approach.reshape(len(kept), cfg.model.n_joints))


def verification_errors(cfg: CellConfig, steps: Sequence[PlannedStep], records: Sequence[MeasurementRecord],
                        recentring: Mapping[int, np.ndarray] | None = None) -> dict[tuple[str, int], np.ndarray]:
    """Per held-out pose (point id, elbow): the ``(n_cycles, 3)`` position errors [mm] of the
    measured head against its target, one row per valid cycle. ``recentring``: the run's
    re-centring displacements by step (:func:`station.cell.run.recentring.stored_recentring`); a
    re-centred reading is moved back to where the robot stood at its command, so the error is
    the robot's, not what is left after the re-centring."""
    heads = head_targets_world(cfg)
    moved = recentring or {}
    out: dict[tuple[str, int], list[np.ndarray]] = {}
    for r in records:
        if not r.ok or r.pose is None:
            continue
        st = steps[r.step_index]
        meas = head_as_commanded(cfg.body_points[st.point] @ invert(r.pose), moved.get(r.step_index))
        out.setdefault((st.point_id, st.elbow), []).append(meas[:3, 3] - heads[st.point][:3, 3])
    return {k: np.array(v) for k, v in out.items()}


def reference_params(cfg: CellConfig, judge: RunJudge) -> np.ndarray:
    """The judge's robot parameters as seen through the station's approach (a simulated cell's
    reference, :mod:`station.cell.records.judge`): every joint arrives from the same side, so half
    the reversal error is a constant joint offset (revolute joints from below, the quill from
    above), which belongs to the model of this cell's robot."""
    p = np.array(judge.params, dtype=float)
    if not cfg.model.is_scara:  # a tilted joint frame: the zero offset is folded in as C·Rz(δ)
        from station.core.kinematics.joint_offsets import apply_joint_offsets

        half = 0.5 * np.asarray(judge.backlash, dtype=float)
        return apply_joint_offsets(cfg.model, p, np.where(np.array(cfg.model.joint_types) == "revolute", -half, half))
    for k, (t, kind) in enumerate(zip(cfg.model.joint_transforms, cfg.model.joint_types)):
        direction = 1.0 if kind == "revolute" else -1.0
        p[6 * t + (5 if kind == "revolute" else 2)] -= 0.5 * judge.backlash[k] * direction
    return p


def grid_for(cfg: CellConfig) -> GridSpec:
    """The correction grid before identification: the configured one, or the station's design
    (:func:`station.cell.correction.design.design_for`). A run stores the grid its table was
    built on (``correction_grid``, refined for the identified robot where it needed it)."""
    if cfg.correction.explicit:
        return correction_grid(cfg.correction, tuple(cfg.plan.elbows))
    return design_for(cfg).grid


def build_table_for(cfg: CellConfig, params: np.ndarray, grid: GridSpec | None = None,
                    delta: Any = None) -> CorrectionTable:
    """The correction table of ``params`` on ``grid`` (default :func:`grid_for`; the controller's
    nominal model); ``delta``: joint errors beyond geometry ``q ↦ δ(q)`` the robot stands with
    (the identified terms, or a simulated cell's judge's; None: geometric)."""
    return build_correction_table(cfg.model, params, grid_for(cfg) if grid is None else grid,
                                  capacity=MAX_TABLE_VALUES, delta=delta)


def verification_orientation_errors(cfg: CellConfig, steps: Sequence[PlannedStep], records: Sequence[MeasurementRecord],
                                    recentring: Mapping[int, np.ndarray] | None = None) -> np.ndarray:
    """Orientation error [rad] ``(n,)`` of every valid verification record: the angle between the
    measured head frame and its target (a re-centred one moved back, as in :func:`verification_errors`)."""
    from station.core.kinematics.transforms import rotation_log

    heads = head_targets_world(cfg)
    moved = recentring or {}
    out = []
    for r in records:
        if not r.ok or r.pose is None:
            continue
        st = steps[r.step_index]
        meas = head_as_commanded(cfg.body_points[st.point] @ invert(r.pose), moved.get(r.step_index))
        out.append(float(np.linalg.norm(rotation_log(heads[st.point][:3, :3].T @ meas[:3, :3]))))
    return np.array(out)



#: what to do for each limit a verified run can miss (station/cell/records/missed.py)
_GAIN_HINT = ("the correction gained less than the station requires: read the report's acceptance table, check that "
              "nothing moved between the identification and the verification (set-up, body, probe head) and the "
              "identification residual, then calibrate again (the required gain is the station's, no cell setting)")
_AP_HINT = ("the worst held-out pose is farther from its target than the specification allows: check the set-up "
            "and the body's fixing and the identification residual, then calibrate again; or, where the "
            "specification allows it, raise [verification] max_ap_um")
_RP_HINT = ("RP is the robot's repeatability, which no correction changes: check the robot (backlash, brakes, "
            "warm-up) and the cell's stiffness; or, where the specification allows it, raise [verification] "
            "max_rp_um")


def missed_limits(cfg: CellConfig, summary: RunSummary, min_gain: float) -> tuple[MissedLimit, ...]:
    """The acceptance limits a verified run missed, each with the measured value, the limit, the
    setting that governs it and what to do: the gain below ``min_gain``, and ISO 9283 AP and RP of
    the worst held-out pose after correction above ``[verification]``'s limits."""
    missed: list[MissedLimit] = []
    gain, after, spec = summary.gain, summary.after, cfg.verification
    if gain is not None and gain < min_gain:
        missed.append(MissedLimit("min_gain", "the improvement ratio (RMS before / RMS after)", float(gain),
                                  float(min_gain), "×", "the station's required gain (Options.min_gain)", _GAIN_HINT,
                                  at_least=True))
    if after is not None and spec.max_ap_um is not None and after.ap_max_um > spec.max_ap_um:
        missed.append(MissedLimit("max_ap_um", "AP after correction at its worst pose", float(after.ap_max_um),
                                  float(spec.max_ap_um), "µm", "[verification] max_ap_um", _AP_HINT))
    if after is not None and spec.max_rp_um is not None and after.rp_max_um is not None \
            and after.rp_max_um > spec.max_rp_um:
        missed.append(MissedLimit("max_rp_um", "RP after correction at its worst pose", float(after.rp_max_um),
                                  float(spec.max_rp_um), "µm", "[verification] max_rp_um", _RP_HINT))
    return tuple(missed)


def verified_outcome(cfg: CellConfig, summary: RunSummary, min_gain: float) -> tuple[Outcome, tuple[str, ...]]:
    """A verified run's outcome: SUCCESS when the gain reaches ``min_gain`` and the held-out poses
    meet ``[verification]``'s accuracy specification (ISO 9283 AP and RP of every pose after
    correction, where configured); else TARGET_MISSED, with a note for each limit of the
    specification missed (the gain stands in the run's figures; :func:`missed_limits` has all)."""
    missed = missed_limits(cfg, summary, min_gain)
    notes = tuple(m.note for m in missed if m.id != "min_gain")
    ok = summary.gain is not None and not missed
    return (Outcome.SUCCESS if ok else Outcome.TARGET_MISSED), notes
