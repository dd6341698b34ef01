"""Pieces of the operator UI that know nothing of a running app: the yes / no dialog and the
markup of the status line, the phase strip and the result panel.

The result panel reads only the :class:`~station.cell.summary.RunSummary` — its outcome, exit
code, figures and failure — so it shows what the CLI, ``--json`` and the report show.
"""

from __future__ import annotations

import math
from typing import Any

from textual import on
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.markup import escape as _markup_escape
from textual.screen import ModalScreen
from textual.widgets import Button, Label

from station.cell.summary import RunSummary
from station.errors import Outcome

__all__ = ["ConfirmScreen", "PHASES", "STATE_TEXT", "ACTIVE_STATES", "fmt_num", "esc", "phase_markup",
           "summary_markup"]

PHASES: tuple[str, ...] = ("connect", "plan", "measure", "identify", "correct", "upload", "verify", "done")

# Run states shown in the status line (and readable as StationApp.state).
IDLE, RUNNING, PAUSING, PAUSED, ABORTING = "idle", "running", "pausing", "paused", "aborting"
FINISHED, FAILED, ABORTED = "finished", "failed", "aborted"
ACTIVE_STATES = (RUNNING, PAUSING, PAUSED, ABORTING)

STATE_TEXT = {
    IDLE: "[b]idle[/] — press [b]s[/] to start",
    RUNNING: "[b $success]running[/]",
    PAUSING: "[b $warning]pause requested[/] — the robot stops at the next safe point",
    PAUSED: "[b $warning]PAUSED[/] at a safe point — press [b]p[/] to resume",
    ABORTING: "[b $error]aborting[/] — the robot stops at the next safe point",
    FINISHED: "[b $success]finished[/]",
    FAILED: "[b $error]FAILED[/]",
    ABORTED: "[b $error]ABORTED[/] by the operator",
}


def fmt_num(value: Any, unit: str = "", digits: int = 1) -> str:
    suffix = f" {unit}" if unit else ""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return f"{value}{suffix}"
    if not math.isfinite(value):
        return "—"
    if isinstance(value, int):
        return f"{value}{suffix}"
    return f"{value:.{digits}f}{suffix}"


def esc(text: Any) -> str:
    """Runner text in Textual markup: a '[' in a message must not open a style."""
    return _markup_escape(str(text))


def phase_markup(current: str | None, visited: set[str]) -> str:
    """connect › plan › …: visited phases ticked, the current one highlighted."""
    parts = []
    for name in PHASES:
        if name == current:
            parts.append(f"[b reverse $accent] {name} [/]")
        elif name in visited:
            parts.append(f"[$success]✓ {name}[/]")
        else:
            parts.append(f"[dim]{name}[/]")
    return " › ".join(parts)


def summary_markup(summary: RunSummary, step_index: int | None = None) -> str:
    """The result panel: for a failure what stopped the run and what to do first, then the
    outcome, the headline figures and the exit code as aligned rows."""
    lines: list[str] = []
    failure = summary.failure
    if failure is not None:
        where = f" at step {step_index + 1}" if step_index is not None else ""
        head = ("ABORTED by the operator" if summary.outcome is Outcome.ABORTED
                else f"FAILED — {failure.error_type}")
        lines.append(f"[b $error]{esc(head)}[/]{where}")
        lines.append(esc(failure.message))
        if failure.hint:
            lines.append(f"[b]What to do:[/] {esc(failure.hint)}")
        if failure.log_file and failure.log_file not in failure.message:
            lines.append(f"traceback in {esc(failure.log_file)}")
        lines.append("")
    rows: list[tuple[str, str]] = [
        ("outcome", f"[b]{summary.outcome.name}[/] — {esc(summary.outcome.description)}")]
    if summary.run_id is not None:
        rows.append(("run", f"#{summary.run_id}"))
    for key in ("robot", "cell"):
        if value := getattr(summary, key):
            rows.append((key, esc(value)))
    rows.extend((label, fmt_num(value, unit, digits)) for label, value, unit, digits in summary.figures())
    if summary.upload_skipped:
        rows.append(("upload", "skipped (the table was not sent)"))
    if summary.report:
        rows.append(("report", esc(summary.report)))
    rows.append(("exit code", f"[b]{summary.exit_code}[/]"))
    width = max(len(label) for label, _ in rows)
    lines.extend(f"{label:<{width}}  {value}" for label, value in rows)
    return "\n".join(lines)


class ConfirmScreen(ModalScreen[bool]):
    """Yes / no question; dismisses with True (y, Yes) or False (n, Escape, No)."""

    BINDINGS = [
        Binding("y", "answer(True)", "Yes"),
        Binding("n", "answer(False)", "No"),
        Binding("escape", "answer(False)", "No", show=False),
    ]

    DEFAULT_CSS = """
    ConfirmScreen { align: center middle; }
    ConfirmScreen > Vertical {
        width: 64; height: auto; padding: 1 2;
        border: thick $error; background: $surface;
    }
    ConfirmScreen Label { width: 100%; margin-bottom: 1; }
    ConfirmScreen Horizontal { height: auto; align: center middle; }
    ConfirmScreen Button { margin: 0 2; }
    """

    def __init__(self, question: str) -> None:
        super().__init__()
        self.question = question

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label(self.question, id="question")
            with Horizontal():
                yield Button("Yes (y)", variant="error", id="yes")
                yield Button("No (n)", variant="primary", id="no")

    def on_mount(self) -> None:
        # A stray Enter must not confirm an abort.
        self.query_one("#no", Button).focus()

    def action_answer(self, answer: bool) -> None:
        self.dismiss(answer)

    @on(Button.Pressed)
    def _pressed(self, event: Button.Pressed) -> None:
        event.stop()
        self.dismiss(event.button.id == "yes")
