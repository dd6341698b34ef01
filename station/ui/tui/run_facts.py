"""The run's figures as the operator UI states them while the run goes on (issue 42).

Each line is made from one figure event of the run's stream (:mod:`station.cell.run.facts.events`):
the figures are the event's, which are the run's stored summary's; nothing here computes or
reads back a figure. Units as people read them: µm, seconds, and the gain as a ratio.
"""

from __future__ import annotations

from station.cell.run.facts.events import Event, Identified, TableDesigned, Uploaded, Verified
from station.ui.tui.widgets import fmt_num

__all__ = ["fact_line"]


def fact_line(event: Event) -> str | None:
    """One plain line for a figure event (None for any other event)."""
    if isinstance(event, Identified):
        ident = event.identification
        return (f"identified {ident.n_parameters} parameters from {ident.n_measurements} measurements: residual "
                f"RMS {fmt_num(ident.rms_residual_um, 'µm')} ({ident.rms_normalized:.2f}× the expected noise)")
    if isinstance(event, TableDesigned):
        c = event.correction
        grid = "×".join(map(str, c.grid_shape)) or "?"
        limit = "" if c.limit_um is None else f" (limit {fmt_num(c.limit_um, 'µm')})"
        return (f"correction table: grid {grid}, {c.n_values} values, CRC-32 {c.crc32}, interpolation bound "
                f"{fmt_num(c.interpolation_bound_um, 'µm')}{limit}")
    if isinstance(event, Uploaded):
        return (f"table CRC-32 {event.upload.crc32} uploaded and active in {fmt_num(event.upload.seconds, 's', 2)}; "
                f"roll-back slot: {event.previous_crc32}")
    if isinstance(event, Verified):
        before = "—" if event.before is None else fmt_num(event.before.rms_um, "µm")
        gain = "" if event.gain is None else f", gain {fmt_num(event.gain, '×')}"
        return f"verified: RMS before {before}, after {fmt_num(event.after.rms_um, 'µm')}{gain}"
    return None
