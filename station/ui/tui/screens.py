"""The operator UI's dialogs: help, the database's runs (to resume one, or to see its results),
and the questions the pipeline asks before it changes the controller (upload the table? keep it?).

They know nothing of a running app: each is given plain data and dismisses with the answer.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from rich.text import Text
from textual import on
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical, VerticalScroll
from textual.screen import ModalScreen
from textual.widgets import Button, DataTable, Label, Static

from station.cell.records.reading.run_list import RunInfo
from station.cell.run.questions import KeepCorrection, Question, UploadProposal
from station.core.units import ARCSEC, UM
from station.ui.tui.widgets import esc

__all__ = ["HelpScreen", "ResumeScreen", "RunPick", "QuestionScreen", "question_markup", "HELP_TEXT"]

HELP_TEXT = """\
[b]Keys[/]
  [b]s[/]      start a new run (clears the screen)
  [b]c[/]      continue the stopped run at its next step, if it can go on as is
  [b]r[/]      resume an interrupted run: pick it from the list of unfinished runs
  [b]p[/]      pause / resume at the next safe point (never during a probe touch)
  [b]a[/]      abort at the next safe point, after a confirmation
  [b]v[/]      results of the last run: parameters with σ, correlations,
         residuals, verification before/after/oracle, predicted accuracy;
         without one, pick a run of the database (also v in the r list)
  [b]?[/] [b]h[/] [b]F1[/] this help          [b]q[/] quit (asks while a run is in progress)

[b]Screen[/]
  Status line: run number, state, time left (it stands still while paused;
  once the run has stopped it says how long it ran).
  Phase strip: Connect › Plan › Measure › Identify › Correct › Upload › Verify › Done;
  the line below says what the station is doing.
  Measurements: one row per reading — ✓ valid, ✗ rejected, and why in [b]note[/].
  Devices: controller state and heartbeat, joints (° / mm), each probe as a bar over
  its stroke (centre ┃), a red ▒ bar when out of range.
  Notices: phases, warnings, upload read-back and activation.
  Result (at the end): "Next:" what to do now, for every outcome; the outcome,
  exit code, RMS before / after, gain, after / oracle, the table left active
  and the report; the exact command line that resumes. PgDn / PgUp
  scroll a long one.

[b]Upload[/]
  Before the table is sent the station shows it (values, grid, interpolation bound,
  largest correction per joint) and asks; after the verification it asks whether to
  keep it — [b]n[/] rolls the controller back. Either "no" ends as NOT_UPLOADED (11).

[b]Report[/]
  After every run with a run number (failed and aborted ones say how far they got)
  the report is written next to the run database (report-<database name>-run-N/);
  the Result panel shows its path.

Esc, q or ? closes this help."""


class HelpScreen(ModalScreen[None]):
    BINDINGS = [Binding("escape,q,question_mark,h,f1", "close", "Close")]

    DEFAULT_CSS = """
    HelpScreen { align: center middle; }
    HelpScreen > VerticalScroll { width: 90; max-width: 100%; height: auto; max-height: 100%;
        border: round $accent; background: $surface; padding: 0 1; }
    """

    def compose(self) -> ComposeResult:
        with VerticalScroll() as box:
            box.border_title = "Help"
            yield Static(HELP_TEXT, id="help-text")

    def action_close(self) -> None:
        self.dismiss(None)


@dataclass(frozen=True)
class RunPick:
    """A run picked from the database's list: to resume it, or to see its results (``results``)."""

    run_id: int
    results: bool = False


class ResumeScreen(ModalScreen[RunPick | None]):
    """The database's runs, newest first. To resume (``results=False``): the unfinished ones; Enter
    resumes the chosen one, ``v`` shows its results. For the results view (``results=True``): the
    calibrations that ended (whatever their outcome); Enter or ``v`` shows the chosen one's."""

    BINDINGS = [Binding("escape", "cancel", "Cancel"), Binding("v", "results", "Results")]

    DEFAULT_CSS = """
    ResumeScreen { align: center middle; }
    ResumeScreen > Vertical { width: 100; max-width: 100%; height: auto; max-height: 100%;
        border: round $accent; background: $surface; padding: 0 1; }
    ResumeScreen DataTable { height: auto; max-height: 14; }
    ResumeScreen #resume-help { color: $text-muted; }
    """

    def __init__(self, runs: Sequence[RunInfo], where: str = "", results: bool = False) -> None:
        super().__init__()
        self.for_results = results
        self.runs = [r for r in runs if (r.outcome is not None and r.kind == "calibration" if results else r.resumable)]
        self.where = where

    def compose(self) -> ComposeResult:
        where = f" in {esc(self.where)}" if self.where else ""
        with Vertical() as box:
            box.border_title = "Results of which run?" if self.for_results else "Resume an interrupted run"
            if not self.runs:
                what = "ended calibration runs" if self.for_results else "unfinished runs"
                yield Label(f"No {what}{where}.", id="no-runs")
            else:
                yield DataTable(id="runs", cursor_type="row", zebra_stripes=True)
            yield Label("Enter or v: its results · Esc: cancel" if self.for_results
                        else "Enter: resume the selected run · v: its results · Esc: cancel", id="resume-help")

    def on_mount(self) -> None:
        if not self.runs:
            return
        table = self.query_one("#runs", DataTable)
        table.add_columns("run", "started (UTC)", "robot", "status", "steps", "ended as")
        for r in self.runs:
            table.add_row(Text(f"#{r.id}", style="bold"), r.created_utc[:16].replace("T", " "), r.robot,
                          r.status, f"{r.steps_done}/{r.steps_total}", r.outcome or "interrupted",
                          key=str(r.id))
        table.focus()

    @on(DataTable.RowSelected)
    def _selected(self, event: DataTable.RowSelected) -> None:
        event.stop()
        if event.row_key.value is not None:
            self.dismiss(RunPick(int(event.row_key.value), self.for_results))

    def action_results(self) -> None:
        for table in self.query("#runs").results(DataTable):
            if table.row_count:
                key = table.coordinate_to_cell_key(table.cursor_coordinate).row_key.value
                if key is not None:
                    self.dismiss(RunPick(int(key), results=True))

    def action_cancel(self) -> None:
        self.dismiss(None)


def _correction(value: float, joint_type: str) -> str:
    return f"{value / UM:.1f} µm" if joint_type == "prismatic" else f"{value / ARCSEC:.1f}″"


def question_markup(question: Question) -> tuple[str, str, str]:
    """(title, body markup, yes-button label) of a question of the pipeline."""
    if isinstance(question, UploadProposal):
        shape = " × ".join(str(n) for n in question.grid_shape)
        joints = "  ".join(f"J{i + 1} {_correction(v, t)}"
                           for i, (v, t) in enumerate(zip(question.max_correction, question.joint_types)))
        body = (f"The correction table is ready. It is sent, read back, and only activated when the "
                f"read-back is identical.\n\n"
                f"values               {question.n_values} (grid {shape})\n"
                f"interpolation bound  {question.interpolation_bound_um:.1f} µm\n"
                f"CRC-32               {question.crc32}\n"
                f"largest correction   {joints}\n\n"
                f"[b]y[/] upload and activate · [b]n[/] do not upload (the controller is left as it is)")
        return "Upload the correction table?", body, "Upload (y)"
    if isinstance(question, KeepCorrection):
        body = (f"Verification with the new table (CRC-32 {question.crc32}):\n\n"
                f"RMS before   {question.rms_before_um:.1f} µm\n"
                f"RMS after    {question.rms_after_um:.1f} µm\n"
                f"improvement  {question.gain:.1f} ×\n\n"
                f"[b]y[/] keep it active · [b]n[/] roll back (the previous state comes back)")
        return "Keep the new correction?", body, "Keep (y)"
    return "Confirm", esc(question), "Yes (y)"


class QuestionScreen(ModalScreen[bool]):
    """A question of the pipeline; dismisses with True (y) or False (n, Escape)."""

    BINDINGS = [
        Binding("y", "answer(True)", "Yes"),
        Binding("n", "answer(False)", "No"),
        Binding("escape", "answer(False)", "No", show=False),
        Binding("a", "app.abort", "Abort the run"),
    ]

    DEFAULT_CSS = """
    QuestionScreen { align: center middle; }
    QuestionScreen > Vertical { width: 84; max-width: 100%; height: auto; max-height: 100%;
        padding: 0 1; border: thick $warning; background: $surface; }
    QuestionScreen #question-body { width: 100%; margin-bottom: 1; }
    QuestionScreen Horizontal { height: auto; align: center middle; }
    QuestionScreen Button { margin: 0 2; }
    """

    def __init__(self, question: Question) -> None:
        super().__init__()
        self.question = question

    def compose(self) -> ComposeResult:
        title, body, yes = question_markup(self.question)
        no = "Roll back (n)" if isinstance(self.question, KeepCorrection) else "Don't upload (n)"
        with Vertical() as box:
            box.border_title = title
            yield Static(body, id="question-body")
            with Horizontal():
                yield Button(yes, variant="success", id="yes")
                yield Button(no, variant="error", id="no")

    def action_answer(self, answer: bool) -> None:
        self.dismiss(answer)

    @on(Button.Pressed)
    def _pressed(self, event: Button.Pressed) -> None:
        event.stop()
        self.dismiss(event.button.id == "yes")
