"""Operator terminal UI of the calibration station (Textual).

The UI is a *client of the runner*: it never imports drivers and never talks to a device.  It is
given a ``start_run(emit, control) -> RunSummary`` callable (dependency injection); on Start it
calls it in a thread worker, receives the runner's typed :mod:`station.cell.events` through
``emit`` (forwarded thread-safely into the app as :class:`EventMessage`), and steers the run only
through the shared :class:`~station.cell.runcontrol.RunControl` (pause / resume / abort at safe
points).  Every widget is updated from messages on the UI thread; nothing blocks it.

How a run ended is the :class:`~station.cell.summary.RunSummary` alone: the exit code shown and
returned is ``summary.exit_code``.  An exception that escapes ``start_run`` (the session never
lets one) is classified by type like the session does; an internal error writes its traceback
to a log file the UI names.

    app = StationApp(start_run, title="SR 800 calibration")
    app.run()
    sys.exit(app.return_code or 0)
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from rich.text import Text
from textual import on
from textual.app import App, ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal
from textual.message import Message
from textual.widgets import Button, DataTable, Footer, Header, ProgressBar, RichLog, Static
from textual.worker import Worker, WorkerState

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
from station.cell.outcomes import classify, failure_summary
from station.cell.runcontrol import RunControl
from station.cell.summary import Failure, RunSummary
from station.errors import Outcome
from station.ui.tui_widgets import (
    ABORTED,
    ABORTING,
    ACTIVE_STATES,
    FAILED,
    FINISHED,
    IDLE,
    PAUSED,
    PAUSING,
    PHASES,
    RUNNING,
    STATE_TEXT,
    ConfirmScreen,
    esc,
    fmt_num,
    phase_markup,
    summary_markup,
)

__all__ = ["StationApp", "EventMessage", "ConfirmScreen", "StartRun", "PHASES"]

StartRun = Callable[[Callable[[Event], None], RunControl], RunSummary]


class EventMessage(Message):
    """A runner event, carried into the app's message queue."""

    def __init__(self, event: Event) -> None:
        super().__init__()
        self.event = event


class StationApp(App[RunSummary | None]):
    """Operator UI for one calibration run at a time.

    ``start_run(emit, control)`` runs the whole calibration (blocking, in a worker thread); it
    reports through ``emit``, calls ``control.checkpoint()`` at every safe point and returns the
    run's :class:`RunSummary`.  ``log_dir`` receives the traceback of an exception that escapes
    it.

    After the app ends, ``app.return_code`` is the run's exit code (0 when no run was started) and
    the app's result (``app.run()``'s return) is the summary (None when no run was started).
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
    #summary { height: auto; max-height: 24; padding: 0 1; border: round $accent; display: none; }
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
        log_dir: str | Path = ".",
    ) -> None:
        super().__init__()
        self._start_run = start_run
        self.title = title
        self._autostart = autostart
        self.log_dir = Path(log_dir)
        self.control: RunControl | None = None
        self.worker: Worker[RunSummary] | None = None
        self.state: str = IDLE
        self.run_id: int | None = None
        self.phase: str | None = None
        self.summary: RunSummary | None = None
        self.step_index: int | None = None
        self._quit_when_done = False
        self._settled = False  # the worker has ended; its return value is final
        self._visited: set[str] = set()

    # Derived from the summary only, so no second notion of how the run ended can drift.
    @property
    def outcome(self) -> str | None:
        return self.summary.outcome.name if self.summary is not None else None

    @property
    def exit_code(self) -> int | None:
        return self.summary.exit_code if self.summary is not None else None

    @property
    def failure(self) -> Failure | None:
        return self.summary.failure if self.summary is not None else None

    @property
    def running(self) -> bool:
        return self.state in ACTIVE_STATES

    # ------------------------------------------------------------------ layout
    def compose(self) -> ComposeResult:
        yield Header()
        with Horizontal(id="status-bar"):
            yield Static("run —", id="run-id")
            yield Static(STATE_TEXT[IDLE], id="state")
        yield Static(phase_markup(None, set()), id="phases")
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
    def _set_state(self, state: str) -> None:
        self.state = state
        self.query_one("#state", Static).update(STATE_TEXT[state])
        self.query_one("#start", Button).disabled = state in ACTIVE_STATES
        steerable = state in (RUNNING, PAUSING, PAUSED)
        pause_btn = self.query_one("#pause", Button)
        pause_btn.disabled = not steerable
        pause_btn.label = "Resume (p)" if state in (PAUSING, PAUSED) else "Pause (p)"
        self.query_one("#abort", Button).disabled = not steerable
        self.sub_title = f"run {self.run_id} — {state}" if self.run_id is not None else state

    def _note(self, *parts: str | tuple[str, str]) -> None:
        """Append a line to the notices log; parts are plain text or (text, rich style)."""
        self.query_one("#notices", RichLog).write(Text.assemble(*parts))

    def _emit(self, event: Event) -> None:
        """Called by the runner, from its thread: forward the event into the app's queue."""
        self.post_message(EventMessage(event))

    def _poll_control(self) -> None:
        # A runner that does not announce Paused still shows up as standing in checkpoint().
        if self.state == PAUSING and self.control is not None and self.control.waiting:
            self._set_state(PAUSED)
            self._note(("Paused", "yellow"), " — the robot stands at a safe point")

    def _show_phases(self, current: str | None) -> None:
        self.query_one("#phases", Static).update(phase_markup(current, self._visited))

    def _reset_view(self) -> None:
        self.run_id = None
        self.phase = None
        self.summary = None
        self.step_index = None
        self._settled = False
        self._visited = set()
        self.query_one("#measurements", DataTable).clear()
        self.query_one("#progress", ProgressBar).update(total=None, progress=0)
        self.query_one("#run-id", Static).update("run —")
        self._show_phases(None)
        self.query_one("#phase-detail", Static).update("")
        self.query_one("#step", Static).update("step —")
        panel = self.query_one("#summary", Static)
        panel.update("")
        panel.remove_class("-shown", "-ok", "-failed")

    # ------------------------------------------------------------------ actions
    def action_start(self) -> None:
        if self.running:
            self.notify("A run is already in progress.", severity="warning")
            return
        self._reset_view()
        self.control = RunControl()
        control = self.control
        self._set_state(RUNNING)
        self._note(("Start", "bold"), " pressed — run starting")

        def work() -> RunSummary:
            return self._start_run(self._emit, control)

        self.worker = self.run_worker(work, name="calibration-run", group="run", thread=True,
                                      exit_on_error=False)

    def action_pause(self) -> None:
        if self.control is None or self.state not in (RUNNING, PAUSING, PAUSED):
            return
        if self.state == RUNNING:
            self.control.pause()
            self._set_state(PAUSED if self.control.waiting else PAUSING)
            self._note(("Pause requested", "yellow"), " — stopping at the next safe point")
        else:
            self.control.resume()
            self._set_state(RUNNING)
            self._note("Resume requested")

    def _confirm_abort(self, question: str, then_quit: bool) -> None:
        def answered(yes: bool | None) -> None:
            # The run may have ended while the dialog was open.
            if yes and self.control is not None and self.running:
                self._quit_when_done = then_quit
                self.control.abort()
                self._set_state(ABORTING)
                what = "Quit confirmed" if then_quit else "Abort confirmed"
                self._note((what, "bold red"), " — stopping at the next safe point")

        self.push_screen(ConfirmScreen(question), answered)

    def action_abort(self) -> None:
        if self.control is None or self.state not in (RUNNING, PAUSING, PAUSED):
            return
        self._confirm_abort("Abort the calibration run?\nThe robot stops at the next safe point.", False)

    async def action_quit(self) -> None:
        if not self.running:
            self._exit_with_summary()
        elif self.state == ABORTING:
            self._quit_when_done = True
            self.notify("Quitting once the run has stopped at a safe point.")
        else:
            self._confirm_abort("A run is in progress.\nAbort it at the next safe point and quit?", True)

    def _exit_with_summary(self) -> None:
        self.exit(self.summary, return_code=self.exit_code or 0)

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
            self._note("Run ", (f"#{ev.run_id}", "bold"), f" started: {ev.n_steps} steps{extra}")
            self._set_state(self.state)
        elif isinstance(ev, PhaseChanged):
            self.phase = ev.phase
            self._visited.add(ev.phase)
            self._show_phases(ev.phase)
            self.query_one("#phase-detail", Static).update(esc(ev.detail))
            self._note("phase ", (ev.phase, "bold"), f": {ev.detail}" if ev.detail else "")
        elif isinstance(ev, StepStarted):
            self.step_index = ev.index
            self.query_one("#step", Static).update(f"step [b]{ev.index + 1}[/]/{ev.total}: {esc(ev.label)}")
            bar = self.query_one("#progress", ProgressBar)
            if bar.total != ev.total:
                bar.update(total=ev.total)
        elif isinstance(ev, MeasurementRecorded):
            self._add_measurement(ev)
            bar = self.query_one("#progress", ProgressBar)
            bar.update(total=ev.total, progress=max(bar.progress, ev.index + 1))
        elif isinstance(ev, Notice):
            if ev.level == "warning":
                self._note(("WARNING ", "bold yellow"), (ev.message, "yellow"))
                self.notify(ev.message, severity="warning")
            else:
                self._note(("info ", "bold"), ev.message)
        elif isinstance(ev, Paused):
            if self.state in (RUNNING, PAUSING):
                self._set_state(PAUSED)
            self._note(("Paused", "yellow"), f" at a safe point before step {ev.index + 1}")
        elif isinstance(ev, Resumed):
            if self.state in (PAUSED, PAUSING):
                self._set_state(RUNNING)
            self._note(f"Resumed at step {ev.index + 1}")
        elif isinstance(ev, (RunFinished, RunFailed)) and not self._settled:
            self._show_summary(ev.summary)

    def _add_measurement(self, ev: MeasurementRecorded) -> None:
        table = self.query_one("#measurements", DataTable)
        key = str(ev.index)
        ok = Text("✓", style="bold green") if ev.ok else Text("✗", style="bold red")
        residual = Text(fmt_num(ev.residual_um, digits=2), justify="right")
        cells = (Text(str(ev.index + 1)), Text(ev.label), ok, residual, Text(ev.message))
        if key in table.rows:  # a repeated measurement of the same step replaces the row
            for col, value in zip(("index", "label", "ok", "residual", "note"), cells):
                table.update_cell(key, col, value)
        else:
            table.add_row(*cells, key=key)
        # After the refresh, so the table's size already includes the new row.
        self.call_after_refresh(self._follow_row, key)
        if not ev.ok:
            self._note((f"measurement {ev.index + 1} not valid", "yellow"), f": {ev.message}")

    def _follow_row(self, key: str) -> None:
        table = self.query_one("#measurements", DataTable)
        if key in table.rows:
            table.move_cursor(row=table.get_row_index(key), animate=False)

    # ------------------------------------------------------------------ end of run
    def _show_summary(self, summary: RunSummary) -> None:
        """Show how the run ended; called again with the worker's return value, which wins
        over the event's copy (the session completes it, e.g. with the database path)."""
        if summary == self.summary:
            return
        first = self.summary is None
        self.summary = summary
        panel = self.query_one("#summary", Static)
        panel.update(summary_markup(summary, self.step_index))
        panel.set_class(summary.ok, "-ok")
        panel.set_class(not summary.ok, "-failed")
        panel.add_class("-shown")
        if summary.failure is None:
            self._visited.add("done")
            self._show_phases("done")
            self._set_state(FINISHED)
        else:
            self._set_state(ABORTED if summary.outcome is Outcome.ABORTED else FAILED)
        if first:
            self._announce(summary)

    def _announce(self, summary: RunSummary) -> None:
        name = summary.outcome.name
        if summary.failure is None:
            self._note(("Run finished", "bold green" if summary.ok else "bold yellow"), f": {name}")
        else:
            self._note((f"{name} (exit code {summary.exit_code})", "bold red"), f": {summary.failure.message}")
        for note in summary.notes:
            self._note(("note ", "bold"), note)

    def on_worker_state_changed(self, event: Worker.StateChanged) -> None:
        if event.worker is not self.worker:
            return
        worker = event.worker
        if event.state in (WorkerState.SUCCESS, WorkerState.ERROR):
            # Events still queued behind this message must not replace the final summary.
            self._settled = True
        if event.state == WorkerState.SUCCESS:
            result = worker.result
            if isinstance(result, RunSummary):
                self._show_summary(result)
            elif self.summary is None:
                bug = TypeError(f"start_run returned {type(result).__name__}, not a RunSummary")
                self._show_summary(failure_summary(bug, run_id=self.run_id, log_dir=self.log_dir))
        elif event.state == WorkerState.ERROR and worker.error is not None:
            error = worker.error
            # An escaping RunAborted after the session's own ABORTED summary says nothing new.
            if self.summary is None or self.summary.outcome is not classify(error):
                self._show_summary(failure_summary(error, run_id=self.run_id, log_dir=self.log_dir))
        else:
            return
        if self._quit_when_done:
            self._exit_with_summary()
