"""The elapsed time and the time left that ``station calibrate``'s progress lines carry (on
stderr): time left from the plan's duration estimate (the one 'station plan' gives: motion at the
robot file's joint speeds × [plan].speed, plus the settling) for the steps still to go, else from
the rate so far (a robot file without joint speeds, a simulated cell with instant motion)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from station.cell.records.rundb import RunDB
from station.cell.run.facts import events as ev

__all__ = ["ProgressClock", "plan_seconds"]


def clock_text(seconds: float) -> str:
    s = int(round(max(seconds, 0.0)))
    return f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}" if s >= 3600 else f"{s // 60:02d}:{s % 60:02d}"


def plan_seconds(db_path: str | Path, run_id: int, time_scale: float | None) -> float | None:
    """The plan's duration estimate [s] of run ``run_id`` (motion from the robot file's joint speeds
    at [plan].speed, as 'station plan' gives it, plus the settling), × ``time_scale`` for a simulated
    cell (None: a real one); None where the robot file gives no speeds, a simulated motion is
    instant, or the stored run cannot be read (the progress lines then go by the rate so far)."""
    if time_scale is not None and time_scale <= 0:
        return None
    try:
        from station.cell.pipeline.preview import motion_seconds
        from station.cell.records.reading.stored_config import stored_config, stored_plan

        with RunDB(db_path) as db:
            cfg, steps = stored_config(db, run_id), stored_plan(db, run_id)
        motion = motion_seconds(cfg, steps)
    except Exception:  # noqa: BLE001 - an estimate only: the progress goes on without it
        return None
    if motion is None:
        return None
    return (motion + len(steps) * cfg.plan.settle_s) * (1.0 if time_scale is None else time_scale)


class ProgressClock:
    """Elapsed time and time left of a run for its progress lines: time left from the plan's
    estimate (:func:`plan_seconds`) for the steps still to go, else from the rate so far."""

    def __init__(self, estimate: Callable[[int], float | None] | None = None,
                 now: Callable[[], float] | None = None) -> None:
        import time

        self._now = now or time.monotonic
        self._estimate = estimate
        self.start = self._now()
        self.total_s: float | None = None
        self.n_steps = 0
        self.first_index = 0
        self.first_t = self.start

    def started(self, e: ev.RunStarted) -> None:
        self.n_steps, self.first_index, self.first_t = e.n_steps, e.resumed_from, self._now()
        self.total_s = self._estimate(e.run_id) if self._estimate is not None else None

    def text(self, done: int, total: int) -> str:
        elapsed = self._now() - self.start
        left_steps = max(total - done, 0)
        if self.total_s is not None and total:
            left, how = self.total_s * left_steps / total, "plan estimate"
        elif done > self.first_index:
            left, how = (self._now() - self.first_t) / (done - self.first_index) * left_steps, "rate so far"
        else:
            return f"{clock_text(elapsed)} elapsed"
        return f"{clock_text(elapsed)} elapsed, ≈ {clock_text(left)} left ({how})"
