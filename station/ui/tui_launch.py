"""``station tui``: the operator UI over the same session as ``station calibrate``.

The UI gets only a ``start_run(emit, control)`` callable; the session opens the devices in the
worker thread the UI runs it in, and its summary is the exit code.
"""

from __future__ import annotations

from pathlib import Path

from station.cell.session import CellRequest, run_calibration_session
from station.ui.tui import StationApp

__all__ = ["launch"]


def launch(request: CellRequest, title: str | None = None) -> int:
    """Run the operator UI on ``request``'s cell until the operator quits; returns the exit
    code of the last run (0 when none was started)."""
    if title is None:
        title = "Calibration station — " + ("simulated cell" if request.simulated else str(request.config))
    # The session writes its tracebacks next to the database; an escaping one goes there too.
    app = StationApp(lambda emit, control: run_calibration_session(request, emit, control), title=title,
                     log_dir=Path(request.db).resolve().parent)
    app.run()
    return int(app.return_code or 0)
