"""Operator terminal UI of the calibration station (Textual).

The UI is a *client of the runner*: it never imports drivers and never talks to a device.  It is
given a ``start_run(emit, control) -> dict`` callable (dependency injection); on Start it calls it
in a thread worker, receives the runner's typed :mod:`station.cell.events` through ``emit`` (forwarded
thread-safely into the app as :class:`EventMessage`), and steers the run only through the shared
:class:`~station.cell.runcontrol.RunControl` (pause / resume / abort at safe points).  Every widget is
updated from messages on the UI thread; nothing blocks it.

    app = StationApp(start_run, title="SR 800 calibration")
    app.run()
    sys.exit(app.return_code or 0)
"""

from __future__ import annotations

import math
from typing import Any, Callable

from rich.text import Text
from textual import on
from textual.app import App, ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.markup import escape as _markup_escape
from textual.message import Message
from textual.screen import ModalScreen
from textual.widgets import Button, DataTable, Footer, Header, Label, ProgressBar, RichLog, Static
from textual.worker import Worker, WorkerState

from station import errors as _errors
from station.cell.events import (
    Event,
    MeasurementRecorded,
    Notice,
    Paused,
    PhaseChanged,
    Resumed,
    RunFailed,
    RunFinished,
    RunStarted,
    StepStarted,
)
from station.ui.report import summary_figures
from station.cell.runcontrol import RunAborted, RunControl

__all__ = [
    "StationApp", "EventMessage", "ConfirmScreen", "StartRun", "PHASES", "OUTCOME_EXIT_CODES",
    "exit_code_for", "summary_figures",
]

StartRun = Callable[[Callable[[Event], None], RunControl], dict]

PHASES: tuple[str, ...] = ("connect", "plan", "measure", "identify", "correct", "upload", "verify", "done")

# Run states shown in the status line (and readable as StationApp.state).
IDLE, RUNNING, PAUSING, PAUSED, ABORTING = "idle", "running", "pausing", "paused", "aborting"
FINISHED, FAILED, ABORTED = "finished", "failed", "aborted"
ACTIVE_STATES = (RUNNING, PAUSING, PAUSED, ABORTING)

_STATE_TEXT = {
    IDLE: "[b]idle[/] — press [b]s[/] to start",
    RUNNING: "[b $success]running[/]",
    PAUSING: "[b $warning]pause requested[/] — the robot stops at the next safe point",
    PAUSED: "[b $warning]PAUSED[/] at a safe point — press [b]p[/] to resume",
    ABORTING: "[b $error]aborting[/] — the robot stops at the next safe point",
    FINISHED: "[b $success]finished[/]",
    FAILED: "[b $error]FAILED[/]",
    ABORTED: "[b $error]ABORTED[/] by the operator",
}


def _all_subclasses(cls: type) -> list[type]:
    out = []
    for sub in cls.__subclasses__():
        out.append(sub)
        out.extend(_all_subclasses(sub))
    return out


def exit_code_for(error_type: str) -> int:
    """Exit code for an error type name: a StationError subclass's own code, otherwise 1."""
    if error_type == "RunAborted":
        return RunAborted.exit_code
    for cls in [_errors.StationError, *_all_subclasses(_errors.StationError)]:
        if cls.__name__ == error_type:
            return int(getattr(cls, "exit_code", 2))
    return 1


def _fmt_num(value: Any, unit: str = "", digits: int = 1) -> str:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return f"{value}{(' ' + unit) if unit else ''}"
    if not math.isfinite(value):
        return "—"
    if isinstance(value, int):
        return f"{value}{(' ' + unit) if unit else ''}"
    return f"{value:.{digits}f}{(' ' + unit) if unit else ''}"


def _esc(text: Any) -> str:
    """Escape runner text for Textual markup (Static widgets)."""
    return _markup_escape(str(text))


# Mirror of station.cell.pipeline.Outcome (name -> exit code) for a RunFinished without "exit_code"
# in its summary; the UI does not import the pipeline (tests check the two agree).
OUTCOME_EXIT_CODES: dict[str, int] = {
    "SUCCESS": 0, "CONFIG_ERROR": 2, "IDENTIFICATION_FAILED": 3, "UNREACHABLE": 4,
    "DATABASE_ERROR": 5, "ABORTED": 6, "DEVICE_FAULT": 7, "SAFETY_STOP": 8,
    "UPLOAD_FAILED": 9, "TARGET_MISSED": 10,
}


class EventMessage(Message):
    """A runner event, carried into the app's message queue."""

    def __init__(self, event: Event) -> None:
        super().__init__()
        self.event = event


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
        self.query_one("#no", Button).focus()

    def action_answer(self, answer: bool) -> None:
        self.dismiss(answer)

    @on(Button.Pressed)
    def _pressed(self, event: Button.Pressed) -> None:
        event.stop()
        self.dismiss(event.button.id == "yes")


class StationApp(App[dict]):
    """Operator UI for one calibration run at a time.

    ``start_run(emit, control)`` runs the whole calibration (blocking, in a worker thread); it
    reports through ``emit`` and calls ``control.checkpoint()`` at every safe point.  Its return
    value (a dict) fills in the summary where no ``RunFinished`` event did.

    After the app ends, ``app.return_code`` is the run's exit code (0 when no run was started) and
    the app's result (``app.run()``'s return) is the summary dict.
    """

    CSS = """
    #status-bar { height: 1; padding: 0 1; background: $boost; }
    #run-id { width: 14; text-style: bold; }
    #state { width: 1fr; }
    #phases { height: 1; padding: 0 1; }
    #phase-detail { height: 1; padding: 0 1; color: $text-muted; }
    #step { height: 1; padding: 0 1; }
    #progress { padding: 0 1; height: 1; }
    #progress Bar { width: 1fr; }
    #middle { height: 1fr; }
    #measurements { width: 3fr; height: 100%; border: round $primary; }
    #notices { width: 2fr; height: 100%; border: round $secondary; }
    #summary { height: auto; max-height: 16; padding: 0 1; border: round $accent; display: none; }
    #summary.-shown { display: block; }
    #summary.-ok { border: round $success; }
    #summary.-failed { border: thick $error; }
    #buttons { height: 3; }
    #buttons Button { margin: 0 1; min-width: 14; }
    """

    BINDINGS = [
        Binding("s", "start", "Start"),
        Binding("p", "pause", "Pause/Resume"),
        Binding("a", "abort", "Abort"),
        Binding("q", "quit", "Quit"),
        Binding("ctrl+q", "quit", "Quit", show=False, priority=True),
    ]

    def __init__(
        self,
        start_run: StartRun,
        title: str = "Calibration station",
        *,
        autostart: bool = False,
    ) -> None:
        super().__init__()
        self._start_run = start_run
        self.title = title
        self._autostart = autostart
        self.control: RunControl | None = None
        self.worker: Worker | None = None
        self.state: str = IDLE
        self.run_id: int | None = None
        self.phase: str | None = None
        self.outcome: str | None = None
        self.summary: dict = {}
        self.failure: RunFailed | None = None
        self.exit_code: int | None = None
        self.step_index: int | None = None
        self._quit_when_done = False
        self._got_terminal_event = False
        self._visited: set[str] = set()

    # ------------------------------------------------------------------ layout
    def compose(self) -> ComposeResult:
        yield Header()
        with Horizontal(id="status-bar"):
            yield Static("run —", id="run-id")
            yield Static(_STATE_TEXT[IDLE], id="state")
        yield Static(self._phase_markup(None), id="phases")
        yield Static("", id="phase-detail")
        yield Static("step —", id="step")
        yield ProgressBar(total=None, show_eta=True, id="progress")
        with Horizontal(id="middle"):
            table: DataTable = DataTable(id="measurements", zebra_stripes=True, cursor_type="row")
            table.border_title = "Measurements"
            yield table
            log = RichLog(id="notices", wrap=True, min_width=20)
            log.border_title = "Notices"
            yield log
        summary = Static("", id="summary")
        summary.border_title = "Result"
        yield summary
        with Horizontal(id="buttons"):
            yield Button("Start (s)", id="start", variant="success")
            yield Button("Pause (p)", id="pause", variant="warning", disabled=True)
            yield Button("Abort (a)", id="abort", variant="error", disabled=True)
            yield Button("Quit (q)", id="quit")
        yield Footer()

    def on_mount(self) -> None:
        table = self.query_one("#measurements", DataTable)
        table.add_column("#", key="index", width=4)
        table.add_column("point", key="label")
        table.add_column("ok", key="ok", width=4)
        table.add_column("residual µm", key="residual", width=12)
        table.add_column("note", key="note")
        self.set_interval(0.1, self._poll_control)
        if self._autostart:
            self.call_after_refresh(self.action_start)

    # ------------------------------------------------------------------ helpers
    @property
    def running(self) -> bool:
        return self.state in ACTIVE_STATES

    def _phase_markup(self, current: str | None) -> str:
        """connect › plan › …: visited phases ticked, the current one highlighted."""
        parts = []
        for name in PHASES:
            if name == current:
                parts.append(f"[b reverse $accent] {name} [/]")
            elif name in self._visited:
                parts.append(f"[$success]✓ {name}[/]")
            else:
                parts.append(f"[dim]{name}[/]")
        return " › ".join(parts)

    def _set_state(self, state: str) -> None:
        self.state = state
        self.query_one("#state", Static).update(_STATE_TEXT[state])
        active = state in ACTIVE_STATES
        self.query_one("#start", Button).disabled = active
        pause_btn = self.query_one("#pause", Button)
        pause_btn.disabled = state not in (RUNNING, PAUSING, PAUSED)
        pause_btn.label = "Resume (p)" if state in (PAUSING, PAUSED) else "Pause (p)"
        self.query_one("#abort", Button).disabled = state not in (RUNNING, PAUSING, PAUSED)
        self.sub_title = f"run {self.run_id} — {state}" if self.run_id is not None else state

    def _log(self, *parts: str | tuple[str, str]) -> None:
        """Append a line to the notices log; parts are plain text or (text, rich style)."""
        self.query_one("#notices", RichLog).write(Text.assemble(*parts))

    def _emit(self, event: Event) -> None:
        """Called by the runner, from its thread: forward the event into the app's queue."""
        self.post_message(EventMessage(event))

    def _poll_control(self) -> None:
        # A runner that does not announce Paused still shows up as standing in checkpoint().
        if self.state == PAUSING and self.control is not None and self.control.waiting:
            self._set_state(PAUSED)
            self._log(("Paused", "yellow"), " — the robot stands at a safe point")

    def _reset_view(self) -> None:
        self.run_id = None
        self.phase = None
        self.outcome = None
        self.summary = {}
        self.failure = None
        self.exit_code = None
        self.step_index = None
        self._got_terminal_event = False
        self._visited = set()
        self.query_one("#measurements", DataTable).clear()
        self.query_one("#progress", ProgressBar).update(total=None, progress=0)
        self.query_one("#run-id", Static).update("run —")
        self.query_one("#phases", Static).update(self._phase_markup(None))
        self.query_one("#phase-detail", Static).update("")
        self.query_one("#step", Static).update("step —")
        summary = self.query_one("#summary", Static)
        summary.update("")
        summary.remove_class("-shown", "-ok", "-failed")

    # ------------------------------------------------------------------ actions
    def action_start(self) -> None:
        if self.running:
            self.notify("A run is already in progress.", severity="warning")
            return
        self._reset_view()
        self.control = RunControl()
        control = self.control
        self._set_state(RUNNING)
        self._log(("Start", "bold"), " pressed — run starting")

        def work() -> dict:
            return self._start_run(self._emit, control)

        self.worker = self.run_worker(
            work, name="calibration-run", group="run", thread=True, exit_on_error=False
        )

    def action_pause(self) -> None:
        if self.control is None or self.state not in (RUNNING, PAUSING, PAUSED):
            return
        if self.state == RUNNING:
            self.control.pause()
            self._set_state(PAUSED if self.control.waiting else PAUSING)
            self._log(("Pause requested", "yellow"), " — stopping at the next safe point")
        else:
            self.control.resume()
            self._set_state(RUNNING)
            self._log("Resume requested")

    def action_abort(self) -> None:
        if self.control is None or self.state not in (RUNNING, PAUSING, PAUSED):
            return

        def answered(yes: bool | None) -> None:
            if yes and self.control is not None and self.running:
                self.control.abort()
                self._set_state(ABORTING)
                self._log(("Abort confirmed", "bold red"), " — stopping at the next safe point")

        self.push_screen(
            ConfirmScreen("Abort the calibration run?\nThe robot stops at the next safe point."),
            answered,
        )

    async def action_quit(self) -> None:
        if not self.running:
            self.exit(self.summary, return_code=self.exit_code or 0)
            return
        if self.state == ABORTING:
            self._quit_when_done = True
            self.notify("Quitting once the run has stopped at a safe point.")
            return

        def answered(yes: bool | None) -> None:
            if yes and self.control is not None and self.running:
                self._quit_when_done = True
                self.control.abort()
                self._set_state(ABORTING)
                self._log(("Quit confirmed", "bold red"), " — aborting; the UI closes at the next safe point")

        self.push_screen(
            ConfirmScreen("A run is in progress.\nAbort it at the next safe point and quit?"),
            answered,
        )

    @on(Button.Pressed, "#start")
    def _start_pressed(self) -> None:
        self.action_start()

    @on(Button.Pressed, "#pause")
    def _pause_pressed(self) -> None:
        self.action_pause()

    @on(Button.Pressed, "#abort")
    def _abort_pressed(self) -> None:
        self.action_abort()

    @on(Button.Pressed, "#quit")
    async def _quit_pressed(self) -> None:
        await self.action_quit()

    # ------------------------------------------------------------------ events from the runner
    def on_event_message(self, message: EventMessage) -> None:
        ev = message.event
        if isinstance(ev, RunStarted):
            self.run_id = ev.run_id
            self.query_one("#run-id", Static).update(f"run #{ev.run_id}")
            self.query_one("#progress", ProgressBar).update(total=ev.n_steps, progress=ev.resumed_from)
            extra = f", resuming after {ev.resumed_from} steps on disk" if ev.resumed_from else ""
            self._log("Run ", (f"#{ev.run_id}", "bold"), f" started: {ev.n_steps} steps{extra}")
            self._set_state(self.state)
        elif isinstance(ev, PhaseChanged):
            self.phase = ev.phase
            self._visited.add(ev.phase)
            self.query_one("#phases", Static).update(self._phase_markup(ev.phase))
            self.query_one("#phase-detail", Static).update(_esc(ev.detail))
            self._log("phase ", (ev.phase, "bold"), f": {ev.detail}" if ev.detail else "")
        elif isinstance(ev, StepStarted):
            self.step_index = ev.index
            self.query_one("#step", Static).update(
                f"step [b]{ev.index + 1}[/]/{ev.total}: {_esc(ev.label)}"
            )
            bar = self.query_one("#progress", ProgressBar)
            if bar.total != ev.total:
                bar.update(total=ev.total)
        elif isinstance(ev, MeasurementRecorded):
            self._add_measurement(ev)
            bar = self.query_one("#progress", ProgressBar)
            bar.update(total=ev.total, progress=max(bar.progress, ev.index + 1))
        elif isinstance(ev, Notice):
            if ev.level == "warning":
                self._log(("WARNING ", "bold yellow"), (ev.message, "yellow"))
            else:
                self._log(("info ", "bold"), ev.message)
            if ev.level == "warning":
                self.notify(ev.message, severity="warning")
        elif isinstance(ev, Paused):
            if self.state in (RUNNING, PAUSING):
                self._set_state(PAUSED)
            self._log(("Paused", "yellow"), f" at a safe point before step {ev.index + 1}")
        elif isinstance(ev, Resumed):
            if self.state in (PAUSED, PAUSING):
                self._set_state(RUNNING)
            self._log(f"Resumed at step {ev.index + 1}")
        elif isinstance(ev, RunFinished):
            self._got_terminal_event = True
            self._show_finished(ev.outcome, dict(ev.summary))
        elif isinstance(ev, RunFailed):
            self._got_terminal_event = True
            self._show_failed(ev)

    def _add_measurement(self, ev: MeasurementRecorded) -> None:
        table = self.query_one("#measurements", DataTable)
        key = str(ev.index)
        ok = Text("✓", style="bold green") if ev.ok else Text("✗", style="bold red")
        residual = Text(_fmt_num(ev.residual_um, digits=2), justify="right")
        cells = (Text(str(ev.index + 1)), Text(ev.label), ok, residual, Text(ev.message))
        if key in table.rows:  # a repeated measurement of the same step replaces the row
            for col, value in zip(("index", "label", "ok", "residual", "note"), cells):
                table.update_cell(key, col, value)
        else:
            table.add_row(*cells, key=key)
        # Follow the newest row; after the refresh, so the table's size already includes it.
        self.call_after_refresh(self._follow_row, key)
        if not ev.ok:
            self._log((f"measurement {ev.index + 1} not valid", "yellow"), f": {ev.message}")

    def _follow_row(self, key: str) -> None:
        table = self.query_one("#measurements", DataTable)
        if key in table.rows:
            table.move_cursor(row=table.get_row_index(key), animate=False)

    # ------------------------------------------------------------------ end of run
    def _summary_markup(self, outcome: str, summary: dict) -> str:
        """Result panel text; understands flat keys and the pipeline's nested summary."""
        rows: list[tuple[str, str]] = [("outcome", f"[b]{_esc(outcome)}[/]")]
        for key in ("robot", "cell"):
            if isinstance(summary.get(key), (str, int)):
                rows.append((key, _esc(summary[key])))
        for label, value, unit, digits in summary_figures(summary):
            rows.append((label, _fmt_num(value, unit, digits)))
        exit_code = summary.get("exit_code", self.exit_code)
        rows.append(("exit code", f"[b]{exit_code}[/]"))
        width = max(len(label) for label, _ in rows)
        return "\n".join(f"{label:<{width}}  {value}" for label, value in rows)

    def _show_finished(self, outcome: str, summary: dict) -> None:
        self.outcome = outcome
        self.summary = {"outcome": outcome, **summary}
        if "exit_code" in summary:
            self.exit_code = int(summary["exit_code"])
        else:
            self.exit_code = OUTCOME_EXIT_CODES.get(outcome, 0)
        panel = self.query_one("#summary", Static)
        panel.update(self._summary_markup(outcome, summary))
        ok = self.exit_code == 0
        panel.set_class(ok, "-ok")
        panel.set_class(not ok, "-failed")
        panel.add_class("-shown")
        self._visited.add("done")
        self.query_one("#phases", Static).update(self._phase_markup("done"))
        self._log(("Run finished", "bold green" if ok else "bold yellow"), f": {outcome}")
        self._set_state(FINISHED)

    def _show_failed(self, ev: RunFailed, exit_code: int | None = None) -> None:
        self.failure = ev
        aborted = ev.error_type == "RunAborted"
        self.outcome = "aborted" if aborted else "failed"
        self.exit_code = exit_code_for(ev.error_type) if exit_code is None else exit_code
        self.summary = {
            "outcome": self.outcome,
            "error_type": ev.error_type,
            "message": ev.message,
            "hint": ev.hint,
            "exit_code": self.exit_code,
        }
        where = f" at step {self.step_index + 1}" if self.step_index is not None else ""
        head_plain = "ABORTED by the operator" if aborted else f"FAILED — {ev.error_type}"
        head = _esc(head_plain)
        text = f"[b $error]{head}[/]{where}\n{_esc(ev.message)}"
        if ev.hint:
            text += f"\n[b]What to do:[/] {_esc(ev.hint)}"
        text += f"\nexit code [b]{self.exit_code}[/]"
        panel = self.query_one("#summary", Static)
        panel.update(text)
        panel.remove_class("-ok")
        panel.add_class("-shown", "-failed")
        if self.state not in (FAILED, ABORTED):
            self._log((head_plain, "bold red"), f": {ev.message}")
        self._set_state(ABORTED if aborted else FAILED)

    def on_worker_state_changed(self, event: Worker.StateChanged) -> None:
        if event.worker is not self.worker:
            return
        worker = event.worker
        if event.state == WorkerState.SUCCESS:
            result = worker.result if isinstance(worker.result, dict) else {}
            if not self._got_terminal_event:
                outcome = str(result.get("outcome", "done"))
                self._show_finished(outcome, {k: v for k, v in result.items() if k != "outcome"})
            elif self.state in (FAILED, ABORTED) and "exit_code" in result:
                # The runner reported the failure as an event and returned its exit code.
                code = int(result["exit_code"])
                if code != self.exit_code and self.failure is not None:
                    self._show_failed(self.failure, exit_code=code)
            elif self.state == FINISHED and result:
                # Fill in what the RunFinished summary left out (e.g. exit_code) from the return value.
                merged = {**result, **self.summary}
                if merged != self.summary:
                    self._show_finished(self.outcome or "done", {k: v for k, v in merged.items() if k != "outcome"})
            elif self.running:
                self._set_state(FINISHED)
        elif event.state in (WorkerState.ERROR, WorkerState.CANCELLED):
            error = worker.error
            if isinstance(error, RunAborted):
                if self.state != ABORTED:
                    self._show_failed(RunFailed(
                        "RunAborted", str(error), "the measurements so far are on disk; the run can be resumed"))
            elif not self._got_terminal_event:
                hint = ""
                if isinstance(error, _errors.StationError) and type(error).__doc__:
                    hint = type(error).__doc__.strip().splitlines()[0]
                code = getattr(error, "exit_code", None)
                if not isinstance(code, int) or isinstance(code, bool):
                    code = None
                self._show_failed(
                    RunFailed(type(error).__name__ if error else "Cancelled", str(error or "run cancelled"), hint),
                    exit_code=code,
                )
            elif self.running:
                self._set_state(FAILED)
        else:
            return
        if self._quit_when_done:
            self.exit(self.summary, return_code=self.exit_code or 0)
