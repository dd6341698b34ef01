"""The operator UI's side features, apart from following a run: the pipeline's questions
(a modal dialog that blocks the worker until the operator answers), resuming an unfinished run
picked from the database's list, the results view (of this session's run, or of any run picked
from the database's list), the report written after a run, the activity line, and help.

:class:`SideActions` is the base of :class:`station.ui.tui.app.StationApp`; everything that reads
the run database or writes the report is an injected callable run in a thread worker.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from pathlib import Path

from textual import work
from textual.app import App
from textual.message import Message
from textual.widgets import Static
from textual.worker import get_current_worker

from station.cell.records.reading.run_list import RunInfo
from station.cell.records.summary import RunSummary
from station.cell.run.facts.events import Event
from station.cell.run.questions import Question
from station.cell.run.runcontrol import RunControl
from station.ui.report.writer import ReportData
from station.ui.tui.result_panel import CellContext
from station.ui.tui.results import ResultsScreen
from station.ui.tui.screens import HelpScreen, QuestionScreen, ResumeScreen, RunPick, question_markup
from station.ui.tui.widgets import RUNNING, Eta, esc

__all__ = ["SideActions", "EventMessage", "QuestionMessage"]


class EventMessage(Message):
    """A runner event, carried into the app's message queue."""

    def __init__(self, event: Event) -> None:
        super().__init__()
        self.event = event


class QuestionMessage(Message):
    """A question of the pipeline; the worker waits on ``answered`` for ``answer``."""

    def __init__(self, question: Question) -> None:
        super().__init__()
        self.question = question
        self.answer = False
        self.answered = threading.Event()

    def reply(self, answer: bool) -> None:
        if not self.answered.is_set():
            self.answer = answer
            self.answered.set()


class SideActions(App[RunSummary | None]):
    """Questions, resume, results, report and help of the operator UI (see the module)."""

    _list_runs: Callable[[], list[RunInfo]] | None
    _load_results: Callable[[int], ReportData] | None
    _write_report: Callable[[int], Path] | None
    db_label: str
    cell: CellContext | None
    eta: Eta
    control: RunControl | None
    state: str
    summary: RunSummary | None
    step_index: int | None
    question: QuestionMessage | None
    deferred_question: QuestionMessage | None
    abort_asked: bool
    report_path: Path | None
    # the activity line: what the station does (markup), whether that is the run's end, and the
    # dialogs waiting for the operator (newest last)
    _activity: str = ""
    _activity_end: bool = False
    _waits: tuple[str, ...] = ()

    def _panels_gone(self) -> bool:
        """The app is closing: its main screen's panels are removed. An event, a question or a timer
        that arrives then has nothing to show on (the run's database keeps the facts)."""
        return not self.query("#summary")

    # Implemented by station.ui.tui.app.StationApp (the only subclass); declared here so that the side
    # actions type-check against them. Not abc.abstractmethod: Textual's App has its own metaclass.
    @property
    def running(self) -> bool:
        raise NotImplementedError

    def action_start(self, resume: int | None = None) -> None:
        raise NotImplementedError

    def _note(self, *parts: str | tuple[str, str]) -> None:
        raise NotImplementedError

    def _show_result(self) -> None:
        raise NotImplementedError

    def _mark_more(self) -> None:
        raise NotImplementedError

    def _show_eta(self) -> None:
        raise NotImplementedError

    def action_pause(self) -> None:
        raise NotImplementedError

    def action_resume(self) -> None:
        """``p`` while paused (its own binding, so the footer reads "p Resume"): the pause toggles."""
        self.action_pause()

    # ------------------------------------------------------------------ the activity line
    def _show_activity(self, markup: str | None = None, *, end: bool | None = False) -> None:
        """The line under the phase strip: what the station does now (``markup``). While a dialog
        waits for the operator it says so, and once the run has ended (``end=True``) how it ended; an
        activity reported after that (a late notice) does not replace it. ``end=None`` starts afresh."""
        if markup is not None:
            if end is None:
                self._activity_end, self._waits = False, ()
            elif self._activity_end and not end:
                return
            self._activity, self._activity_end = markup, bool(end)
        text = self._activity
        if self._waits and not self._activity_end:
            text = f"[b $warning]Waiting for you:[/] {esc(self._waits[-1])}"
        for line in self.query("#phase-detail").results(Static):
            line.update(text)

    def _waiting(self, what: str, open_: bool) -> None:
        """A dialog asking ``what`` opened (``open_``) or closed."""
        self._waits = (*self._waits, what) if open_ else tuple(w for w in self._waits if w != what)
        self._show_activity()

    def _confirm(self, question: Question) -> bool:
        """Called by the pipeline, from the worker thread: ask the operator and wait for the
        answer.  An abort answers "no"."""
        control = self.control
        message = QuestionMessage(question)
        self.post_message(message)
        worker = get_current_worker() if threading.current_thread() is not threading.main_thread() else None
        while not message.answered.wait(0.05):
            if (control is not None and control.aborted) or (worker is not None and worker.is_cancelled):
                return False  # aborted, or the app is closing
        return message.answer

    def _ask_deferred_question(self) -> None:
        message, self.deferred_question = self.deferred_question, None
        if message is not None:
            self.on_question_message(message)

    def _release_question(self) -> None:
        """An abort answers the open question "no" and closes its dialog."""
        if self.question is not None:
            self.question.reply(False)
            if isinstance(self.screen, QuestionScreen):
                self.screen.dismiss(False)

    def action_help(self) -> None:
        if not isinstance(self.screen, HelpScreen):
            self.push_screen(HelpScreen())

    def action_resume_run(self) -> None:
        if self.running:
            self.notify("A run is in progress.", severity="warning")
        elif self._list_runs is None:
            cli = self.cell.command(resume=None) if self.cell is not None else "station calibrate CONFIG"
            self.notify(f"No run database: resume with '{cli} --resume RUN'.", severity="warning")
        else:
            self._fetch_runs()

    @work(thread=True, group="db", exclusive=True)
    def _fetch_runs(self, results: bool = False) -> None:
        assert self._list_runs is not None
        try:
            runs = self._list_runs()
        except Exception as exc:  # noqa: BLE001 - a database problem is the operator's to see
            self.call_from_thread(self.notify, f"cannot list the runs: {exc}", severity="error")
            return
        if results:
            self.call_from_thread(self.push_screen, ResumeScreen(runs, self.db_label, results=True), self._picked)
        else:
            self.call_from_thread(self._show_runs, runs)

    def _show_runs(self, runs: list[RunInfo]) -> None:
        self.push_screen(ResumeScreen(runs, self.db_label), self._picked)

    def _picked(self, pick: RunPick | None) -> None:
        if pick is None:
            return
        if pick.results:
            self._open_results(pick.run_id)
        elif not self.running:
            self.action_start(resume=pick.run_id)

    def action_results(self) -> None:
        """The results of this session's run; without one that identified its parameters (a new
        session, a run that stopped early), the database's runs to pick one from."""
        s = self.summary
        if self._load_results is None:
            self.notify("No run database: 'station report RUN' writes a run's results.", severity="warning")
        elif s is not None and s.run_id is not None and s.identification is not None:
            self._open_results(s.run_id)
        elif self._list_runs is None:
            self.notify("No results yet: the results view needs a run that identified its parameters.",
                        severity="warning")
        else:
            self._fetch_runs(results=True)

    def _open_results(self, run_id: int) -> None:
        if self._load_results is None:  # v in the resume list of a UI that cannot read results
            self.notify(f"'station report {run_id}' writes the results of run #{run_id}.", severity="warning")
            return
        self.notify(f"Loading the results of run #{run_id} …")
        self._fetch_results(run_id)

    @work(thread=True, group="db", exclusive=True)
    def _fetch_results(self, run_id: int) -> None:
        assert self._load_results is not None
        try:
            data = self._load_results(run_id)
        except Exception as exc:  # noqa: BLE001
            self.call_from_thread(self.notify, f"cannot load the results: {exc}", severity="error")
            return
        self.call_from_thread(self.push_screen, ResultsScreen(data))

    @work(thread=True, group="report", exit_on_error=False)  # a late report never takes the app down
    def _make_report(self, run_id: int) -> None:
        assert self._write_report is not None
        try:
            path = self._write_report(run_id)
        except Exception as exc:  # noqa: BLE001 - the run's result stands without its report
            # words for people (issue 33): the message, not the Python type, unless it has none
            self.call_from_thread(self._note, ("report not written: ", "bold yellow"), str(exc) or type(exc).__name__)
            return
        self.call_from_thread(self._report_written, run_id, path)

    def _report_written(self, run_id: int, path: Path) -> None:
        if self.summary is None or self.summary.run_id != run_id:
            return
        self.report_path = path
        self.summary = self.summary.replace(report=str(path))
        self._show_result()
        self.call_after_refresh(self._mark_more)
        self._note(("Report written: ", "bold"), str(path))

    # ------------------------------------------------------------------ the pipeline's questions
    def on_question_message(self, message: QuestionMessage) -> None:
        # aborted, or the app is closing (its panels are gone, no dialog can open): "no", as an abort answers
        if (self.control is not None and self.control.aborted) or self._panels_gone():
            message.reply(False)
            return
        if self.abort_asked:
            # The operator's "Abort?" dialog is open: a question pushed over it would take the "y"
            # meant for the abort (and upload a table). It is asked once that dialog is answered.
            self.deferred_question = message
            return
        self.question = message
        self.eta.pause()  # waiting for the operator is not run time
        self._show_eta()  # shown now, not at the next tick of the 1 s timer
        asked = question_markup(message.question)[0]
        self._note(("Asked: ", "bold"), asked)
        self._waiting(f"{asked} (y / n)", True)

        def answered(yes: bool | None) -> None:
            message.reply(bool(yes))
            self._waiting(f"{asked} (y / n)", False)
            self.question = None
            if self.state == RUNNING:
                self.eta.resume()
            self._show_eta()
            self._note(("Answer: ", "bold"), "yes" if message.answer else "no")

        self.push_screen(QuestionScreen(message.question), answered)
