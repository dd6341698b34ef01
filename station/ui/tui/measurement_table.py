"""The measurement table: the latest row stays in view, and a note too long for its cell is
shortened in the middle (issue 37).

When the result panel opens the table gets fewer rows of the screen (``.-ended``): a table that
only scrolled when its cursor moved kept showing rows 39–41 of a run that stopped at 56. This one
scrolls to its end whenever its size changes while it follows the last row. The note column takes
the width the other columns leave; a note longer than that keeps its start (what refused the
reading) and its end (the figure that decides), with an ellipsis between, instead of being cut at
the right edge. The full notes are kept, so a wider terminal shows more of them.
"""

from __future__ import annotations

from rich.text import Text
from textual import events
from textual.widgets import DataTable

__all__ = ["MeasurementTable", "shorten_middle", "NOTE_COLUMN"]

NOTE_COLUMN = "note"
_MIN_NOTE = 12  # narrower than this, a note says nothing: the table scrolls sideways instead


def shorten_middle(text: str, width: int) -> str:
    """``text`` in at most ``width`` characters: its start and its end with "…" between, two thirds
    of the room to the start (it names what refused the reading: "probe 4 over range" stays whole
    at 80 columns) and one third to the end (the figure that decides)."""
    if len(text) <= width:
        return text
    if width <= 1:
        return "…"[:max(width, 0)]
    head = (2 * (width - 1) + 2) // 3
    return text[:head] + "…" + text[len(text) - (width - 1 - head):]


class MeasurementTable(DataTable):
    """The run's measurements, one row per step (``key``: the step index)."""

    def __init__(self, **kwargs) -> None:
        super().__init__(**kwargs)
        self._notes: dict[str, tuple[str, str]] = {}  # row key -> (full note, style)

    @property
    def note_width(self) -> int:
        """The characters the note column has: what the other columns leave of the table."""
        used = sum(c.get_render_width(self) for k, c in self.columns.items() if k.value != NOTE_COLUMN)
        # the vertical scrollbar's room is kept whether it shows yet or not: a table that grows past
        # its height must not get a horizontal scrollbar (and lose a row) for the width it takes
        room = self.content_region.width - self.styles.scrollbar_size_vertical
        return max(_MIN_NOTE, room - used - 2 * self.cell_padding)

    def note_cell(self, key: str, note: str, style: str) -> Text:
        """The note of row ``key`` as its cell shows it (kept in full for a resize)."""
        self._notes[key] = (note, style)
        return Text(shorten_middle(note, self.note_width), style=style)

    def clear(self, columns: bool = False) -> MeasurementTable:
        self._notes.clear()
        super().clear(columns)
        return self

    def following(self) -> bool:
        """The cursor is on the last row (it follows the run, not a row the operator picked)."""
        return self.row_count > 0 and self.cursor_row >= self.row_count - 1

    def on_resize(self, event: events.Resize) -> None:
        follow = self.following()
        self._fit_notes()
        if follow:
            self.call_after_refresh(self.show_last)

    def show_last(self) -> None:
        """Scroll to the last row (cursor on it)."""
        if self.row_count:
            self.move_cursor(row=self.row_count - 1, animate=False)
            self.scroll_end(animate=False, immediate=True, x_axis=False)

    def _fit_notes(self) -> None:
        """The note column as wide as the table leaves, every note shortened to it again."""
        column = next((c for c in self.columns.values() if c.key.value == NOTE_COLUMN), None)
        if column is None:
            return
        width = self.note_width
        column.auto_width, column.width = False, width
        for key, (note, style) in self._notes.items():
            if key in self.rows:
                self.update_cell(key, NOTE_COLUMN, Text(shorten_middle(note, width), style=style))
