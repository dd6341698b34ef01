"""Where a run's report is written by default: one rule for the command line and the TUI."""

from __future__ import annotations

from pathlib import Path

__all__ = ["report_dir"]


def report_dir(db: str | Path, run_id: int) -> Path:
    """A run's default report folder: ``report-<db name>-run-N/`` beside the run database (the
    name without its suffix), so that two databases in one folder never share a report folder."""
    path = Path(db).resolve()
    return path.parent / f"report-{path.stem or path.name}-run-{run_id}"
