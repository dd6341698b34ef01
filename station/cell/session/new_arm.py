"""``station init`` for an articulated arm (a six-axis robot; issue 37 §3): where the SCARA's
derivation (:mod:`station.cell.session.new_cell`) places the body in the arm's annulus with the
quill centred, an arm's set-up is searched over the body's distance and height in front of it,
and the template's SCARA words (elbows, quill, the controller's correction table, a SCARA's
park pose) are replaced by an arm's.

From the files, derived as the run will use them:

* ``[robot] setup``: the body's centroid on the base x axis at the distance and height where the
  plan's own candidates (:func:`~station.cell.plan.articulated.articulated_candidates`, every
  configuration and head orientation through the motion guard) reach the most points, then the
  most (point, configuration, orientation) candidates, then the nearest;
* ``[conformance] park_joints``: the retract pose of the plan's first step, a pose the plan itself
  commands, inside the soft limits and clear of the body;
* ``[plan] repeats`` and ``verification_cycles``: as for a SCARA, from the plan's predicted accuracy.

Nothing moves; the result is text and notes the caller writes.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from station.cell.config.cell_config import CellConfig, parse_text
from station.errors import ConfigError
from station.io.robot.formats import SPEED_HINT

__all__ = ["arm_cell_text", "arm_placement", "SIX_AXIS_WORDS"]

#: the body's nearest point stays this fraction of the flange's horizontal reach in front of axis
#: 1 (the robot's foot stands outside the body's plate); the farthest distance searched for the
#: centroid is FARTHEST of it (beyond, the wrist cannot turn the head at the far points)
NEAREST, FARTHEST = 0.2, 0.8
#: how many distances between them are searched
N_DISTANCES = 5
#: the heights of the body's centroid above axis 2 searched, as fractions of that reach: the head
#: hangs below the flange, so an arm measures best with the cubes above its shoulder's level (the
#: KR 6 R900-like arm of the tests: 24 of 24 points at 0.4–0.5, 8 of 24 at the shoulder's level)
HEIGHTS = (0.0, 0.2, 0.4, 0.6)
#: joint vectors drawn to estimate the reach (fixed seed: init writes the same file every time)
REACH_SAMPLES = 4000

#: (pattern, replacement) of the template's SCARA lines and their arm's words
SIX_AXIS_WORDS = (
    (r"^elbows = \[1, -1\] .*$",
     "# elbows = [1, -1]               # a SCARA's elbows; an arm is measured in every configuration (shoulder,\n"
     "#                                # elbow, wrist) its soft limits allow, each named in 'station plan'"),
    (r"^(verification_every = \d+ +# every \d+th) \(point, elbow\)", r"\1 (point, configuration)"),
    (r"^# The correction table's grid describes .*\n(?:# .*\n)*?(?=max_interpolation_um)",
     "# An articulated arm's controller takes no x, y, z, yaw correction table (the table is a SCARA's):\n"
     "# the identified model gives compensated targets and joint offsets instead ('station compensate',\n"
     "# docs/correction.md, \"Robots without a table\"). The keys below are read for a SCARA only.\n"),
    (r"^# soft limit \(here the quill near its top\) ", "# soft limit (an arm's: none of its joints, as written here) "),
)


def _reach(cfg: CellConfig) -> tuple[float, float]:
    """The flange's horizontal reach [mm] over the soft limits and the height of axis 2 [mm]
    above the base (the frame after A1 and A2's constants at q = 0)."""
    from station.core.kinematics.forward import forward
    from station.core.kinematics.transforms import pose_to_matrix

    lo, hi = cfg.soft_limits[:, 0], cfg.soft_limits[:, 1]
    q = np.random.default_rng(0).uniform(lo, hi, size=(REACH_SAMPLES, cfg.model.n_joints))
    T = forward(cfg.model, q, setup=False)
    P = np.asarray(cfg.model.nominal, dtype=float).reshape(-1, 6)
    shoulder = pose_to_matrix(P[1]) @ pose_to_matrix(P[2])  # A1 then A2: transforms R, A1, A2, …
    return float(np.max(np.hypot(T[:, 0, 3], T[:, 1, 3]))), float(shoulder[2, 3])


def _score(cfg: CellConfig) -> tuple[int, int]:
    """(points with a candidate at the nominal head orientation, candidates in all), counting the
    candidates the plan's collision check keeps (issue 40: scored without it, the KR 6 cell of
    tests/cell/test_init_six_axis.py reached its far cubes only with the upper arm through the near
    ones, and the plan then measured 18 of its 24 points)."""
    from station.cell.plan.articulated import articulated_candidates
    from station.cell.plan.collision import fcl_available
    from station.cell.plan.vias import clear_candidates

    cands, orient, _ = articulated_candidates(cfg)
    if fcl_available():  # without python-fcl the plan refuses to run at all, whatever the set-up
        cands, orient, _ = clear_candidates(cfg, cands, orient)
    return len({c.point for c, k in zip(cands, orient) if k == 0}), len(cands)


def arm_placement(text: str, dest: Path, cfg: CellConfig, with_setup) -> tuple[np.ndarray, str]:
    """The set-up whose candidates reach the most points (then the most candidates), and a line
    saying how many points it reaches."""
    from station.cell.plan.assembly import head_targets_world

    centre = cfg.body_points[:, :3, 3].mean(axis=0)
    reach, shoulder = _reach(cfg)
    n = len(cfg.point_ids)
    best: tuple[tuple[float, ...], np.ndarray, str] | None = None
    depth = float(centre[0] - cfg.body_points[:, 0, 3].min())  # centroid to the body's nearest edge
    near = (depth / reach) + NEAREST
    for frac in np.linspace(near, max(near, FARTHEST), N_DISTANCES):
        for h in HEIGHTS:
            # the head's frame is what the arm carries: its height above the corners is the head's
            lift = float(np.mean(head_targets_world(cfg)[:, 2, 3]) - centre[2])
            z = shoulder + h * reach - lift
            setup = np.array([centre[0] - frac * reach, centre[1], centre[2] - z, 0.0, 0.0, 0.0])
            try:
                c = parse_text(with_setup(text, setup), str(dest))
                points, total = _score(c)
            except ConfigError:
                continue
            score = (float(points), float(total), -float(frac))
            line = (f"the body's centroid {frac * reach:.0f} mm in front of the robot's axis 1 and "
                    f"{z:.0f} mm above its base: {points} of {n} points reached, {total} (point, configuration, "
                    f"orientation) candidates" + ("" if points == n else " ('station plan' names the points left out)"))
            if best is None or score > best[0]:
                best = (score, setup, line)
    if best is None or best[0][0] == 0:
        raise ConfigError("station init: no placement of the body in front of the arm gives a plan: no point is "
                          "reachable at any searched distance and height; check the robot, head and body files")
    return best[1], best[2]


def _park_line(cfg: CellConfig) -> tuple[str, str]:
    """``park_joints`` (deg | mm): the retract pose of the plan's first step, and a note."""
    from station.cell.plan.arm_motion import retract_pose
    from station.cell.plan.measurement_plan import build_plan

    plan = build_plan(cfg)
    first = plan.run_steps(1, with_oracle=False, with_upload=False)[0]
    q = retract_pose(cfg, np.asarray(first.q, dtype=float))
    # rounded to 0.1 towards the middle of the soft range, so that the written value stays inside
    mid = cfg.soft_limits.mean(axis=1)
    vals = []
    for j, (v, kind) in enumerate(zip(q, cfg.model.joint_types)):
        s = math.degrees(float(v)) if kind == "revolute" else float(v)
        m = math.degrees(float(mid[j])) if kind == "revolute" else float(mid[j])
        vals.append(math.floor(s * 10) / 10 if m < s else math.ceil(s * 10) / 10)
    line = "park_joints = [" + ", ".join(f"{v:.1f}" for v in vals) + "]"
    return (f"{line:<32} # deg | mm: {first.point_id}'s retract pose, the plan's first; park the arm there",
            f"[conformance] park_joints: the retract pose above {first.point_id} (the plan's first step), "
            f"inside [limits]")


def arm_cell_text(text: str, dest: Path, cfg: CellConfig, with_setup, set_line, repeats_cycles
                  ) -> tuple[str, list[str]]:
    """The template ``text`` made an arm's: its words, set-up, repeats, cycles and park pose."""
    notes: list[str] = []
    for pattern, repl in SIX_AXIS_WORDS:
        text, k = re.subn(pattern, repl, text, count=1, flags=re.MULTILINE)
        if k != 1:  # pragma: no cover - the template changed under this module
            raise AssertionError(f"the template has no line matching {pattern!r}")
    setup, line = arm_placement(text, dest, cfg, with_setup)
    text = with_setup(text, setup)
    cfg = parse_text(text, str(dest))
    repeats, cycles, why = repeats_cycles(cfg)
    text = set_line(text, r"^repeats = 2 +# ", f"{f'repeats = {repeats}':<32} # ")
    text = set_line(text, r"^verification_cycles = 3 +# ", f"{f'verification_cycles = {cycles}':<32} # ")
    cfg = parse_text(text, str(dest))
    park, park_note = _park_line(cfg)
    text = set_line(text, r"^# park_joints = \[.*$", park)
    notes.append(f"[robot] setup: {line}; measure where the robot really stands and correct it to a few mm")
    notes.append(f"[plan] repeats = {repeats}, verification_cycles = {cycles}: {why}")
    notes.append(park_note)
    if cfg.model.max_speed is None:
        notes.append("the robot file gives no joint speeds, so 'station plan' estimates no motion time: "
                     + SPEED_HINT)
    return text, notes

