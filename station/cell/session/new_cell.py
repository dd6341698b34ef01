"""``station init CONFIG --robot R --head H --body B``: a configuration derived from the cell's
own files (issue 27), so that ``station plan`` and ``station calibrate --simulated`` work on it
at the first try.

From the files: the robot's limits (its soft limits 2 % of each range inside them), the head's
real stroke (in the comments and in ``recenter_margin_mm``), the body's cube edge (the shortest
distance between two corners of one cube). Derived:

* ``[robot] setup``: a guess of where the robot stands, the body in front of it (the body's
  centroid on the base x axis), at the distance and height where the most (point, elbow) pairs
  can be measured within the soft limits (the plan decides, as it will before the run);
* ``[plan] repeats`` and ``verification_cycles``: the fewest repeats whose predicted accuracy
  (the plan's linear propagation plus the robot's repeatability) shows the gain the run must
  show (``min_gain``, 20×) with a margin of 1.5 against the error a robot of the configured error
  size has before calibration; enough cycles for 50 verification readings;
* ``[correction]``: no grid keys, the station designs it; the design is quoted in a comment.

Everything is computed, nothing moves; the result is a text the caller writes.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from station.cell.config.cell_config import CellConfig, parse_text
from station.cell.config.template import TEMPLATE
from station.errors import ConfigError

__all__ = ["NewCell", "new_cell_text", "MIN_GAIN"]

#: the gain a run must show (the pipeline's Options.min_gain)
MIN_GAIN = 20.0
#: the predicted gain must exceed MIN_GAIN by this factor
GAIN_MARGIN = 1.5
#: verification readings (poses × cycles) enough for the RMS to be known to about ±10 %
VERIFICATION_READINGS = 50
#: a placement keeps every verification target within this fraction of the arm's reach where it
#: can: towards the stretched arm the correction bends too much for a table of 32 000 values
STRETCH = 0.85


@dataclass(frozen=True)
class NewCell:
    """The configuration text and what ``station init`` tells the user about it."""

    text: str
    notes: tuple[str, ...]


#: the position σ init writes for a cell with a head [µm]: the head's reading noise on a robot
#: whose repeatability σ is about ASSUMED_REPEATABILITY_UM per axis; where the robot file states
#: its RP, the fit adds that and init writes the head's part alone, HEAD_SIGMA_UM
ASSUMED_SIGMA_UM = 6.0
ASSUMED_REPEATABILITY_UM = 5.0
HEAD_SIGMA_UM = round(math.sqrt(ASSUMED_SIGMA_UM ** 2 - ASSUMED_REPEATABILITY_UM ** 2), 1)


def _kv(setting: str, comment: str) -> str:
    """A template line: the setting, its comment at the template's column."""
    return f"{setting:<32} # {comment}"


def _set(text: str, pattern: str, repl: str) -> str:
    out, n = re.subn(pattern, lambda _m: repl, text, count=1, flags=re.MULTILINE)
    if n != 1:  # pragma: no cover - the template changed under this module
        raise AssertionError(f"the template has no line matching {pattern!r}")
    return out


def _rel(path: str, dest: Path) -> str:
    p = Path(path)
    if not p.exists():
        raise ConfigError(f"{path}: no such file")
    try:
        return os.path.relpath(p.resolve(), dest.resolve().parent)
    except ValueError:  # another drive
        return str(p.resolve())


def _cube_edge(body: str) -> float:
    """The shortest distance between two corners of one cube (ids ``<cube>.<corner>``), else 40 mm."""
    from station.io.body_file import read_body_file

    report = read_body_file(body)
    groups: dict[str, list[np.ndarray]] = {}
    for pid, pose in zip(report.ids, report.poses):
        groups.setdefault(re.sub(r"[._-]?[A-Za-z0-9]$", "", pid), []).append(np.asarray(pose[:3], dtype=float))
    best = math.inf
    for pts in groups.values():
        for i in range(len(pts)):
            for j in range(i + 1, len(pts)):
                best = min(best, float(np.linalg.norm(pts[i] - pts[j])))
    return round(best, 1) if math.isfinite(best) and best > 1.0 else 40.0


def _limits_line(model) -> str:
    lim = np.asarray(model.joint_limits, dtype=float)
    pairs = []
    for (lo, hi), kind in zip(lim, model.joint_types):
        pad = 0.02 * (hi - lo)
        lo, hi = lo + pad, hi - pad
        if kind == "revolute":
            lo, hi = math.degrees(lo), math.degrees(hi)
        pairs.append(f"[{lo:.1f}, {hi:.1f}]")
    return "joints = [" + ", ".join(pairs) + "]"


def _with_setup(text: str, setup: np.ndarray) -> str:
    return _set(text, r"^setup = \[.*\]$", "setup = [" + ", ".join(f"{v:.1f}" for v in setup) + "]")


def _try(text: str, dest: Path) -> tuple[CellConfig, object] | None:
    """The configuration and its plan, or None when the plan cannot be made."""
    from station.cell.plan.measurement_plan import build_plan

    try:
        cfg = parse_text(text, str(dest))
        return cfg, build_plan(cfg)
    except ConfigError:
        return None


def _quill_shift(cfg: CellConfig, setup: np.ndarray) -> float:
    """How far [mm] to raise the set-up's z so that the quill's joint values of every measuring
    point, with the clearance above (its last repetition's) and the approach, sit in the middle
    of the quill's soft range."""
    from station.cell.plan.measurement_plan import point_joints

    m = cfg.model
    j = next((k for k, t in enumerate(m.joint_types) if t == "prismatic"), None)
    if j is None:
        return 0.0
    import dataclasses

    c = dataclasses.replace(cfg, model=m.with_setup(setup))
    q = point_joints(c, cfg.plan.elbows[0])[:, j]
    q = q[np.isfinite(q)]
    if not q.size:
        return 0.0
    lo, hi = (float(v) for v in cfg.soft_limits[j])
    last = max(cfg.plan.repeats, cfg.plan.verification_cycles) - 1
    # the verification's Cartesian targets follow the identified set-up: 3 σ of its z as room
    room = 3.0 * float(getattr(cfg.simulation, "setup_sigma_mm", 1.5) or 1.5) + 1.0
    top = cfg.plan.clearance_mm * (1.0 + 0.1 * last) * 1.05 + room
    bottom = cfg.plan.approach_mm * (1.0 + 0.25 * last) + room
    low, high = lo + bottom, hi - top  # where every point's quill value must lie
    if high - low >= float(q.max() - q.min()):
        want = 0.5 * ((low - float(q.min())) + (high - float(q.max())))  # all fit: centred
    else:  # not all fit: the shift that keeps the most points inside (the plan names the others)
        shifts = low - np.sort(q)
        inside = [int(np.sum((q + d >= low - 1e-9) & (q + d <= high + 1e-9))) for d in shifts]
        want = float(shifts[int(np.argmax(inside))])
    q0 = np.zeros((2, m.n_joints))
    q0[1, j] = 1.0
    from station.core.kinematics.forward import forward

    z = forward(m, q0, setup=False)[:, 2, 3]
    slope = float(z[1] - z[0]) or 1.0
    return -want * slope  # q = (z_target - setup_z - z0) / slope


def _placement(text: str, dest: Path, cfg: CellConfig) -> tuple[np.ndarray, str]:
    """The set-up guess whose plan measures the most (point, elbow) pairs (then: nearest the
    middle of the arm's annulus), the quill centred on the points' heights, and a line saying
    how many it measures."""
    from station.cell.plan.assembly import head_targets_world
    from station.core.kinematics.transforms import invert, pose_to_matrix

    m = cfg.model
    heads = head_targets_world(cfg)[:, :3, 3]
    centre = heads.mean(axis=0)
    P = np.asarray(m.nominal, dtype=float).reshape(-1, 6)
    l1, l2 = float(np.hypot(*P[2, :2])), float(np.hypot(*P[3, :2]))
    r_in, r_out = abs(l1 - l2), l1 + l2
    best: tuple[tuple[float, ...], np.ndarray, str] | None = None
    for frac in np.linspace(0.3, 0.85, 12):
        r = r_in + frac * (r_out - r_in)
        setup = np.array([centre[0] - r, centre[1], float(m.nominal[2]), 0.0, 0.0, 0.0])
        setup[2] += _quill_shift(cfg, setup)
        got = _try(_with_setup(text, setup), dest)
        if got is None:
            continue
        c, plan = got
        rejected = len(plan.rejected)  # type: ignore[attr-defined]
        n = 2 * len(c.point_ids) if len(c.plan.elbows) == 2 else len(c.point_ids)
        # the correction bends most near the stretched arm: verification targets within STRETCH of the reach
        base = invert(pose_to_matrix(setup))[None] @ np.array([t.head_world for t in plan.verification])  # type: ignore[attr-defined]
        far = float(np.max(np.hypot(base[:, 0, 3], base[:, 1, 3]))) / r_out if len(base) else 0.0
        score = (float(far <= STRETCH), -float(rejected), -abs(float(frac) - 0.55))
        line = (f"the body's centroid {r:.0f} mm from the robot's axis 1: {n - rejected} of {n} (point, elbow) pairs "
                f"measured" + (f", {rejected} out of reach or the soft limits ('station plan' names them)" if rejected else ""))
        if best is None or score > best[0]:
            best = (score, setup, line)
    if best is None:
        raise ConfigError("station init: no placement of the body in front of the robot gives a plan: the body's "
                          "points do not fit the robot's reach and quill stroke; check the robot, head and body files")
    return best[1], best[2]


def _repeats_cycles(cfg: CellConfig) -> tuple[int, int, str]:
    """The fewest repeats whose predicted gain reaches MIN_GAIN × GAIN_MARGIN, and the cycles."""
    import dataclasses

    from station.cell.correction.design import _prior
    from station.cell.pipeline.preview import preview
    from station.core.kinematics.forward import forward
    from station.core.measurement.repeatability import sigma_from_rp

    sim = cfg.simulation
    rp = cfg.model.repeatability_mm
    if rp is not None:  # the robot's data sheet (issue 38), not the simulator's figure
        rep_um = sigma_from_rp(rp) * 1e3
        rep_text = f"repeatability σ {rep_um:.1f} µm per axis from the robot file's RP {rp * 1e3:g} µm"
    else:
        rep_um = float(getattr(sim, "repeatability_um", ASSUMED_REPEATABILITY_UM) or ASSUMED_REPEATABILITY_UM)
        rep_text = f"repeatability {rep_um:g} µm"
    plan_cfg = dataclasses.replace(cfg, plan=dataclasses.replace(cfg.plan, repeats=1))
    p1 = preview(plan_cfg, with_upload=True)
    q = np.array([s.step.joints for s in p1.steps if s.step.kind.value == "identification"])
    nominal = forward(cfg.model, q, setup=False)[:, :3, 3]
    before = float(np.sqrt(np.mean([np.sum((forward(cfg.model, q, p, setup=False)[:, :3, 3] - nominal) ** 2, axis=1)
                                    for p in _prior(cfg)]))) * 1000.0
    for repeats in range(2, 13):
        sigma = p1.sigma_position_um[1] / math.sqrt(repeats)  # the mean σ falls as 1/√repeats
        after = math.hypot(sigma, rep_um)
        if before / after >= MIN_GAIN * GAIN_MARGIN:
            break
    cycles = int(min(10, max(5, math.ceil(VERIFICATION_READINGS / max(p1.n_verification_targets, 1)))))
    why = (f"predicted: before correction ≈ {before:.0f} µm RMS (robots with errors of the size [simulation] states), "
           f"after ≈ {after:.1f} µm (σ {sigma:.1f} µm from {repeats} repeats, {rep_text}): gain "
           f"≈ {before / after:.0f}× against the {MIN_GAIN:g}× the run must show")
    return repeats, cycles, why


def new_cell_text(dest: str | Path, robot: str | None = None, head: str | None = None,
                  body: str | None = None) -> NewCell:
    """The configuration ``station init DEST --robot R --head H --body B`` writes (each optional:
    without any, the template)."""
    dest = Path(dest)
    text = TEMPLATE
    notes: list[str] = []
    if robot is None and head is None and body is None:
        return NewCell(text, ())
    from station.io.robot.files import load_robot

    if robot is not None:
        model = load_robot(robot if Path(robot).exists() else robot)
        rel = _rel(robot, dest) if Path(robot).exists() else robot
        text = _set(text, r'^model = "sr800" .*$', _kv(f'model = "{rel}"', "the robot file (docs/robot-file.md), "
                                                        "relative to this file"))
        text = _set(text, r"^joints = \[\[-125\.0.*$", _limits_line(model))
        text = _set(text, r"^# finite, lower < upper, inside the robot file's limits\.$",
                    "# finite, lower < upper, inside the robot file's limits (here: 2 % of each range inside them).")
    if body is not None:
        edge = _cube_edge(body)
        text = _set(text, r"^cube_edge_mm = 40\.0 .*$", _kv(f"cube_edge_mm = {edge:g}", "> 0 … 1000 (from the body "
                                                                 "file: the shortest distance between two corners of a cube)"))
        text = _set(text, r'^# file = "body\.csv"$', f'file = "{_rel(body, dest)}"')
        text = re.sub(r"^points = \[\n(?:  \{.*\},\n)+\]\n", "", text, count=1, flags=re.MULTILINE)
    if head is not None:
        text = _set(text, r'^# \[head\]\n# file = "head\.toml" .*$',
                    "[head]\n" + _kv(f'file = "{_rel(head, dest)}"', "the probe-head file (docs/probe-head.md)"))
        rp = model.repeatability_mm if robot is not None else None
        if rp is None:
            sigma_line = _kv(f"sigma_position_um = {ASSUMED_SIGMA_UM:g}", f"0.01 … 1000 (the head's reading noise on "
                             f"the robot's ≈ {ASSUMED_REPEATABILITY_UM:g} µm repeatability; with [robot] "
                             f"repeatability_mm in the robot file, {HEAD_SIGMA_UM:g} µm)")
        else:  # the fit adds the robot file's RP in quadrature (issue 38): not counted twice
            sigma_line = _kv(f"sigma_position_um = {HEAD_SIGMA_UM:g}", f"0.01 … 1000 (the head's reading noise "
                             f"alone: the robot file's RP {rp * 1e3:g} µm is added to it)")
        text = _set(text, r"^sigma_position_um = 15\.0 .*$", sigma_line)
        text = _set(text, r"^sigma_angle_arcsec = 20\.0 .*$", _kv("sigma_angle_arcsec = 6.0", "0.01 … 3600"))
    cfg = parse_text(text, str(dest))
    stroke = float(np.min(cfg.head.strokes)) if cfg.head is not None else 10.0
    margin = round(min(1.5, 0.3 * stroke / 2), 2)
    text = _set(text, r"^recenter_margin_mm = 1\.5 .*\n# +# a \[head\] file states its own\)$", _kv(f"recenter_margin_mm = {margin:g}", f"0 … 4 (this head's "
                                                             f"shortest probe stroke is ±{stroke / 2:g} mm)"))
    if cfg.model.is_scara:
        text = _set(text, r"^verification_cycles = 3 +# ", f"{'verification_cycles = 5':<32} # ")
        setup, _ = _placement(text, dest, cfg)
        cfg = parse_text(_with_setup(text, setup), str(dest))
        repeats, cycles, why = _repeats_cycles(cfg)
        text = _set(text, r"^repeats = 2 +# ", f"{f'repeats = {repeats}':<32} # ")
        base = text
        while True:  # the last cycle's approach and clearance widen the motions: as many cycles as fit
            text = _set(base, r"^verification_cycles = 5 +# ", f"{f'verification_cycles = {cycles}':<32} # ")
            try:
                setup, line = _placement(text, dest, parse_text(text, str(dest)))
                break
            except ConfigError:
                if cycles <= 3:
                    raise
                cycles -= 1
        text = _with_setup(text, setup)
        notes.append(f"[robot] setup: {line}; measure where the robot really stands and correct it to a few mm")
        notes.append(f"[plan] repeats = {repeats}, verification_cycles = {cycles}: {why}")
        from station.cell.correction.design import GRID_POINT
        from station.cell.correction.precheck import check_correction

        cfg = parse_text(text, str(dest))
        try:
            design = check_correction(cfg)
            if design is not None:
                notes.append(f"[correction] designed by the station: {design.describe()}")
        except ConfigError as exc:
            notes.append(f"[correction]: {exc}")
        notes.append(f"the correction grid's x, y, z describe {GRID_POINT}")
    else:  # an articulated arm: its own placement, park pose and words (issue 37 §3)
        from station.cell.session.new_arm import arm_cell_text

        text, more = arm_cell_text(text, dest, cfg, _with_setup, _set, _repeats_cycles)
        notes += more
    return NewCell(text, tuple(notes))
