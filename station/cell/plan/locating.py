"""Locating the body before the identification poses (issue 37 §1): what the probes' stroke can
find, checked before any motion.

A set-up guess (``[robot].setup``) is a few mm off; a probe reads only within ±stroke/2. Where a
face lies beyond that, the station searches: it touches again with the head moved along that
face's normal (its probes' mean direction), by a bounded step, in the direction the probes' over-
or under-range says, never farther than the set-up's uncertainty (``[robot]
setup_uncertainty_mm``) nor the clearance (``[plan] clearance_mm``), at most ``[plan]
locate_steps`` times per face (``station/cell/run/locate.py`` does it).

One touch finds a face whose displacement ``e`` from the nominal touch satisfies
``|e − c| ≤ a`` with ``c`` the commanded offset and ``a = min_i (stroke_i/2 − |s0_i|)`` over that
face's probes (``s0``: the reading at the nominal touch). The search counts on
:data:`WINDOW_SHARE` of it (``w``: the set-up's small rotation, the robot's own error and the
probes' noise take the rest) and steps by ``2w``, so ``k`` steps cover ``w + 2w·k``. A set-up
uncertainty beyond that, or beyond the clearance, is refused here: ``station plan`` and
``station calibrate`` say so before anything moves, naming the stroke, the uncertainty and what
to change (each figure offered is one this check passes).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from station.cell.config.cell_config import CellConfig
from station.core.probe.geometry import ProbeHeadGeometry, default_probe_head
from station.errors import ConfigError

__all__ = ["WINDOW_SHARE", "FACE_NAMES", "Coverage", "coverage", "check_locating"]

#: the share of a touch's window the search counts on (the rest: rotation, robot error, noise)
WINDOW_SHARE = 0.8
#: the faces of a cube corner, in the head file's numbering (0 top, 1 x, 2 y)
FACE_NAMES = ("top", "x", "y")


@dataclass(frozen=True)
class Coverage:
    """What the search reaches along every face normal [mm]: ``window`` (``w``, what one touch
    finds around its commanded offset), ``step`` (``2w``), ``steps`` (``[plan] locate_steps``),
    ``reach`` (``w + step·steps``), ``limit`` (the farthest a search moves: the set-up's
    uncertainty, at most the clearance) and ``half_stroke`` (the shortest probe's stroke/2)."""

    window: float
    step: float
    steps: int
    reach: float
    limit: float
    half_stroke: float
    uncertainty: float
    clearance: float

    def steps_needed(self) -> int:
        """Search steps per face that cover the set-up's uncertainty."""
        return max(0, math.ceil((self.uncertainty - self.window) / self.step - 1e-12))

    def describe(self) -> str:
        """One line for the plan's preview."""
        return (f"body located within ±{self.uncertainty:g} mm of [robot].setup: one touch finds a face within "
                f"±{self.window:.2f} mm (probes ±{self.half_stroke:g} mm), up to {self.steps} search step(s) of "
                f"{self.step:.2f} mm per face reach ±{min(self.reach, self.limit):.2f} mm")


def _head(cfg: CellConfig) -> ProbeHeadGeometry:
    return cfg.head if cfg.head is not None else default_probe_head(cube_edge_mm=cfg.cube_edge_mm)


def face_windows(geom: ProbeHeadGeometry) -> np.ndarray:
    """``(3,)`` per face (top, x, y): the displacement [mm] one touch still reads on every probe of
    that face, ``min (stroke/2 − |s0|)`` (inf for a face without probes)."""
    margin = geom.strokes / 2 - np.abs(geom.nominal_readings())
    faces = np.asarray(geom.faces, dtype=int)
    return np.array([float(margin[faces == f].min()) if np.any(faces == f) else math.inf for f in range(3)])


def coverage(cfg: CellConfig) -> Coverage:
    """The search's reach for this cell's head and settings."""
    geom = _head(cfg)
    a = float(face_windows(geom).min())
    w = WINDOW_SHARE * a
    steps = int(cfg.plan.locate_steps)
    u = float(cfg.plan.setup_uncertainty_mm)
    clearance = float(cfg.plan.clearance_mm)
    return Coverage(window=w, step=2 * w, steps=steps, reach=w + 2 * w * steps, limit=min(u, clearance),
                    half_stroke=float(np.min(geom.strokes)) / 2, uncertainty=u, clearance=clearance)


def check_locating(cfg: CellConfig) -> Coverage:
    """Refuse (:class:`ConfigError`) a cell whose probes cannot find the body within the set-up's
    uncertainty, even with the search; returns the coverage."""
    c = coverage(cfg)
    if c.uncertainty > c.clearance:
        raise ConfigError(
            f"the set-up's uncertainty ([robot] setup_uncertainty_mm = {c.uncertainty:g}) exceeds the clearance "
            f"([plan] clearance_mm = {c.clearance:g}): a search for the body would move the head farther than it "
            f"stands clear of the cubes. Give [robot].setup more exactly and set setup_uncertainty_mm <= "
            f"{c.clearance:g}, or raise clearance_mm to {math.ceil(c.uncertainty):g}")
    if c.reach >= c.uncertainty:
        return c
    k = c.steps_needed()
    better = f"[plan] locate_steps = {k}" if k <= _MAX_STEPS else None
    exact = c.reach  # the uncertainty the present steps cover
    options = [o for o in (better, f"[robot] setup_uncertainty_mm = {math.floor(exact * 10) / 10:g} (give "
                                   f"[robot].setup that exactly: measure where the robot stands)",
                           f"probes of a longer stroke (±{math.ceil(_half_stroke_for(c) * 10) / 10:g} mm)") if o]
    raise ConfigError(
        f"the probes' stroke (±{c.half_stroke:g} mm; a touch finds a face within ±{c.window:.2f} mm) cannot cover "
        f"the set-up's uncertainty ±{c.uncertainty:g} mm ([robot] setup_uncertainty_mm) even with "
        f"{c.steps} search step(s) of {c.step:.2f} mm per face (±{c.reach:.2f} mm): the body might not be found. "
        f"Change one of: {'; '.join(options)}")


#: the most search steps offered (the schema's bound)
_MAX_STEPS = 20


def _half_stroke_for(c: Coverage) -> float:
    """The half stroke [mm] whose window covers the uncertainty with the present steps (the nominal
    readings' offset kept as it is)."""
    offset = c.half_stroke - c.window / WINDOW_SHARE
    return c.uncertainty / (WINDOW_SHARE * (1 + 2 * c.steps)) + offset
