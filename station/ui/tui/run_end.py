"""How the operator UI shows a run's end: the result panel at its width, the activity line, the
phase strip's last tick and the notices that close the run (the outcome, the table left active).

:class:`RunEnd` sits between :class:`station.ui.tui.actions.SideActions` and
:class:`station.ui.tui.app.StationApp`; it reads the summary only, like the app.
"""

from __future__ import annotations

from textual.containers import VerticalScroll
from textual.widgets import Static

from station.cell.records.summary import RunSummary
from station.errors import Outcome
from station.ui.tui.actions import SideActions
from station.ui.tui.result_panel import (
    CONTINUE_KEY,
    active_table,
    advice,
    can_continue,
    kept_table,
    summary_markup,
)
from station.ui.tui.widgets import ABORTED, FAILED, FINISHED

__all__ = ["RunEnd"]


class RunEnd(SideActions):
    """The end of a run on screen (see the module)."""

    phase: str | None
    _visited: set[str]

    # Implemented by station.ui.tui.app.StationApp (see SideActions).
    def _show_phases(self, current: str | None) -> None:
        raise NotImplementedError

    def _set_state(self, state: str) -> None:
        raise NotImplementedError

    def _show_summary(self, summary: RunSummary) -> None:
        """Show how the run ended; called again with the worker's return value, which wins
        over the event's copy (the session completes it, e.g. with the database path)."""
        if summary == self.summary:
            return
        if self._panels_gone():
            return
        first = self.summary is None
        self.summary = summary  # the title stays the cell's as the UI started: it names the station, not the run
        self._show_result()
        for widget in (self.query_one("#summary", Static), self.query_one("#summary-box")):
            widget.set_class(summary.ok, "-ok")
            widget.set_class(not summary.ok, "-failed")
            widget.add_class("-shown")
        self.add_class("-ended")
        self.call_after_refresh(self._mark_more)
        if summary.failure is None:
            self._visited.add("done")
            self._show_phases("done")
            crc = kept_table(summary)
            self._show_activity(f"Done — {f'table CRC-32 {crc} active · ' if crc else ''}[b]v[/] shows the results",
                                end=True)
            self._set_state(FINISHED)
        else:
            resume = (f"[b]{CONTINUE_KEY}[/] continues run #{summary.run_id}" if can_continue(summary, self.phase)
                      else "the Result panel says what next")
            self._show_activity(f"Stopped — {resume}", end=True)
            self._set_state(ABORTED if summary.outcome is Outcome.ABORTED else FAILED)
        if first:
            self._announce(summary)

    def _show_result(self) -> None:
        """The result panel at its width (again after a resize: its long values wrap under their
        column)."""
        for panel in self.query("#summary").results(Static):
            if self.summary is not None:
                width = panel.content_region.width or None
                panel.update(summary_markup(self.summary, self.step_index, self.cell, width, self.phase))
                if width is None:  # not laid out yet: once it is
                    self.call_after_refresh(self._show_result)
                else:  # the frame says "more" after the text laid out at its width, not before
                    self.call_after_refresh(self._mark_more)

    def _mark_more(self) -> None:
        # what does not fit says so on the frame (the first rows hold what matters)
        for box in self.query("#summary-box").results(VerticalScroll):
            box.border_subtitle = "more: PgDn ↓" if box.max_scroll_y > 0 else ""

    def action_result_page(self, direction: int) -> None:
        """PgDn / PgUp: the result panel's next or previous page (no Tab to it first)."""
        for box in self.query("#summary-box").results(VerticalScroll):
            if direction > 0:
                box.scroll_page_down(animate=False)
            else:
                box.scroll_page_up(animate=False)

    def _announce(self, summary: RunSummary) -> None:
        name = summary.outcome.name
        if summary.failure is None:
            self._note(("Run finished", "bold green" if summary.ok else "bold yellow"), f": {name}")
            if (table := active_table(summary)) is not None:  # the kept table, not the last one uploaded (oracle)
                self._note(("Active table: ", "bold"), table)
        else:
            message, _ = advice(summary.failure, self.cell, summary.run_id)
            self._note((f"{name} (exit code {summary.exit_code})", "bold red"), f": {message}")
