"""A cell's file with a short plan, for the tests about keys, pipes, signals, screens and what travels
where, not about accuracy (issue 42): one visit per identification pose and one verification cycle.
The example's plan (4 visits, 5 cycles) costs about three times the CPU and shows those alike.
tests/conftest.py serves the built-in cell's as the session fixture ``short_cell``."""

from __future__ import annotations

import shutil
from pathlib import Path

#: the cell file's plan lines and their short form
SHORT_PLAN = {"repeats = 4": "repeats = 1", "verification_cycles = 5": "verification_cycles = 1"}


def shortened(text: str) -> str:
    """A cell file's text with :data:`SHORT_PLAN` (each line must be there: a changed example fails here)."""
    for old, new in SHORT_PLAN.items():
        assert old in text, f"the cell file has no {old!r} to shorten"
        text = text.replace(old, new)
    return text


def built_in_short(folder: Path) -> Path:
    """The built-in simulated cell's configuration (seed 1) with the short plan, as ``folder/cell.toml``
    for ``calibrate --simulated CONFIG`` (which starts its own simulators on it)."""
    from simulators import start_simulated_cell
    from simulators.reference_cell import cell_config_text

    with start_simulated_cell(seed=1) as sim:
        text = cell_config_text(sim, 1)
    path = folder / "cell.toml"
    path.write_text(shortened(text), encoding="utf-8")
    return path


def example_short(cell_file: Path, folder: Path) -> Path:
    """An example cell's folder copied into ``folder`` with its cell file's plan short; the copy's cell file."""
    copy = folder / cell_file.parent.name
    shutil.copytree(cell_file.parent, copy)
    path = copy / cell_file.name
    path.write_text(shortened(path.read_text(encoding="utf-8")), encoding="utf-8")
    return path
