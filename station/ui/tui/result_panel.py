"""The operator UI's result panel: how the run ended, its headline figures, and what to do next.

What to do is fitted to the cell the UI runs on (:class:`CellContext`): advice written for a
network or a cable is not shown for a simulator, and a serial probe interface is not a TCP one.
The drivers' messages state what happened; some also carry general advice ("start the run
again"), which the panel leaves out — the hint says what the operator does, with the resume key.
The resume the hint asks for is one key (``c``); where a command line is shown it is the exact
one, with ``--simulated``, ``--db`` and the configuration as this UI was started with.

Knows the drivers' errors only as the cell layer classified them, by type (``Failure.device`` and
``Failure.link``, :mod:`station.cell.results.outcomes`): the UI imports no driver.
"""

from __future__ import annotations

import re
import shlex
from dataclasses import dataclass
from typing import Literal

from textual.content import Content

from station.cell.records.summary import Failure, RunSummary
from station.errors import Outcome
from station.ui.tui.widgets import esc, fmt_num

__all__ = ["CellContext", "DeviceKind", "CONTINUE_KEY", "advice", "device_kind", "summary_markup",
           "HEADLINE_FIGURES", "can_continue", "exact_commands"]

DeviceKind = Literal["simulator", "serial", "tcp"]

#: the key that continues the run that just stopped (the one-key resume)
CONTINUE_KEY = "c"

#: the figures shown first, right under the outcome and the exit code (then the report's path)
HEADLINE_FIGURES = ("RMS before", "RMS after", "improvement ratio", "oracle RMS after", "after / oracle")

#: pyserial's URL forms that are a network link, not a serial line
_NETWORK_PORTS = ("socket://", "rfc2217://")


def device_kind(port: str) -> DeviceKind:
    """``[devices].probe_head``'s kind: a pyserial network URL is TCP, anything else a serial line."""
    return "tcp" if port.strip().lower().startswith(_NETWORK_PORTS) else "serial"


@dataclass(frozen=True)
class CellContext:
    """The cell the UI runs on, as its command line named it, and the kind of each device."""

    name: str = ""  # [cell] name
    config: str | None = None
    simulated: bool = False
    seed: int | None = None
    robot: str | None = None  # a built-in simulated cell's robot (--robot)
    db: str | None = None
    verb: str = "calibrate"  # the command the UI's runs are: calibrate or recheck
    probe: DeviceKind = "serial"
    controller: DeviceKind = "tcp"

    def title(self) -> str:
        """The UI's title: ``[cell] name``, and whether the cell is simulated or it is a recheck."""
        parts = (["Recheck"] if self.verb == "recheck" else []) + [self.name or self.config or "calibration cell"]
        return " · ".join(parts + (["simulated"] if self.simulated else []))

    def command(self, verb: str | None = None, resume: int | None = None) -> str:
        """The exact command line of ``verb`` on this cell (``station reset`` takes only CONFIG)."""
        verb = verb or self.verb
        words = ["station", verb]
        if verb in ("calibrate", "recheck"):
            if self.simulated:
                words.append("--simulated")
            if self.robot is not None:
                words += ["--robot", self.robot]
            if self.seed is not None:
                words += ["--seed", str(self.seed)]
        if self.config:
            words.append(self.config)
        elif verb not in ("calibrate", "recheck"):
            words.append("CONFIG")
        if verb in ("calibrate", "recheck") and self.db is not None:
            words += ["--db", self.db]
        if resume is not None:
            words += ["--resume", str(resume)]
        return shlex.join(words)


# --------------------------------------------------------------------- advice by device kind
#: advice inside a driver's message that is for a program calling it, or for a network
_MESSAGE_ADVICE: tuple[tuple[str, dict[str, str]], ...] = (
    (r"; check the robot program and the link, then start the run again", {"simulator": "", "tcp": ""}),
    (r": check the network and that the robot program runs; the station reconnects on its next request",
     {"simulator": "", "tcp": ""}),
    (r"; check the network\b", {"simulator": ""}),
    (r"the robot program or the link is down", {"simulator": "the simulated controller did not keep up"}),
)

#: the outcome table's advice for a serial probe line, as it reads for a probe interface on TCP
_TCP_PROBE_HINTS = (
    ("check the probe cable and [devices].baudrate",
     "check the network link to the probe interface ([devices].probe_head) and its serial settings"),
    ("reconnect the probe interface", "check that the probe interface answers at [devices].probe_head"),
    ("check [devices].baudrate against the unit's setting and the cable",
     "check the unit's serial settings and the network link to it"),
)

_RESUME = re.compile(r"then continue with '?station (?:calibrate|recheck) CONFIG --resume (\d+|RUN)'?")
_COMMAND = re.compile(r"'station (calibrate|recheck|reset) CONFIG'")


def _simulator_hint(failure: Failure, continues: str) -> str | None:
    if not failure.link:
        return None
    what = "probe interface" if failure.device == "probe" else "controller"
    return (f"the simulated {what} did not answer in time: the simulators share this computer's CPU, so a busy "
            f"machine is the likely cause (let it finish what else it runs); {continues}")


def advice(failure: Failure, ctx: CellContext | None, run_id: int | None) -> tuple[str, str]:
    """(message, hint) of ``failure`` as the operator of ``ctx``'s cell reads them: device advice for
    its kind of device, the resume as the one key (``run_id``: the run it continues), and every
    command line the exact one (without ``ctx``: the texts as they are, but the resume key)."""
    message, hint = failure.message, failure.hint
    continues = f"then press {CONTINUE_KEY} to continue run #{run_id}" if run_id is not None else ""
    if ctx is not None:
        kind = ctx.controller if failure.device == "controller" else ctx.probe
        for pattern, by_kind in _MESSAGE_ADVICE:
            if kind in by_kind:
                message = re.sub(pattern, by_kind[kind], message)
        if ctx.simulated:
            hint = _simulator_hint(failure, continues or "then start the run again") or hint.replace(
                "check the network cable and the controller, ", "")
        elif ctx.probe == "tcp" and failure.device == "probe":
            for old, new in _TCP_PROBE_HINTS:
                hint = hint.replace(old, new)
    if continues:
        hint = _RESUME.sub(continues, hint).replace("then resume to upload again", f"{continues} and upload again")
    return exact_commands(message, ctx), exact_commands(hint, ctx)


def exact_commands(text: str, ctx: CellContext | None) -> str:
    """``text`` with each ``'station VERB CONFIG'`` the exact command line on ``ctx``'s cell."""
    if ctx is None:
        return text
    return _COMMAND.sub(lambda m: f"'{ctx.command(m.group(1))}'", text)


def can_continue(summary: RunSummary | None) -> bool:
    """A run that stopped before its end, with a run to continue: one key resumes it."""
    return summary is not None and summary.failure is not None and summary.run_id is not None


# --------------------------------------------------------------------- the panel
def _visible(markup: str) -> int:
    return Content.from_markup(markup).cell_length


def _wrap(value: str, width: int) -> list[str]:
    """``value`` (markup whose tags never span a space) in lines of at most ``width`` cells; a
    word longer than a line (a path) is cut where it holds no markup."""
    lines: list[str] = []
    line, used = "", 0
    for word in value.split(" "):
        n = _visible(word)
        while n > width and "[" not in word and "\\" not in word:
            room = width - used - (1 if line else 0)
            if room < 8:  # not worth a cut: the word starts the next line
                lines.append(line)
                line, used, room = "", 0, width
            cut = word.rfind("/", 0, room) + 1  # a path breaks after a folder where it can
            cut = cut if cut >= room // 2 else room
            head, word = word[:cut], word[cut:]
            lines.append(f"{line} {head}" if line else head)
            line, used, n = "", 0, len(word)
        if line and used + 1 + n > width:
            lines.append(line)
            line, used = "", 0
        line, used = (f"{line} {word}", used + 1 + n) if line else (word, n)
    return [*lines, line]


def summary_markup(summary: RunSummary, step_index: int | None = None, ctx: CellContext | None = None,
                   width: int | None = None) -> str:
    """The result panel. First what matters at the end, so that it is in view at 80×24 without
    scrolling: for a failure what stopped the run and what to do; the outcome and the exit code;
    RMS before / after, the gain, after / oracle; the report; how to continue. Then the rest.

    ``width``: the panel's width in cells; a long value then goes on under its own column (not
    under the labels)."""
    lines: list[str] = []
    failure = summary.failure
    if failure is not None:
        message, hint = advice(failure, ctx, summary.run_id)
        where = f" at step {step_index + 1}" if step_index is not None else ""
        head = ("ABORTED by the operator" if summary.outcome is Outcome.ABORTED
                else f"FAILED — {summary.outcome.name}")
        lines.append(f"[b $error]{esc(head)}[/]{where}")
        lines.append(esc(message))
        if hint:
            lines.append(f"[b]What to do:[/] {esc(hint)}")
        if failure.log_file and failure.log_file not in message:
            lines.append(f"traceback in {esc(failure.log_file)}")
        lines.append("")
    elif summary.not_uploaded_reason == "correction_bound":  # not a failure to resume: the same table again
        lines.append("[b $warning]NOT UPLOADED — no correction table meets the bound[/]")
        lines.append("[b]What to do:[/] the measurements and the identification are kept: set a looser "
                     "correction.max_interpolation_um or a smaller correction.region (the note below gives the "
                     "numbers), then resume the run" + ("" if summary.run_id is None else f" #{summary.run_id}")
                     + "; it builds the table again without measuring")
        if ctx is not None and summary.run_id is not None:
            lines.append(esc(ctx.command(resume=summary.run_id)))
        lines.append("")
    # two blocks, each aligned on its own labels: the first one's short labels leave its values room
    rows: list[tuple[str, str]] = [
        ("outcome", f"[b]{summary.outcome.name}[/] — {esc(summary.outcome.description)}"),
        ("exit code", f"[b]{summary.exit_code}[/]")]
    figures = [(label, fmt_num(value, unit, digits)) for label, value, unit, digits in summary.figures()]
    rows.extend(f for f in figures if f[0] in HEADLINE_FIGURES)
    if summary.report:
        rows.append(("report", esc(summary.report)))
    if can_continue(summary):
        rows.append(("continue", f"press [b]{CONTINUE_KEY}[/]: run #{summary.run_id} goes on at its next step "
                                 f"([b]r[/]: pick another run)"))
        if ctx is not None:
            rows.append(("command", esc(ctx.command(resume=summary.run_id))))
    lines.extend(_aligned(rows, width))
    first_w = max(len(label) for label, _ in rows)
    rows = [f for f in figures if f[0] not in HEADLINE_FIGURES]
    if summary.run_id is not None:
        rows.append(("run", f"#{summary.run_id}"))
    for key in ("robot", "cell"):
        if value := getattr(summary, key):
            rows.append((key, esc(value)))
    if summary.upload_skipped:
        rows.append(("upload", "skipped (the table was not sent)"))
    for note in summary.notes:
        rows.append(("note", esc(exact_commands(note, ctx))))
    if summary.db and (failure is not None or summary.report is None):
        rows.append(("database", esc(summary.db)))
    lines.extend(_aligned(rows, width, first_w))
    return "\n".join(lines)


def _aligned(rows: list[tuple[str, str]], width: int | None, at_least: int = 0) -> list[str]:
    """``label  value`` lines, the values in one column (wrapped within it at ``width``)."""
    if not rows:
        return []
    label_w = max(at_least, *(len(label) for label, _ in rows))
    value_w = None if width is None else width - label_w - 2
    lines = []
    for label, value in rows:
        parts = [value] if value_w is None or value_w < 16 else _wrap(value, value_w)
        lines.append(f"{label:<{label_w}}  {parts[0]}")
        lines.extend(" " * (label_w + 2) + part for part in parts[1:])
    return lines
