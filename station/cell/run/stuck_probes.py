"""Probes known to be stuck during a run (a redundant head only).

A probe whose reading stays frozen while the other probes show the head moving is stuck
(:func:`station.core.probe.check.frozen_probes`). Once a reading has shown that, the runner
keeps it here: later touches solve the pose without it from the start, so a stuck probe no
longer fails every touch's residual test and gets every touch measured twice. A known-stuck
probe that reads something else again moves again and is used again.

:func:`still_stuck` and :func:`usable_head` serve the touch procedure; :class:`StuckLog` is the
runner's record of the run (its notices and the summary's notes).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from station.cell.run.facts.events import Event, Notice
from station.core.probe.geometry import ProbeHeadGeometry

#: a known-stuck probe whose reading moves by more than this many reading σ moves again
FREED_SIGMA = 4.0


def still_stuck(geom: ProbeHeadGeometry, values: np.ndarray,
                stuck: Mapping[int, float]) -> tuple[dict[int, float], tuple[int, ...]]:
    """The known-stuck probes (index -> frozen reading [mm]) that still read their frozen value
    in ``values`` (head order), and those that read something else now (freed)."""
    tol = FREED_SIGMA * geom.reading_sigma_mm
    kept = {k: v for k, v in stuck.items() if np.isfinite(values[k]) and abs(values[k] - v) <= tol}
    return kept, tuple(k for k in stuck if k not in kept)


def usable_head(geom: ProbeHeadGeometry, stuck: Mapping[int, float]) -> tuple[ProbeHeadGeometry, np.ndarray]:
    """The head without its stuck probes and the mask of the probes kept; the whole head when
    none is stuck or when the rest would not fix the pose (then the stuck probe stays in and the
    residual test goes on catching it)."""
    from station.core.probe.check import fixes_pose

    keep = np.ones(geom.n_probes, dtype=bool)
    keep[list(stuck)] = False
    if keep.all() or keep.sum() < 6:
        return geom, np.ones(geom.n_probes, dtype=bool)
    sub = geom.subset(keep)
    if not fixes_pose(sub):
        return geom, np.ones(geom.n_probes, dtype=bool)
    return sub, keep


@dataclass
class StuckProbe:
    label: str  # "X1 (channel 5)"
    value_mm: float  # the frozen reading
    since_step: int  # the step of the earliest recent touch that already read it
    found_step: int  # the step whose reading showed it stuck
    readings: int = 0  # readings solved without it


class StuckLog:
    """The runner's record of stuck probes: ``known()`` for the touch procedure, ``update`` after
    each reading (says so in a notice when a probe is found stuck or moves again), ``notes()``
    for the run's summary."""

    def __init__(self, geom: ProbeHeadGeometry, emit: Callable[[Event], None]):
        self.geom = geom
        self.emit = emit
        self.probes: dict[int, StuckProbe] = {}
        self.freed: list[str] = []

    def known(self) -> dict[int, float]:
        return {k: p.value_mm for k, p in self.probes.items()}

    def is_stuck(self, label: str) -> bool:
        return any(p.label == label for p in self.probes.values())

    def update(self, stuck: Sequence[tuple[int, float]], freed: Sequence[int], step: int, label: str,
               touches: Sequence[tuple[int, np.ndarray]]) -> None:
        """After the reading of ``step`` (``label``): ``stuck`` the probes it left out as stuck
        ((index, frozen reading)), ``freed`` the known ones that read elsewhere again;
        ``touches``: (step, probe readings in head order) of the recent touches, most recent first."""
        g = self.geom
        for k in freed:
            p = self.probes.pop(k, None)
            if p is None:
                continue
            self.freed.append(f"probe {p.label} moved again at step {step + 1} after {p.readings} readings "
                              f"without it; used again")
            self.emit(Notice("warning", f"probe {p.label} reads again ({label}): it had been stuck at "
                                        f"{p.value_mm:.4f} mm since step {p.since_step + 1}; it is used again"))
        for k, value in stuck:
            if k in self.probes:
                self.probes[k].readings += 1
                continue
            since = step
            for s, v in touches:  # the frozen stretch: back to the first recent touch with that reading
                if not (np.isfinite(v[k]) and abs(v[k] - value) <= FREED_SIGMA * g.reading_sigma_mm):
                    break
                since = min(since, s)
            p = self.probes[k] = StuckProbe(g.label(k), float(value), since, step, 1)
            rest = g.n_probes - 1
            self.emit(Notice("warning", f"probe {p.label} is stuck: it reads {value:.4f} mm at every touch since "
                                        f"step {since + 1} while the other probes show the head moving. It is left "
                                        f"out of the pose from now on (solved from the other {rest} probes) and "
                                        f"its touches are no longer measured twice; free or replace the probe "
                                        f"('station check') before the next run"))

    def notes(self) -> list[str]:
        """The summary's lines about stuck probes."""
        out = [f"probe {p.label} stuck at {p.value_mm:.4f} mm from step {p.since_step + 1} on: left out of "
               f"{p.readings} readings, solved from the other {self.geom.n_probes - 1} probes"
               for p in self.probes.values()]
        return out + self.freed
