"""Pieces of the operator UI that know nothing of a running app: the yes / no dialog, the
markup of the status line, the phase strip, the device panel, the notices log and the time-left
estimate (the result panel is :mod:`station.ui.tui.result_panel`).

The device panel reads only the runner's :class:`~station.cell.run.facts.events.DeviceSnapshot` events.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

from rich.text import Text
from textual import on
from textual.app import ComposeResult, RenderResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical, VerticalScroll
from textual.markup import escape as _markup_escape
from textual.screen import ModalScreen
from textual.widget import Widget
from textual.widgets import Button, Label, Static

from station.cell.run.facts.events import DeviceSnapshot

__all__ = ["APP_CSS", "ConfirmScreen", "DevicePanel", "Eta", "NoticeLog", "PHASES", "PHASE_NAMES", "STATE_TEXT",
           "ACTIVE_STATES", "fmt_num", "fmt_clock", "esc", "phase_markup", "passed_phases", "activity_text",
           "device_text"]

PHASES: tuple[str, ...] = ("connect", "plan", "measure", "identify", "correct", "upload", "verify", "done")

#: what the phase strip shows for each phase (the runner's names are the keys)
PHASE_NAMES = {"connect": "Connect", "plan": "Plan", "measure": "Measure", "identify": "Identify",
               "correct": "Correct", "upload": "Upload", "verify": "Verify", "done": "Done"}
#: what the activity line says while a phase runs
PHASE_ACTIVITY = {"connect": "Connecting", "plan": "Planning", "measure": "Measuring",
                  "identify": "Identifying the parameters", "correct": "Computing the correction table",
                  "upload": "Uploading the correction table", "verify": "Verifying", "done": "Done"}

#: the main screen's layout: it fits 80×24 (the button row gives way to the footer's keys)
APP_CSS = """
    #status-bar { height: 1; padding: 0 1; background: $boost; }
    #run-id { width: 10; text-style: bold; }
    #state { width: 1fr; }
    #eta { width: auto; }
    #phases { height: 1; padding: 0 0 0 1; }
    #phase-detail { height: 1; padding: 0 1; color: $text-muted; }
    #step { height: 1; padding: 0 1; }
    /* the next move's clearance (issue 40): a line of its own while a run streams one */
    #next-move { height: 1; padding: 0 1; color: $text-muted; display: none; }
    #next-move.-shown { display: block; }
    .-ended #next-move { display: none; }
    #progress { padding: 0 1; height: 1; }
    #progress Bar { width: 1fr; }
    #measurements { height: 1fr; min-height: 5; border: round $primary; }
    #bottom { height: auto; max-height: 50%; }
    #devices { width: 48; height: auto; border: round $secondary; padding: 0 1; }
    #notices { width: 1fr; height: 100%; min-height: 6; border: round $secondary; scrollbar-size-vertical: 1; }
    #notices > Static { width: 100%; height: auto; }
    #summary-box { width: 3fr; height: auto; max-height: 100%; border: round $accent; display: none;
        scrollbar-size-vertical: 1; scrollbar-gutter: stable; }
    #summary-box.-shown { display: block; }
    #summary-box.-ok { border: round $success; }
    #summary-box.-failed { border: thick $error; }
    #summary { height: auto; padding: 0 1; }
    #buttons { height: 3; }
    #buttons Button { margin: 0 1; min-width: 12; }
    .-short #buttons { display: none; }
    .-wide #devices { width: 72; }
    .-ended #devices { display: none; }
    /* after the end the result panel has the room: at 120×40 it shows whole, the table a few rows */
    .-ended #bottom { height: 3fr; max-height: 100%; }
    .-ended #measurements { height: 1fr; min-height: 6; }
    .-ended #summary-box { width: 2fr; }
    /* 80×24 after the end: the result and the notices take the screen (the table is in 'v') */
    .-short.-ended #measurements, .-short.-ended #phases, .-short.-ended #step, .-short.-ended #progress,
    .-short.-ended #phase-detail { display: none; }
"""

# Run states shown in the status line (and readable as StationApp.state).
IDLE, RUNNING, PAUSING, PAUSED, ABORTING = "idle", "running", "pausing", "paused", "aborting"
FINISHED, FAILED, ABORTED = "finished", "failed", "aborted"
ACTIVE_STATES = (RUNNING, PAUSING, PAUSED, ABORTING)

STATE_TEXT = {
    IDLE: "[b]idle[/] — [b]s[/] start, [b]r[/] resume a run, [b]?[/] help",
    RUNNING: "[b $success]running[/]",
    PAUSING: "[b $warning]pause requested[/] — stops at the next safe point",
    PAUSED: "[b $warning]PAUSED[/] at a safe point — [b]p[/] to resume",
    ABORTING: "[b $error]aborting[/] — stops at the next safe point",
    FINISHED: "[b $success]finished[/] — [b]v[/] results",
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


def fmt_clock(seconds: float | None) -> str:
    """``HH:MM:SS``; ``--:--:--`` when there is no estimate yet."""
    if seconds is None or not math.isfinite(seconds):
        return "--:--:--"
    s = max(0, int(round(seconds)))
    return f"{s // 3600:02d}:{s // 60 % 60:02d}:{s % 60:02d}"


def esc(text: Any) -> str:
    """Runner text in Textual markup: a '[' in a message must not open a style."""
    return _markup_escape(str(text))


def phase_markup(current: str | None, visited: set[str]) -> str:
    """Connect › Plan › …: visited phases ticked, the current one highlighted (fits 80 columns)."""
    parts = []
    for name in PHASES:
        label = PHASE_NAMES[name]
        if name == current:
            parts.append(f"[b reverse $accent] {label} [/]")
        elif name in visited:
            parts.append(f"[$success]✓{label}[/]")
        else:
            parts.append(f"[dim]{label}[/]")
    return " › ".join(parts)


def passed_phases(current: str, visited: set[str]) -> set[str]:
    """The phases ticked once ``current`` runs: those visited, and every one the run passes before
    ``current`` (a resumed run starts at Measure or later: its Connect and Plan are done). The
    verification before the correction comes before the upload, so Verify does not tick Upload."""
    if current not in PHASES:
        return visited | {current}
    before = set(PHASES[:PHASES.index(current)])
    if current == "verify" and "upload" not in visited:
        before.discard("upload")
    return visited | before | {current}


def activity_text(phase: str, detail: str = "") -> str:
    """The readable line under the phase strip: ``Verifying before correction``."""
    head = PHASE_ACTIVITY.get(phase, phase.capitalize())
    if not detail:
        return head
    if phase == "verify":
        return f"{head} {detail}"
    return f"{head} — {detail}"


class Eta:
    """Time left for the run's steps, from the rate of the steps measured in this attempt.

    The clock runs only while the run runs: :meth:`pause` stops it (the estimate stands still)
    and :meth:`resume` continues it where it stopped, so the estimate neither counts down during
    a pause nor jumps on resume.  Between two steps it counts down from the last step's
    estimate.  :meth:`stop` ends it with the run: no time is left, and it says how long the run
    ran.  ``clock`` is injectable (a frozen clock gives ``--:--:--``: nothing measured).
    """

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self.clock = clock
        self.reset()

    def reset(self) -> None:
        self._active = 0.0  # seconds of running time before _since
        self._since: float | None = None  # running since (clock), None while stopped
        self._base = 0  # steps on disk when the attempt started
        self._done = 0
        self._total = 0
        self._active_at_done = 0.0
        self._ended = False

    @property
    def running(self) -> bool:
        return self._since is not None

    def active_s(self) -> float:
        return self._active + (self.clock() - self._since if self._since is not None else 0.0)

    def start(self, done: int, total: int) -> None:
        self.reset()
        self._base = self._done = done
        self._total = total
        self._since = self.clock()

    def pause(self) -> None:
        if self._since is not None:
            self._active += self.clock() - self._since
            self._since = None

    def resume(self) -> None:
        if self._since is None and self._total and not self._ended:
            self._since = self.clock()

    def stop(self) -> None:
        """The run has ended (finished, aborted or failed): the clock stops for good."""
        self.pause()
        self._ended = True

    @property
    def ended(self) -> bool:
        return self._ended

    def update(self, done: int, total: int) -> None:
        if done != self._done:
            self._active_at_done = self.active_s()
        self._done, self._total = done, total

    def remaining_s(self) -> float | None:
        n = self._done - self._base
        if self._ended:
            return None
        if n <= 0 or self._active_at_done <= 0.0:
            return None
        per_step = self._active_at_done / n
        since_done = self.active_s() - self._active_at_done
        return max(0.0, per_step * (self._total - self._done) - since_done)

    def text(self) -> str:
        if self._ended:
            return f"ran {fmt_clock(self._active)}" if self._total else ""
        return f"left {fmt_clock(self.remaining_s())}" + ("" if self.running or not self._total else " ⏸")


# --------------------------------------------------------------------- notices
class NoticeLog(VerticalScroll):
    """The notices of a run, newest last, wrapped at the panel's width whatever it becomes (a
    log that wraps when it writes keeps lines cut to an earlier, wider panel)."""

    MAX_LINES = 500  # a long run's oldest notices give way; the run database keeps them all

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self._lines: list[Text] = []

    def compose(self) -> ComposeResult:
        yield Static("")

    def write(self, line: Text) -> None:
        self._lines = [*self._lines[-(self.MAX_LINES - 1):], line]
        self._show()
        self.call_after_refresh(self.scroll_end, animate=False)

    def clear(self) -> None:
        self._lines = []
        self._show()

    def _show(self) -> None:
        for static in self.query(Static).results(Static):
            static.update(Text("\n").join(self._lines))

    @property
    def lines(self) -> tuple[Text, ...]:
        return tuple(self._lines)

    @property
    def text(self) -> str:
        return "\n".join(line.plain for line in self._lines)


# --------------------------------------------------------------------- device panel
_STATUS_WORD = {"over_range": "OVER", "under_range": "UNDER", "invalid": "INVAL"}


def _probe_bar(value: float, status: str, stroke: float, width: int) -> Text:
    """A bar over ±stroke/2 with the centre marked; the reading fills from the centre."""
    out = Text("▕")
    half = stroke / 2 if stroke > 0 else 1.0
    ok = status == "ok" and math.isfinite(value) and abs(value) <= half
    centre = width // 2
    if ok:
        pos = int(round((value + half) / (2 * half) * (width - 1)))
        lo, hi = sorted((centre, pos))
        for i in range(width):
            if lo <= i <= hi and i != centre:
                out.append("█", "green")
            elif i == centre:
                out.append("┃", "bold")
            else:
                out.append("─", "dim")
    else:
        out.append("▒" * width, "bold red")
    out.append("▏")
    return out


def device_text(snap: DeviceSnapshot | None, width: int) -> Text:
    """The device panel's text at ``width`` columns: controller state and heartbeat, joints
    (degrees for revolute, mm for prismatic), and each probe as a bar within its stroke with
    out-of-range readings marked."""
    if snap is None:
        return Text("no reading yet", style="dim")
    width = max(width, 24)
    text = Text()
    state_style = "green" if snap.controller in ("ready", "moving") else "bold red"
    text.append("controller ", "bold")
    text.append(snap.controller, state_style)
    if snap.heartbeat_age_s is not None:
        text.append(f" · heartbeat {snap.heartbeat_age_s:.2f} s ago", "yellow" if snap.heartbeat_age_s > 1.0 else "")
    else:
        text.append(" · heartbeat n/a", "dim")
    text.append("\n")
    cells = []
    for i, (q, kind) in enumerate(zip(snap.joints, snap.joint_types)):
        cells.append(f"J{i + 1} {q:+.2f} mm" if kind == "prismatic" else f"J{i + 1} {math.degrees(q):+.2f}°")
    cell_w = max((len(c) for c in cells), default=1) + 2
    per_line = max(1, (width + 2) // cell_w)
    for start in range(0, len(cells), per_line):
        text.append("  ".join(c.ljust(cell_w - 2) for c in cells[start:start + per_line]).rstrip() + "\n")
    n = len(snap.probe_mm)
    # the head file's ids when the runner gives them (wired channels only), else the channels
    ids = [str(i)[:6] for i in snap.probe_ids] if len(snap.probe_ids) == n else [f"P{k + 1}" for k in range(n)]
    id_w = max((len(i) for i in ids), default=2)
    cols = max(1, min(3, (width + 2) // (20 + id_w)))
    cell = (width + 2) // cols - 2
    bar_w = max(5, cell - 11 - id_w)
    for start in range(0, n, cols):
        for k in range(start, min(n, start + cols)):
            value, status = snap.probe_mm[k], snap.probe_status[k]
            if k > start:
                text.append("  ")
            text.append(f"{ids[k]:<{id_w}} ", "bold")
            text.append_text(_probe_bar(value, status, snap.stroke_mm, bar_w))
            word = _STATUS_WORD.get(status)
            if word is None and math.isfinite(value):
                text.append(f"{value:+7.3f}")
            else:
                text.append(f" {word or '—':>6}", "bold red")
        if start + cols < n:
            text.append("\n")
    return text


class DevicePanel(Widget):
    """What the devices reported at the last reading (from ``DeviceSnapshot`` events only)."""

    DEFAULT_CSS = "DevicePanel { height: auto; }"

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.snapshot: DeviceSnapshot | None = None

    def show(self, snap: DeviceSnapshot | None) -> None:
        self.snapshot = snap
        self.refresh(layout=True)

    def render(self) -> RenderResult:
        return device_text(self.snapshot, self.content_size.width or 40)

    def get_content_height(self, container: Any, viewport: Any, width: int) -> int:
        return len(device_text(self.snapshot, width).wrap(self.app.console, width))


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
        width: 64; max-width: 100%; height: auto; padding: 1 2;
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
