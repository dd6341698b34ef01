"""Operator terminal UI of the calibration station (Textual).

The UI is a *client of the runner*: it never imports drivers and never talks to a device.  It is
given a ``start_run(emit, control[, confirm, resume]) -> RunSummary`` callable (dependency
injection); on Start it calls it in a thread worker, receives the runner's typed
:mod:`station.cell.run.facts.events` through ``emit`` (forwarded thread-safely into the app as
:class:`EventMessage`), steers the run only through the shared
:class:`~station.cell.run.runcontrol.RunControl` (pause / resume / abort at safe points), and answers
the pipeline's questions (:mod:`station.cell.run.questions`) through ``confirm``, which blocks the
worker until the operator has answered in a modal screen.  Every widget is updated from messages
on the UI thread; nothing blocks it.  Reading the run database (the unfinished runs, a run's
results) and writing the report are injected callables too, run in thread workers.

How a run ended is the :class:`~station.cell.records.summary.RunSummary` alone: the exit code shown and
returned is ``summary.exit_code``.  An exception that escapes ``start_run`` (the session never
lets one) is classified by type like the session does; an internal error writes its traceback
to a log file the UI names.  A run that stopped before its end is continued with one key (c) where
continuing it as it is can succeed; every end has one "Next: …" line, chosen by the kind of failure
and told for the cell's kind of devices (:mod:`station.ui.tui.result_panel`); the end is shown by
:class:`~station.ui.tui.run_end.RunEnd`.

    app = StationApp(start_run, title="SR 800 calibration")
    app.run()
    sys.exit(app.return_code or 0)
"""

from __future__ import annotations

import inspect
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from rich.text import Text
from textual import events, on
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, VerticalScroll
from textual.content import Content
from textual.widgets import Button, DataTable, Footer, Header, ProgressBar, Static
from textual.worker import Worker, WorkerState

from station.cell.pipeline.outcomes import classify, failure_summary
from station.cell.records.reading.run_list import RunInfo
from station.cell.records.summary import Failure, RunSummary
from station.cell.run.facts.events import (
    DeviceSnapshot,
    Event,
    MeasurementRecorded,
    Notice,
    Paused,
    PhaseChanged,
    Progress,
    Resumed,
    RunFailed,
    RunFinished,
    RunStarted,
    StepStarted,
)
from station.cell.run.facts.next_move import NextMove
from station.cell.run.runcontrol import RunControl
from station.ui.report.writer import ReportData
from station.ui.tui.actions import EventMessage, QuestionMessage
from station.ui.tui.measurement_table import NOTE_COLUMN, MeasurementTable
from station.ui.tui.result_panel import CONTINUE_KEY, CellContext, can_continue, summary_markup
from station.ui.tui.run_end import RunEnd
from station.ui.tui.run_facts import fact_line
from station.ui.tui.widgets import (
    ABORTED,
    ABORTING,
    ACTIVE_STATES,
    APP_CSS,
    FAILED,
    FINISHED,
    IDLE,
    PAUSED,
    PAUSING,
    PHASES,
    RUNNING,
    STATE_TEXT,
    ConfirmScreen,
    DevicePanel,
    Eta,
    NoticeLog,
    activity_text,
    esc,
    fmt_num,
    passed_phases,
    phase_markup,
)

__all__ = ["StationApp", "EventMessage", "QuestionMessage", "ConfirmScreen", "StartRun", "PHASES", "CellContext"]

StartRun = Callable[..., RunSummary]
"""``start_run(emit, control)``; when it takes ``confirm`` and ``resume`` keywords the UI passes
its question dialog and the run picked to resume."""

LABEL_WIDTH = 26  # the point column: long labels are shortened in the middle, keeping "cycle N"


def _accepts(fn: Callable[..., Any], name: str) -> bool:
    try:
        params = inspect.signature(fn).parameters
    except (TypeError, ValueError):
        return False
    return name in params or any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values())


def _shorten(label: str, width: int = LABEL_WIDTH) -> str:
    return label if len(label) <= width else label[: width // 2 - 1] + "…" + label[-(width - width // 2):]


class StationApp(RunEnd):
    """Operator UI for one calibration run at a time.

    ``start_run(emit, control)`` runs the whole calibration (blocking, in a worker thread); it
    reports through ``emit``, calls ``control.checkpoint()`` at every safe point and returns the
    run's :class:`RunSummary`; with ``confirm=`` / ``resume=`` keywords it also gets the question
    dialog and the run to resume.  ``list_runs()`` (the database's runs), ``load_results(run_id)``
    (a :class:`ReportData`) and ``write_report(run_id) -> Path`` are optional and run in worker
    threads.  ``clock`` drives the time-left estimate (injectable for tests).  ``log_dir``
    receives the traceback of an exception that escapes ``start_run``.  ``cell`` names the cell
    and its devices: the title, the advice for its kind of devices and the exact command lines
    (without it the title is ``title`` and no command line is shown).

    After the app ends, ``app.return_code`` is the run's exit code (0 when no run was started) and
    the app's result (``app.run()``'s return) is the summary (None when no run was started).
    """

    CSS = APP_CSS

    BINDINGS = [
        Binding("s", "start", "Start"),
        Binding(CONTINUE_KEY, "continue_run", "Continue run"),
        Binding("r", "resume_run", "Resume run"),
        Binding("p", "pause", "Pause"),
        Binding("p", "resume", "Resume"),  # the same key; the footer names what it does now (check_action)
        Binding("a", "abort", "Abort"),
        Binding("v", "results", "Results"),
        # the result panel scrolls without Tab first, whatever has the focus (a hidden table)
        Binding("pagedown", "result_page(1)", "More", show=False, priority=True),
        Binding("pageup", "result_page(-1)", "Back", show=False, priority=True),
        Binding("question_mark,h,f1", "help", "Help"),
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
        list_runs: Callable[[], list[RunInfo]] | None = None,
        load_results: Callable[[int], ReportData] | None = None,
        write_report: Callable[[int], Path] | None = None,
        db_label: str = "",
        clock: Callable[[], float] = time.monotonic,
        cell: CellContext | None = None,
    ) -> None:
        super().__init__()
        self._start_run = start_run
        self.cell = cell
        self.title = title if cell is None else cell.title()
        self._autostart = autostart
        self.log_dir = Path(log_dir)
        self._list_runs = list_runs
        self._load_results = load_results
        self._write_report = write_report
        self.db_label = db_label
        self.eta = Eta(clock)
        self.control: RunControl | None = None
        self.worker: Worker[RunSummary] | None = None
        self.state: str = IDLE
        self.run_id: int | None = None
        self.phase: str | None = None
        self.summary: RunSummary | None = None
        self.step_index: int | None = None
        self.question: QuestionMessage | None = None  # the question waiting for the operator
        # a question of the run that arrived while the operator's "Abort?" dialog was open: it waits
        # under that dialog's answer (a "y" meant for the abort must never answer "Upload?")
        self.deferred_question: QuestionMessage | None = None
        self.abort_asked = False
        self.report_path: Path | None = None
        self._quit_when_done = False
        self._settled = False  # the worker has ended; its return value is final
        self._visited: set[str] = set()
        self._phase_event: PhaseChanged | None = None
        self._before_upload: PhaseChanged | None = None  # verification goes on after an upload

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

    @property
    def result_text(self) -> str:
        """The result panel's text, one line per row (the panel wraps long values in their column)."""
        if self.summary is None:
            return ""
        return Content.from_markup(summary_markup(self.summary, self.step_index, self.cell, phase=self.phase)).plain

    # ------------------------------------------------------------------ layout
    def compose(self) -> ComposeResult:
        yield Header()
        with Horizontal(id="status-bar"):
            yield Static("run —", id="run-id")
            yield Static(STATE_TEXT[IDLE], id="state")
            yield Static("", id="eta")
        yield Static(phase_markup(None, set()), id="phases")
        yield Static("", id="phase-detail")
        yield Static("step —", id="step")
        yield Static("", id="next-move")  # the plan's clearance of the step's moves (NextMove)
        yield ProgressBar(total=1, show_eta=False, id="progress")  # no pulsing bar: snapshots stay still
        table = MeasurementTable(id="measurements", zebra_stripes=True, cursor_type="row")
        table.border_title = "Measurements"
        yield table
        with Horizontal(id="bottom"):
            devices = DevicePanel(id="devices")
            devices.border_title = "Devices"
            yield devices
            with VerticalScroll(id="summary-box") as box:
                box.border_title = "Result"
                yield Static("", id="summary")
            log = NoticeLog(id="notices")
            log.border_title = "Notices"
            yield log
        with Horizontal(id="buttons"):
            yield Button("Start (s)", id="start", variant="success")
            yield Button("Pause (p)", id="pause", variant="warning", disabled=True)
            yield Button("Abort (a)", id="abort", variant="error", disabled=True)
            yield Button("Resume run (r)", id="resume")
            yield Button("Quit (q)", id="quit")
        yield Footer()

    def on_mount(self) -> None:
        table = self.query_one("#measurements", DataTable)
        table.add_column("#", key="index", width=4)
        table.add_column("point", key="label", width=LABEL_WIDTH)
        table.add_column("ok", key="ok", width=2)
        table.add_column("µm", key="residual", width=6)
        table.add_column("note (why not valid)", key=NOTE_COLUMN)
        self._fit(self.size.width, self.size.height)
        self.set_interval(0.1, self._poll_control)
        self.set_interval(1.0, self._show_eta)
        if self._autostart:
            self.call_after_refresh(self.action_start)

    def on_resize(self, event: events.Resize) -> None:
        self._fit(event.size.width, event.size.height)
        self.call_after_refresh(self._show_result)
        self.call_after_refresh(self._mark_more)

    def _fit(self, width: int, height: int) -> None:
        # Small terminals (80×24) keep the footer's key labels and drop the button row.
        self.set_class(height < 32, "-short")
        self.set_class(width >= 140, "-wide")

    # ------------------------------------------------------------------ helpers
    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        # the footer shows the keys that do something now (80 columns hold no more)
        if action == "continue_run":
            return not self.running and can_continue(self.summary, self.phase)
        if action == "pause":
            return self.state == RUNNING
        if action == "resume":
            return self.state in (PAUSING, PAUSED)
        if action == "abort":
            return self.state in (RUNNING, PAUSING, PAUSED)
        if action in ("start", "resume_run"):
            return not self.running
        if action == "result_page":  # only on the main screen, once the result is shown
            return self.summary is not None and self.screen is self.screen_stack[0]
        return True

    def _set_state(self, state: str) -> None:
        self.state = state
        text = STATE_TEXT[state]
        if state in (ABORTED, FAILED) and can_continue(self.summary, self.phase):
            text += f" — [b]{CONTINUE_KEY}[/] continue run #{self.summary.run_id if self.summary else ''}"
        self.query_one("#state", Static).update(text)
        self.query_one("#start", Button).disabled = state in ACTIVE_STATES
        self.query_one("#resume", Button).disabled = state in ACTIVE_STATES or self._list_runs is None
        steerable = state in (RUNNING, PAUSING, PAUSED)
        pause_btn = self.query_one("#pause", Button)
        pause_btn.disabled = not steerable
        pause_btn.label = "Resume (p)" if state in (PAUSING, PAUSED) else "Pause (p)"
        self.query_one("#abort", Button).disabled = not steerable
        if state in (FINISHED, FAILED, ABORTED):
            self.eta.stop()  # no time is left of a run that has stopped
        elif state in (PAUSED, ABORTING) or state not in ACTIVE_STATES:
            self.eta.pause()
        elif state == RUNNING and self.question is None:
            self.eta.resume()
        self._show_eta()
        self.sub_title = f"run {self.run_id} — {state}" if self.run_id is not None else state
        self.refresh_bindings()

    def _show_eta(self) -> None:
        # the 1 s timer can fire once more while the app shuts down and its widgets are already
        # gone: then there is nothing to update (query, not query_one, which would raise)
        for eta in self.query("#eta").results(Static):
            eta.update(self.eta.text() if self.run_id is not None else "")

    def _note(self, *parts: str | tuple[str, str]) -> None:
        """Append a line to the notices log; parts are plain text or (text, rich style). A report
        written while the app closes finds no log any more: nothing to append to (query, not query_one)."""
        for log in self.query("#notices").results(NoticeLog):
            log.write(Text.assemble(*parts))

    def _emit(self, event: Event) -> None:
        """Called by the runner, from its thread: forward the event into the app's queue."""
        self.post_message(EventMessage(event))

    def _poll_control(self) -> None:
        # A runner that does not announce Paused still shows up as standing in checkpoint(): the state
        # line says so. The notice is the Paused event's alone; a note here as well raced with it (two
        # lines or one, as the timer fell: a flaky 80×24 snapshot).
        # The 0.1 s timer can fire while the app closes and its panels are gone (as the ETA's can).
        if self.state == PAUSING and self.control is not None and self.control.waiting and not self._panels_gone():
            self._set_state(PAUSED)

    def _show_phases(self, current: str | None) -> None:
        self.query_one("#phases", Static).update(phase_markup(current, self._visited))

    def _reset_view(self) -> None:
        self.run_id = None
        self.phase = None
        self.summary = None
        self.step_index = None
        self.report_path = None
        self._settled = False
        self._visited = set()
        self._phase_event = self._before_upload = None
        self.eta.reset()
        self.remove_class("-ended")
        self.query_one("#measurements", DataTable).clear()
        self.query_one("#notices", NoticeLog).clear()
        self.query_one("#devices", DevicePanel).show(None)
        self.query_one("#progress", ProgressBar).update(total=1, progress=0)
        self.query_one("#run-id", Static).update("run —")
        self._show_phases(None)
        self._show_activity("", end=None)
        self.query_one("#step", Static).update("step —")
        self._show_next_move(None)
        self.query_one("#summary", Static).update("")
        self.query_one("#summary", Static).remove_class("-ok", "-failed")
        box = self.query_one("#summary-box")
        box.remove_class("-shown", "-ok", "-failed")
        box.border_subtitle = ""

    # ------------------------------------------------------------------ actions
    def action_start(self, resume: int | None = None) -> None:
        if self.running:
            self.notify("A run is already in progress.", severity="warning")
            return
        self._reset_view()
        self.control = RunControl()
        control = self.control
        self._set_state(RUNNING)
        self._note(("Start", "bold"), f" — resuming run #{resume}" if resume is not None else " — new run starting")
        kwargs: dict[str, Any] = {}
        if _accepts(self._start_run, "confirm"):
            kwargs["confirm"] = self._confirm
        if resume is not None:
            kwargs["resume"] = resume

        def work() -> RunSummary:
            return self._start_run(self._emit, control, **kwargs)

        self.worker = self.run_worker(work, name="calibration-run", group="run", thread=True,
                                      exit_on_error=False)

    def action_continue_run(self) -> None:
        """The one-key resume: continue the run that just stopped at its next step."""
        if not self.running and can_continue(self.summary, self.phase) and self.summary is not None:
            self.action_start(resume=self.summary.run_id)

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
        asked = question.split("\n")[0] + " (y / n)"
        self._waiting(asked, True)  # the activity line says so, not what ran before the dialog

        def answered(yes: bool | None) -> None:
            self._waiting(asked, False)
            self.abort_asked = False
            # The run may have ended while the dialog was open.
            if yes and self.control is not None and self.running:
                self._quit_when_done = then_quit
                self.control.abort()
                self._set_state(ABORTING)
                what = "Quit confirmed" if then_quit else "Abort confirmed"
                self._note((what, "bold red"), " — stopping at the next safe point")
                self._release_question()
            self._ask_deferred_question()  # asked now (or answered "no" by the abort)

        self.abort_asked = True
        self.push_screen(ConfirmScreen(question), answered)

    def action_abort(self) -> None:
        if self.control is None or self.state not in (RUNNING, PAUSING, PAUSED):
            return
        run = f"run #{self.run_id}" if self.run_id is not None else "the calibration run"
        self._confirm_abort(f"Abort {run}?\nThe robot stops at the next safe point; what is measured stays "
                            f"in the database; afterwards {CONTINUE_KEY} continues it (r picks any unfinished run), "
                            f"as docs/operator-ui.md says.", False)

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

    @on(Button.Pressed, "#resume")
    def _resume_pressed(self) -> None:
        self.action_resume_run()

    @on(Button.Pressed, "#quit")
    async def _quit_pressed(self) -> None:
        await self.action_quit()

    # ------------------------------------------------------------------ events from the runner
    def on_event_message(self, message: EventMessage) -> None:
        ev = message.event
        if self._panels_gone():
            return
        if isinstance(ev, DeviceSnapshot):
            self.query_one("#devices", DevicePanel).show(ev)
        elif isinstance(ev, RunStarted):
            self.run_id = ev.run_id
            self.query_one("#run-id", Static).update(f"run #{ev.run_id}")
            self.query_one("#progress", ProgressBar).update(total=ev.n_steps, progress=ev.resumed_from)
            self.eta.start(ev.resumed_from, ev.n_steps)
            extra = f", resuming after {ev.resumed_from} steps on disk" if ev.resumed_from else ""
            self._note("Run ", (f"#{ev.run_id}", "bold"), f" started: {ev.n_steps} steps{extra}")
            self._set_state(self.state)
        elif isinstance(ev, PhaseChanged):
            if ev.phase == "upload" and self.phase == "verify":
                self._before_upload = self._phase_event
            self._phase_event = ev
            self.phase = ev.phase
            self._visited = passed_phases(ev.phase, self._visited)  # a resumed run passed the earlier ones
            self._show_phases(ev.phase)
            self._show_activity(esc(activity_text(ev.phase, ev.detail)))
            self._note((activity_text(ev.phase, ev.detail), "bold"))
        elif isinstance(ev, StepStarted):
            if self.phase == "upload" and self._before_upload is not None:  # the oracle's upload
                self.on_event_message(EventMessage(self._before_upload))
            self.step_index = ev.index
            self.query_one("#step", Static).update(f"plan step [b]{ev.index + 1}[/]: {esc(ev.label)}")  # the table's row
            self._show_next_move(None)  # until the step's own clearance comes: none the check did not see
        elif isinstance(ev, NextMove):
            self._show_next_move(ev if ev.index == self.step_index else None)
        elif isinstance(ev, Progress):  # the run's k of n (station/cell/run/facts/progress.py), not the plan's index
            self.query_one("#progress", ProgressBar).update(total=ev.total, progress=ev.done)
            self.eta.update(ev.done, ev.total)
            self._show_eta()
        elif isinstance(ev, MeasurementRecorded):
            self._add_measurement(ev)
        elif isinstance(ev, Notice):
            if self.phase == "upload":  # read back, activation: shown where the operator looks
                self._show_activity(esc(activity_text("upload", ev.message)))
            if ev.level == "warning":
                self._note(("WARNING ", "bold yellow"), (ev.message, "yellow"))
                self.notify(ev.message, severity="warning")
            else:
                self._note(ev.message)
        elif isinstance(ev, Paused):
            if self.state in (RUNNING, PAUSING):
                self._set_state(PAUSED)
            self._note(("Paused", "yellow"), f" at a safe point before step {ev.index + 1}")
        elif isinstance(ev, Resumed):
            if self.state in (PAUSED, PAUSING):
                self._set_state(RUNNING)
            self._note(f"Resumed at step {ev.index + 1}")
        elif (fact := fact_line(ev)) is not None:  # the run's figures, as the stream carries them
            self._note(fact)
        elif isinstance(ev, (RunFinished, RunFailed)) and not self._settled:
            self._show_summary(ev.summary)

    def _show_next_move(self, ev: NextMove | None) -> None:
        """The next move's clearance as the plan's collision check found it (the event carries the
        figure and the pair; nothing is computed here), or no line."""
        line = self.query_one("#next-move", Static)
        line.update("" if ev is None else esc(ev.text()))
        line.set_class(ev is not None, "-shown")

    def _add_measurement(self, ev: MeasurementRecorded) -> None:
        table = self.query_one("#measurements", MeasurementTable)
        key = str(ev.index)
        ok = Text("✓", style="bold green") if ev.ok else Text("✗", style="bold red")
        residual = Text(fmt_num(ev.residual_um, digits=2), justify="right")
        note = table.note_cell(key, ev.message, "" if ev.ok else "bold red")  # shortened in the middle
        cells = (Text(str(ev.index + 1)), Text(_shorten(ev.label)), ok, residual, note)
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

    # ------------------------------------------------------------------ end of run (and station.ui.tui.run_end)
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
        s = self.summary  # every run that has a number gets its report, failed or aborted: it says how far it got
        if s is not None and s.run_id is not None and s.report is None and self._write_report is not None:
            self._note("Writing the report …")
            self._make_report(s.run_id)
        if self._quit_when_done:
            self._exit_with_summary()
