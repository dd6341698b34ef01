"""Per-tool corrections: the working tools that replace the probe head after a calibration
(``[[tool]]`` in the cell configuration; chapter §7.2, ``docs/correction.md`` "Tools after the head").

For each configured tool the station derives the tool on the identified robot
(:func:`station.core.kinematics.tool_frame.derive_tool`: ``K_tool = K_id · H⁻¹ · T``, ``H`` the head in the
flange frame, ``T`` the tool's TCP) and builds the tool's own correction for the controller's
nominal model with that tool (``K_nom · H⁻¹ · T``):

* a SCARA: a correction table on the tool's grid (``[correction]`` with the tool's overrides),
  :func:`station.core.table.build.build_correction_table`;
* other robots: compensated targets (:mod:`station.core.kinematics.compensation`) for the tool's
  verification targets.

The verification targets of a tool are the plan's held-out verification poses re-expressed as
where the tool's TCP is at the same joints: the nominal forward kinematics of those joints with
the tool's nominal K (robot base frame), placed in the body frame with the identified set-up.

Figures per tool (:func:`evaluate_tools`):

* always: what the head's correction (its table used as it is) would leave at the tool's targets,
  *predicted* from the identified model (the reason to switch tables when the tool goes on);
* in simulation (a judge knows the simulated robot, ``station.cell.records.judge``): the real robot's position error at the tool's
  targets with the tool's own correction, with the oracle's (the correction built from the true
  parameters with the true ``K_tool = K_true · H⁻¹ · T``) and with the head's correction. The
  real robot's joints scatter with the simulator's repeatability over
  ``[plan].verification_cycles`` cycles per target (the same scatter for all three), as the
  head's own verification does; nothing moves for it.

Error terms beyond geometry (issue 30, ``docs/error-terms.md``): a run that kept terms builds
every tool's correction with them, on the geometry fitted with them (``params``) and their joint
error ``delta`` ``q ↦ δ(q)`` — the joints' errors are the robot's, the same whatever tool it carries
(the SCARA table's nodes carry them, other robots' targets are compensated with them,
:func:`station.core.terms.compensation.compensated_targets_with_terms`). Compliance is the one term
that depends on the load: ``[[tool]]`` has no mass, so the terms are those identified with the
probe head (the head's payload is assumed). In simulation the simulated robot stands at
``q + δ_ref(q)`` when the judge knows joint errors (``RunJudge.reference_delta``), and the
reference (oracle's) correction is built with them too.

Nothing here uploads: the head's table stays the one the pipeline uploads; ``station export
--tool NAME`` writes a tool's table for the controller (a run with terms: rebuilt with its stored
error model, :mod:`station.cell.records.reading.stored_error_model`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from drivers.controller_map import MAX_TABLE_VALUES
from station.cell.config.cell_config import CellConfig
from station.cell.config.sections import ToolConfig
from station.cell.correction.design import head_in_flange, tool_grid_for
from station.cell.plan.steps import PlannedStep
from station.cell.records.judge import RunJudge
from station.cell.records.rundb import RunDB
from station.cell.records.summary import ToolSummary
from station.cell.run.facts.events import Event, Notice
from station.core.kinematics.compensation import compensated_targets
from station.core.kinematics.forward import forward, inverse_kinematics, scara_ik
from station.core.kinematics.model import RobotModel
from station.core.kinematics.tool_frame import (
    ToolKinematics,
    derive_tool,
    tool_params,
    tool_transform,
)
from station.core.kinematics.transforms import invert, matrix_to_pose, pose_to_matrix
from station.core.table.build import CorrectionTable, build_correction_table
from station.core.table.grid import GridSpec
from station.core.table.values import CorrectionTableData, TableRangeError, interpolate_table
from station.core.terms.compensation import JointDelta, commanded_joints, compensated_targets_with_terms
from station.errors import ConfigError, StationError, UnreachableError

__all__ = [
    "ToolCorrection",
    "ToolEvaluation",
    "ToolTargets",
    "build_tool_correction",
    "check_tools",
    "evaluate_tools",
    "find_tool",
    "head_in_flange",
    "result_key",
    "run_tools",
    "tool_grid",
    "tool_targets",
    "judge_delta",
]

#: a SCARA table corrects x, y, z and yaw of a tool whose axis is parallel to the last joint's
MAX_SCARA_TOOL_TILT_DEG = 10.0
#: salt of the seeded joint scatter of the simulated tool verification
_SCATTER_SALT = 0x7001


def result_key(name: str) -> str:
    """The run-database result key of a tool's correction and figures."""
    return f"tool:{name}"


def find_tool(cfg: CellConfig, name: str) -> ToolConfig:
    """The configured tool called ``name``; :class:`ConfigError` naming the configured ones."""
    for t in cfg.tools:
        if t.name == name:
            return t
    have = ", ".join(repr(t.name) for t in cfg.tools) or "none"
    raise ConfigError(f"no tool {name!r} in the configuration (configured: {have}); add a [[tool]] table "
                      f"with name = {name!r} and its tcp")


def tool_grid(cfg: CellConfig, tool: ToolConfig) -> GridSpec:
    """The grid of the tool's table: ``[correction]``'s grid (configured or designed) with the
    tool's own x_mm / y_mm / z_mm."""

    return tool_grid_for(cfg, tool)


def check_tools(cfg: CellConfig) -> None:
    """Before anything moves: every tool can be corrected on this robot. For a SCARA the tool's
    axis must be parallel to the last joint's (within :data:`MAX_SCARA_TOOL_TILT_DEG`): its table
    corrects x, y, z and yaw, and a tilted TCP frame has no yaw the controller and the table share."""
    if not cfg.model.is_scara:
        return
    H = head_in_flange(cfg)
    K = pose_to_matrix(cfg.model.nominal[-6:])
    for t in cfg.tools:
        R = tool_transform(K, H, t.tcp_matrix)[:3, :3]
        tilt = float(np.degrees(np.arccos(np.clip(R[2, 2], -1.0, 1.0))))
        if tilt > MAX_SCARA_TOOL_TILT_DEG:
            raise ConfigError(
                f"tool {t.name!r}: its TCP frame's z axis is tilted {tilt:.1f} deg against the robot's last axis "
                f"(at most {MAX_SCARA_TOOL_TILT_DEG:g} deg): a SCARA's correction table corrects x, y, z and yaw "
                f"of a tool along its last axis. Give [[tool]].tcp roll and pitch in the flange frame so that the "
                f"TCP's z axis runs along the last axis (check the head file's flange frame)")


# --------------------------------------------------------------------------------------------
# targets
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class ToolTargets:
    """The tool's verification targets. ``joints`` ``(n, g)`` [rad | mm]: the plan's held-out
    verification joints; ``elbows`` ``(n,)`` ±1; ``labels`` ``(n,)`` "<point> elbow ±1";
    ``base`` ``(n, 4, 4)``: the TCP there with the nominal tool, robot base frame [mm];
    ``world`` ``(n, 4, 4)``: the same in the body frame through the identified set-up."""

    joints: np.ndarray
    elbows: np.ndarray
    labels: tuple[str, ...]
    base: np.ndarray
    world: np.ndarray


def _verification_poses(steps: Sequence[PlannedStep]) -> list[PlannedStep]:
    seen: set[tuple[int, int]] = set()
    out = []
    for st in steps:
        if st.kind.is_verification and (st.point, st.elbow) not in seen:
            seen.add((st.point, st.elbow))
            out.append(st)
    return out


def tool_targets(kin: ToolKinematics, steps: Sequence[PlannedStep], setup: np.ndarray) -> ToolTargets:
    """The tool's verification targets (see :class:`ToolTargets`); ``setup`` ``(6,)``: the
    identified set-up R [mm, rad]."""
    poses = _verification_poses(steps)
    g = kin.nominal.n_joints
    q = np.array([st.q for st in poses], dtype=float).reshape(-1, g)
    base = forward(kin.nominal, q, setup=False) if len(q) else np.zeros((0, 4, 4))
    return ToolTargets(q, np.array([st.elbow for st in poses], dtype=int),
                       tuple(f"{st.point_id} elbow {st.elbow:+d}" for st in poses),
                       base, pose_to_matrix(np.asarray(setup, dtype=float)) @ base)


# --------------------------------------------------------------------------------------------
# the correction of one tool
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class ToolCorrection:
    """One tool's correction. ``kin``: the tool on the identified robot; ``table``: its
    correction table (SCARA) or None; ``commands`` ``(n, 4, 4)``: compensated Cartesian targets
    for its verification targets (other robots) or None; ``targets``: those targets."""

    tool: ToolConfig
    kin: ToolKinematics
    targets: ToolTargets
    table: CorrectionTable | None = None
    commands: np.ndarray | None = None
    commanded_joints: np.ndarray | None = None
    #: the error terms' joint error it was built with (None: geometric)
    delta: JointDelta | None = None

    @property
    def with_terms(self) -> bool:
        """Built with error terms beyond geometry (a table's nodes or the targets carry them)."""
        return self.delta is not None or (self.table is not None and self.table.with_terms)

    @property
    def kind(self) -> str:
        return "table" if self.table is not None else "targets"


def build_tool_correction(cfg: CellConfig, tool: ToolConfig, params: np.ndarray,
                          steps: Sequence[PlannedStep], delta: JointDelta | None = None) -> ToolCorrection:
    """The tool's correction from the identified ``params`` ``(n_params,)`` [mm, rad]: a table on
    the tool's grid for a SCARA, compensated targets for its verification targets otherwise.
    ``delta``: the identified error terms' joint error ``q ↦ δ(q)`` (the robot commanded ``q``
    stands at ``q + δ(q)``; ``params`` then the geometry fitted with them), None: geometric."""
    kin = derive_tool(cfg.model, params, head_in_flange(cfg), tool.tcp_matrix)
    targets = tool_targets(kin, steps, np.asarray(params, dtype=float)[:6])
    if cfg.model.is_scara:
        try:
            table = build_correction_table(kin.nominal, kin.params, tool_grid(cfg, tool), capacity=MAX_TABLE_VALUES,
                                           delta=delta)
        except ConfigError as exc:
            raise ConfigError(f"tool {tool.name!r}: {exc} ([[tool]] x_mm, y_mm, z_mm give the tool its own grid)") from None
        return ToolCorrection(tool, kin, targets, table=table, delta=delta)
    if not len(targets.joints):
        return ToolCorrection(tool, kin, targets, commands=np.zeros((0, 4, 4)), commanded_joints=targets.joints,
                              delta=delta)
    comp = (compensated_targets(kin.nominal, kin.params, targets.base, targets.joints) if delta is None
            else compensated_targets_with_terms(kin.nominal, kin.params, delta, targets.base, q0=targets.joints))
    return ToolCorrection(tool, kin, targets, commands=comp.commands, commanded_joints=comp.joints, delta=delta)


# --------------------------------------------------------------------------------------------
# what the controller commands, and where the robot ends
# --------------------------------------------------------------------------------------------

def _in_grid(data: CorrectionTableData, point: np.ndarray) -> bool:
    for k, a in enumerate(data.axes):
        if a.periodic or a.count == 1:
            continue
        u = (point[k] - a.start) / a.step
        if u < -1e-6 or u > a.count - 1 + 1e-6:
            return False
    return True


def _scara_commands(nominal: RobotModel, X: np.ndarray, elbows: np.ndarray,
                    data: CorrectionTableData | None, table_elbows: tuple[int, ...]) -> np.ndarray:
    """Joints ``(n, g)`` the controller commands for base-frame targets ``X`` with the table
    ``data`` active (NaN rows: outside the table's grid or out of reach)."""
    q = np.full((len(X), nominal.n_joints), np.nan)
    for i, (T, e) in enumerate(zip(X, elbows)):
        p = matrix_to_pose(T)
        pt = np.array([p[0], p[1], p[2], p[5]])
        if data is not None and (int(e) not in table_elbows or not _in_grid(data, pt)):
            continue  # the controller refuses a target outside the active table's grid
        try:
            qi = scara_ik(nominal, T[None], int(e), setup=False, check_limits=False)[0]
        except (UnreachableError, np.linalg.LinAlgError):
            continue
        if data is not None:
            try:
                qi = qi + interpolate_table(data, pt[None], table_elbows.index(int(e)))[0]
            except TableRangeError:
                continue
        q[i] = qi
    return q


def _exact_correction_joints(nominal: RobotModel, params: np.ndarray, X: np.ndarray, q0: np.ndarray,
                             delta: JointDelta | None = None) -> np.ndarray:
    """Joints ``(n, g)`` that put the robot ``params`` (standing at ``q + delta(q)``) on ``X``
    (compensated targets; NaN rows where it cannot reach one)."""
    q = np.full((len(X), nominal.n_joints), np.nan)
    for i in range(len(X)):
        try:
            q[i] = (compensated_targets(nominal, params, X[i:i + 1], q0[i:i + 1]) if delta is None else
                    compensated_targets_with_terms(nominal, params, delta, X[i:i + 1], q0=q0[i:i + 1])).joints[0]
        except (UnreachableError, np.linalg.LinAlgError):
            continue
    return q


def _head_correction_joints(cfg: CellConfig, kin: ToolKinematics, p_head: np.ndarray, X: np.ndarray,
                            q0: np.ndarray, elbows: np.ndarray, head_table: CorrectionTable | None,
                            delta: JointDelta | None = None) -> np.ndarray:
    """Joints the controller commands for the tool's targets with the HEAD's correction as it is:
    its table (SCARA); for other robots the head's joint correction at the nominal tool's joints
    ``q_n = IK_nom_tool(x)``: the joints that put the identified head (standing at ``q + delta(q)``
    with error terms) where the nominal head is at ``q_n`` (the head is corrected there, the tool's
    own lever is not)."""
    if cfg.model.is_scara:
        if head_table is None:
            return np.full((len(X), kin.nominal.n_joints), np.nan)
        return _scara_commands(kin.nominal, X, elbows, head_table.data, head_table.elbows)
    q = np.full((len(X), kin.nominal.n_joints), np.nan)
    for i in range(len(X)):
        try:
            q_n = inverse_kinematics(kin.nominal, X[i:i + 1], q0[i:i + 1])
            q_geo = inverse_kinematics(cfg.model, forward(cfg.model, q_n, setup=False), q_n, params=p_head)
            q[i] = q_geo[0] if delta is None else commanded_joints(q_geo, delta)[0][0]
        except (UnreachableError, np.linalg.LinAlgError):
            continue
    return q


def _errors(model: RobotModel, p_real: np.ndarray, q_cmd: np.ndarray, world: np.ndarray,
            scatter: np.ndarray, delta: JointDelta | None = None) -> np.ndarray:
    """``(n, cycles)`` position error [µm] of the robot ``p_real`` (set-up included) driven to
    ``q_cmd`` — standing at ``q_cmd + delta(q_cmd)`` where it has joint errors beyond geometry —
    plus each cycle's joint scatter ``scatter`` ``(cycles, n, g)``, against ``world`` (NaN rows
    where nothing was commanded)."""
    out = np.full((len(q_cmd), scatter.shape[0]), np.nan)
    ok = np.all(np.isfinite(q_cmd), axis=1)
    if ok.any():
        stands = q_cmd[ok] if delta is None else q_cmd[ok] + delta(q_cmd[ok])
        reached = forward(model, stands[None] + scatter[:, ok], p_real)  # (cycles, m, 4, 4)
        d = reached[..., :3, 3] - world[ok][None, :, :3, 3]
        out[ok] = np.linalg.norm(d, axis=-1).T * 1e3
    return out


def _rms_max(e: np.ndarray | None) -> tuple[float | None, float | None, int]:
    if e is None:
        return None, None, 0
    rows = e[np.all(np.isfinite(e), axis=1)]
    if not rows.size:
        return None, None, 0
    return float(np.sqrt(np.mean(rows**2))), float(rows.max()), int(rows.shape[0])


@dataclass(frozen=True, eq=False)
class ToolEvaluation:
    """One tool's correction and figures. Error arrays ``(n_targets, cycles)`` [µm], NaN rows for
    targets a correction does not cover; None where unknown (no judge: a real cell)."""

    correction: ToolCorrection
    head_predicted_um: np.ndarray
    own_um: np.ndarray | None = None
    oracle_um: np.ndarray | None = None
    head_um: np.ndarray | None = None
    notes: tuple[str, ...] = field(default=())

    def summary(self) -> ToolSummary:
        c = self.correction
        t = c.tool
        own_rms, own_max, n_own = _rms_max(self.own_um)
        or_rms, or_max, _ = _rms_max(self.oracle_um)
        hd_rms, hd_max, n_head = _rms_max(self.head_um)
        pr_rms, pr_max, n_pred = _rms_max(self.head_predicted_um)
        tcp = (*(float(v) for v in t.tcp[:3]), *(float(np.degrees(v)) for v in t.tcp[3:]))
        return ToolSummary(
            name=t.name, tcp_mm_deg=tcp, kind=c.kind, n_targets=len(c.targets.labels),
            crc32=f"{c.table.data.crc32():08x}" if c.table is not None else None,
            n_values=int(c.table.data.n_values) if c.table is not None else None,
            interpolation_bound_um=float(c.table.interpolation_bound_um) if c.table is not None else None,
            flange_shift_um=c.kin.flange_shift_um, flange_rotation_arcsec=c.kin.flange_rotation_arcsec,
            head_predicted_rms_um=pr_rms, head_predicted_max_um=pr_max,
            after_rms_um=own_rms, after_max_um=own_max, oracle_rms_um=or_rms, oracle_max_um=or_max,
            head_rms_um=hd_rms, head_max_um=hd_max, n_after=n_own, n_head=n_head)

    def result(self) -> dict[str, Any]:
        """The run-database result (``tool:<name>``): JSON types, units in the keys."""
        c = self.correction
        s = self.summary()
        out: dict[str, Any] = {
            "name": s.name, "tcp_mm_deg": list(s.tcp_mm_deg), "kind": c.kind,
            "tool_params_identified": [float(v) for v in c.kin.params],
            "tool_params_nominal": [float(v) for v in c.kin.nominal.nominal],
            "flange_identified_pose_mm_rad": [float(v) for v in matrix_to_pose(c.kin.flange_identified)],
            "flange_nominal_pose_mm_rad": [float(v) for v in matrix_to_pose(c.kin.flange_nominal)],
            "flange_shift_um": s.flange_shift_um, "flange_rotation_arcsec": s.flange_rotation_arcsec,
            "targets": list(c.targets.labels),
            "head_predicted_um": _listed(self.head_predicted_um),
            "after_um": _listed(self.own_um), "oracle_um": _listed(self.oracle_um), "head_um": _listed(self.head_um),
            "summary": _json_summary(s), "notes": list(self.notes),
            "error_terms": c.with_terms}  # built with the run's error terms (its stored error_model)
        if c.table is not None:
            out["table"] = c.table.summary()
        if c.commands is not None:
            out["commands_pose_mm_rad"] = [[float(v) for v in matrix_to_pose(T)] for T in c.commands]
        return out


def _listed(e: np.ndarray | None) -> list[list[float | None]] | None:
    if e is None:
        return None
    return [[None if not np.isfinite(v) else float(v) for v in row] for row in e]


def _json_summary(s: ToolSummary) -> dict[str, Any]:
    import dataclasses

    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in dataclasses.asdict(s).items()}


def _scatter(judge: RunJudge | None, n: int, g: int, cycles: int) -> np.ndarray:
    """``(cycles, n, g)`` seeded joint scatter with the simulated robot's repeatability σ per joint."""
    sigma = np.asarray(getattr(judge, "repeatability", np.zeros(g)), dtype=float).reshape(-1)
    if sigma.shape != (g,):
        sigma = np.zeros(g)
    rng = np.random.default_rng([int(getattr(judge, "seed", 0)), _SCATTER_SALT])
    return rng.normal(0.0, 1.0, (cycles, n, g)) * sigma


def judge_delta(judge: RunJudge | None) -> JointDelta | None:
    """The simulated robot's joint errors as ``Δq(q)`` at the commanded joints, or None without
    them (a real cell: no judge; a simulated arm with ``joint_errors = "none"``): what the
    reference correction and the simulated tool figures know of the robot (``RunJudge.reference_delta``)."""
    return None if judge is None else judge.reference_delta()


def evaluate_tool(cfg: CellConfig, tool: ToolConfig, params: np.ndarray, steps: Sequence[PlannedStep],
                  head_table: CorrectionTable | None, p_ref: np.ndarray | None = None,
                  judge: RunJudge | None = None, delta: JointDelta | None = None) -> ToolEvaluation:
    """One tool: its correction, the head correction's predicted error at its targets, and — with
    the reference parameters ``p_ref`` ``(n_params,)`` (simulation; ``judge`` the simulated cell's
    :class:`~station.cell.records.judge.RunJudge` for the repeatability and its joint errors, under
    which the simulated robot stands at ``q + δ_ref(q)``) — the simulated robot's errors with its
    own, the reference (oracle's) and the head's correction. ``delta``: the identified error terms' joint error (``params`` the
    geometry fitted with them), which the tool's correction, the head's and the prediction carry."""
    p_id = np.asarray(params, dtype=float)
    corr = build_tool_correction(cfg, tool, p_id, steps, delta)
    kin, tg = corr.kin, corr.targets
    n, g = len(tg.labels), cfg.model.n_joints
    notes: list[str] = []
    if n == 0:
        empty = np.zeros((0, 1))
        return ToolEvaluation(corr, empty, notes=("the plan has no verification poses",))
    H = head_in_flange(cfg)
    scara = cfg.model.is_scara
    # the commands with the tool's own correction (base frame of the identified chain)
    own_table = corr.table
    if own_table is not None:
        q_own = _scara_commands(kin.nominal, tg.base, tg.elbows, own_table.data, own_table.elbows)
        if own_table.interpolation_bound_um > tool.correction.max_interpolation_um:
            notes.append(f"its table interpolates with up to {own_table.interpolation_bound_um:.1f} µm, above "
                         f"correction.max_interpolation_um = {tool.correction.max_interpolation_um:g} (the bound "
                         f"covers the whole grid; a finer or smaller grid for this tool: [[tool]] x_mm, y_mm, z_mm)")
        if head_table is not None and head_table.grid != own_table.grid:
            # the head's correction as it is, on the tool's grid so that it covers the tool's targets
            head_table = build_correction_table(cfg.model, p_id, own_table.grid, capacity=MAX_TABLE_VALUES,
                                                delta=head_table.delta)
    else:
        assert corr.commanded_joints is not None
        q_own = corr.commanded_joints
    with_head = head_table is not None or not scara  # a SCARA's head correction is its table
    q_head = _head_correction_joints(cfg, kin, p_id, tg.base, tg.joints, tg.elbows, head_table, delta)
    outside = int(np.sum(~np.all(np.isfinite(q_own), axis=1)))
    if outside:
        notes.append(f"{outside} of {n} targets lie outside the tool's grid or reach and are not counted")
    missed_head = int(np.sum(~np.all(np.isfinite(q_head), axis=1) & np.all(np.isfinite(q_own), axis=1)))
    if missed_head and with_head:
        notes.append(f"{missed_head} of its targets are out of the head's correction's reach; the head's "
                     f"figures leave them out")
    no_scatter = np.zeros((1, n, g))
    # what the identified model says the head's correction leaves for this tool (a real cell's figure)
    head_predicted = _errors(cfg.model, kin.params, q_head, tg.world, no_scatter, delta)
    if p_ref is None:
        return ToolEvaluation(corr, head_predicted, notes=tuple(notes))
    p_ref = np.asarray(p_ref, dtype=float)
    p_ref_tool = tool_params(cfg.model, p_ref, H, tool.tcp_matrix)
    ref_delta = judge_delta(judge)  # the simulated robot's joints err: it stands at q + δ_ref(q)
    X_oracle = invert(pose_to_matrix(p_ref[:6]))[None] @ tg.world
    if scara:  # the oracle knows what the simulator knows: its table carries the true joint errors
        oracle_table = build_correction_table(kin.nominal, p_ref_tool, tool_grid(cfg, tool), capacity=MAX_TABLE_VALUES,
                                              delta=ref_delta)
        q_oracle = _scara_commands(kin.nominal, X_oracle, tg.elbows, oracle_table.data, oracle_table.elbows)
    else:
        q_oracle = _exact_correction_joints(kin.nominal, p_ref_tool, X_oracle, tg.joints, ref_delta)
    scatter = _scatter(judge, n, g, max(int(cfg.plan.verification_cycles), 1))
    own = _errors(cfg.model, p_ref_tool, q_own, tg.world, scatter, ref_delta)
    oracle = _errors(cfg.model, p_ref_tool, q_oracle, tg.world, scatter, ref_delta)
    head = _errors(cfg.model, p_ref_tool, q_head, tg.world, scatter, ref_delta) if with_head else None
    return ToolEvaluation(corr, head_predicted, own, oracle, head, tuple(notes))


def evaluate_tools(cfg: CellConfig, params: np.ndarray, steps: Sequence[PlannedStep],
                   head_table: CorrectionTable | None, p_ref: np.ndarray | None = None,
                   judge: RunJudge | None = None, delta: JointDelta | None = None) -> tuple[ToolEvaluation, ...]:
    """:func:`evaluate_tool` for every configured tool, in the configuration's order."""
    return tuple(evaluate_tool(cfg, t, params, steps, head_table, p_ref, judge, delta) for t in cfg.tools)



def run_tools(cfg: CellConfig, db: RunDB, run_id: int, steps: Sequence[PlannedStep], params: np.ndarray,
              head_table: CorrectionTable | None, p_ref: np.ndarray | None, judge: RunJudge | None,
              emit: Callable[[Event], None], delta: JointDelta | None = None) -> tuple[ToolSummary, ...]:
    """The pipeline's step after the head's table: every tool's correction and figures, stored as
    ``tool:<name>`` results; returns their summaries. Nothing is uploaded. With error terms kept,
    ``params`` is the geometry fitted with them and ``delta`` their joint error (as for the head)."""
    out = []
    for tool in cfg.tools:
        try:
            ev = evaluate_tool(cfg, tool, params, steps, head_table, p_ref, judge, delta)
        except (StationError, np.linalg.LinAlgError, ValueError) as exc:  # a tool never stops the head's run
            emit(Notice("warning", f"tool {tool.name!r}: no correction was built ({exc}); the head's calibration "
                                   f"goes on"))
            db.save_result(run_id, result_key(tool.name), {"name": tool.name, "error": str(exc)})
            continue
        s = ev.summary()
        db.save_result(run_id, result_key(s.name), ev.result())
        what = (f"table {s.crc32}, interpolation bound {s.interpolation_bound_um:.1f} µm"
                if s.crc32 is not None and s.interpolation_bound_um is not None else f"{s.n_targets} compensated targets")
        line = f"tool {s.name!r}: own correction built ({what}{', with the error terms' if ev.correction.with_terms else ''})"
        if s.head_predicted_rms_um is not None:
            line += f"; the head's correction would leave {s.head_predicted_rms_um:.1f} µm RMS at its targets"
        if s.after_rms_um is not None and s.oracle_rms_um is not None:
            line += f"; simulated: {s.after_rms_um:.1f} µm with its own, {s.oracle_rms_um:.1f} µm with the oracle's"
            if s.head_rms_um is not None:
                line += f", {s.head_rms_um:.1f} µm with the head's"
        emit(Notice("info", line + f". 'station export --tool {s.name}' writes its table"
                    if s.kind == "table" else line))
        for n in ev.notes:
            emit(Notice("warning", f"tool {s.name!r}: {n}"))
        out.append(s)
    return tuple(out)
