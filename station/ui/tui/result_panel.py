"""The operator UI's result panel: how the run ended, its headline figures, and what to do next.

What to do is fitted to the cell the UI runs on (:class:`CellContext`): advice written for a
network or a cable is not shown for a simulator, and a serial probe interface is not a TCP one.
The drivers' messages state what happened; some also carry general advice ("start the run
again"), which the panel leaves out — the hint says what the operator does, with the resume key.
The resume the hint asks for is one key (``c``); where a command line is shown it is the exact
one, with ``--simulated``, ``--db`` and the configuration as this UI was started with.

Knows the drivers' errors only as the cell layer classified them, by type (``Failure.device`` and
``Failure.link``, :mod:`station.cell.pipeline.outcomes`): the UI imports no driver.

Every outcome gets one "Next: …" line (:func:`next_step`), SUCCESS included. Its advice is chosen by
the kind of failure (:func:`failure_kind`: the failure's type and the phase the run stopped in), not
by the exit code's name: a correction step that failed is not advised like a rank-deficient
identification. ``c`` is offered only where continuing the run as it is can succeed
(:func:`can_continue`); where something must change first, the line says what, and how to resume.
"""

from __future__ import annotations

import re
import shlex
from dataclasses import dataclass
from typing import Literal

from textual.content import Content

from station.cell.records.summary import Failure, RunSummary
from station.errors import Outcome
from station.ui.tui.invalid_next import invalid_causes, invalid_next
from station.ui.tui.widgets import esc, fmt_num

__all__ = ["CellContext", "DeviceKind", "CONTINUE_KEY", "advice", "device_kind", "summary_markup",
           "HEADLINE_FIGURES", "can_continue", "exact_commands", "FailureKind", "failure_kind", "next_step",
           "active_table", "kept_table"]

DeviceKind = Literal["simulator", "serial", "tcp"]

#: what kind of failure stopped a run, as the advice is chosen (see :func:`failure_kind`)
FailureKind = Literal["aborted", "internal", "correction", "device", "upload", "measurements", "identification",
                      "configuration", "unreachable", "database", "other"]

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
        """The UI's title: ``[cell] name``, and whether the cell is simulated or it is a recheck. Set
        once when the UI starts: it does not change during a run (the run's own cell name, as the
        session read it, is in the result panel)."""
        name = self.name or self.config or "calibration cell"
        parts = (["Recheck"] if self.verb == "recheck" else []) + [name]
        return " · ".join(parts + (["simulated"] if self.simulated and "simulated" not in name else []))

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


def failure_kind(summary: RunSummary, phase: str | None = None) -> FailureKind | None:
    """The kind of failure that stopped the run (None: it reached its end), by the failure's type as
    the cell layer classified it (``Failure.device``, the outcome of its type) and ``phase``, the
    phase the run was in when it stopped: an error while the correction table was built is a
    correction failure whatever its exit code (an IdentificationError there is no rank deficiency)."""
    failure, outcome = summary.failure, summary.outcome
    if failure is None:
        return None
    if outcome is Outcome.ABORTED:
        return "aborted"
    if outcome is Outcome.INTERNAL_ERROR:
        return "internal"
    if phase == "correct":
        return "correction"
    if failure.device or outcome in (Outcome.DEVICE_FAULT, Outcome.SAFETY_STOP):
        return "device"
    if outcome is Outcome.UPLOAD_FAILED:
        return "upload"
    if outcome is Outcome.IDENTIFICATION_FAILED:
        # too few valid poses: a resume judges the stored readings again and measures the invalid ones
        # again, unless the fix changes how poses are measured (invalid_next.py)
        causes = invalid_causes(failure.message)
        if causes is not None:
            return "identification" if causes.needs_new_run else "measurements"
        return "measurements" if "measured again" in failure.message else "identification"
    return {Outcome.CONFIG_ERROR: "configuration", Outcome.UNREACHABLE: "unreachable",
            Outcome.DATABASE_ERROR: "database"}.get(outcome, "other")  # type: ignore[return-value]


#: the failures after which continuing the run as it is can succeed (once the cause named is fixed
#: at the cell): the others fail again at once until the configuration or the robot file changes
_CONTINUABLE: frozenset[FailureKind] = frozenset({"aborted", "device", "upload", "measurements"})


def can_continue(summary: RunSummary | None, phase: str | None = None) -> bool:
    """A run that stopped before its end, with a run to continue, where continuing it as it is can
    succeed: one key (``c``) resumes it. ``phase``: where it stopped (:func:`failure_kind`)."""
    if summary is None or summary.run_id is None:
        return False
    kind = failure_kind(summary, phase)
    return kind is not None and kind in _CONTINUABLE


def kept_table(summary: RunSummary) -> str | None:
    """The CRC-32 of this run's correction table when the run ended with it active (kept)."""
    up, tables = summary.upload, summary.tables
    if up is None or summary.outcome not in (Outcome.SUCCESS, Outcome.TARGET_MISSED):
        return None
    return up.crc32 if tables is None or tables.active_at_end == up.crc32 else None


def active_table(summary: RunSummary) -> str | None:
    """Which correction table the controller applies after the run: this run's (the kept one,
    by its CRC-32) or the one of the run's start; None when the run did not get that far."""
    up, tables = summary.upload, summary.tables
    kept = up is not None and summary.outcome in (Outcome.SUCCESS, Outcome.TARGET_MISSED)
    if tables is not None:
        end = tables.active_at_end
        if kept and up is not None and end != up.crc32:
            return f"CRC-32 {end}, not this run's {up.crc32}: check the controller before moving the robot"
        if kept:
            return f"CRC-32 {end} (kept)"
        if end in ("none", "unknown"):
            return "none" if end == "none" else "unknown: check the controller"
        return f"CRC-32 {end} (the run's start{', restored' if tables.restored else ''})"
    if kept and up is not None:
        return f"CRC-32 {up.crc32} (kept)"
    return None


def _resume_later(summary: RunSummary, ctx: CellContext | None) -> str:
    run = summary.run_id
    if run is None:
        return "start again (s)"
    return f"resume run #{run} (r, or the command below)" if ctx is not None else f"resume run #{run} (r)"


def next_step(summary: RunSummary, ctx: CellContext | None = None, phase: str | None = None) -> str:
    """What the operator does now, in one line (plain text), for every way a run ends."""
    run, failure = summary.run_id, summary.failure
    config = ctx.config if ctx is not None and ctx.config else "the configuration"
    if failure is not None:
        kind = failure_kind(summary, phase)
        _, hint = advice(failure, ctx, run)
        if kind == "aborted":
            return (f"press {CONTINUE_KEY}: run #{run} goes on at its next step (r: pick another run)"
                    if run is not None else "start a new run (s)")
        causes = invalid_causes(failure.message) if summary.outcome is Outcome.IDENTIFICATION_FAILED else None
        if causes is not None and phase != "correct":  # too few valid poses: the settings the message names
            return invalid_next(causes, config if ctx is not None and ctx.config else "", run, CONTINUE_KEY)
        if kind == "measurements" and run is not None:
            return (f"fix what the warnings name (the probes, the body, the set-up), then press {CONTINUE_KEY}: "
                    f"run #{run} measures the invalid poses again")
        if kind in _CONTINUABLE:  # the device's own advice, which ends in the one key
            if run is not None and f"press {CONTINUE_KEY}" not in hint:
                hint = f"{hint.rstrip('.; ')}; then press {CONTINUE_KEY} to continue run #{run}"
            return hint
        if kind == "internal":
            log = f" with {failure.log_file}" if failure.log_file else ""
            kept = f"; what run #{run} measured is kept" if run is not None else ""
            return f"a bug in the station: report it{log}{kept}"
        if kind == "correction":  # continued unchanged it would fail the same way: no one-key resume
            return (f"change [correction] in {config} as the message says (region, grid, max_interpolation_um), "
                    f"then {_resume_later(summary, ctx)}: the table is built again from the kept measurements")
        if hint and f"press {CONTINUE_KEY}" not in hint:  # the error's own advice, in the UI's words
            for words, keys in _UI_WORDS:
                hint = hint.replace(words, keys)
            return hint
        return _GENERIC_NEXT.get(kind or "other", "read the message above, then start again (s)").format(
            config=config, db=summary.db or (ctx.db if ctx is not None else None) or "the run database")
    return _next_after_the_end(summary, ctx)


#: the command line's advice as the UI's keys say it
_UI_WORDS = (("run the command again", "start again (s)"),
             ("then resume or run again", "then resume (r) or start a new run (s)"),
             ("then run again", "then start a new run (s)"))

#: Next for a failure whose error gave no advice of its own (or only the one key, which would fail again)
_GENERIC_NEXT: dict[str, str] = {
    "identification": "no correction was made: fix what the message names (the robot file, [identification], the "
                      "probes or the body), then start a new run (s)",
    "configuration": "fix what the message names in {config} (the key, file or argument), then start again (s)",
    "unreachable": "nothing was moved: change what the message names (the soft limits, the body's pose or the "
                   "set-up), then start a new run (s)",
    "database": "check {db}: its path, that it is a station run database and that its disk is writable; then "
                "start again (s)",
}


def _next_after_the_end(summary: RunSummary, ctx: CellContext | None) -> str:
    """Next for a run that reached its end (no failure)."""
    outcome = summary.outcome
    crc = kept_table(summary)
    if outcome is Outcome.SUCCESS:
        if ctx is not None and ctx.verb == "recheck":
            return "nothing to fix: the robot holds its calibration; recheck it again when it is due"
        active = f"table CRC-32 {crc} is active; " if crc else ""
        return f"nothing to fix: {active}check and sign the report (v: results)"
    if outcome is Outcome.TARGET_MISSED:
        active = f" (its table CRC-32 {crc} is active)" if crc else ""
        return (f"the correction missed its target{active}: the notes and the report's acceptance table say which "
                f"limit; check the robot, the set-up and [verification], then calibrate again (s)")
    if outcome is Outcome.NOT_UPLOADED:
        if summary.not_uploaded_reason == "correction_bound":
            return ("the measurements and the identification are kept: set a looser correction.max_interpolation_um "
                    "or a smaller correction.region (the note below gives the numbers), then resume "
                    + ("the run" if summary.run_id is None else f"run #{summary.run_id}")
                    + (" (the command below)" if ctx is not None and summary.run_id is not None else "")
                    + ": it builds the table again without measuring")
        if summary.upload is not None:  # uploaded, then rolled back
            return ("the new table was rolled back: the controller applies the table of the run's start; to "
                    "correct the robot, start a new run (s) and keep its table (y)")
        return ("the table was not sent: the controller keeps the table it had at the run's start; to correct "
                "the robot, start a new run (s) and upload its table (y)")
    if outcome is Outcome.DRIFTED:
        cmd = f"'{ctx.command('calibrate')}'" if ctx is not None else "'station calibrate CONFIG'"
        return f"the robot drifted beyond the tolerance: recalibrate it ({cmd})"
    if outcome is Outcome.RECHECK_UNTRUSTED:
        return ("no verdict: check the probe head and the body, warm the robot up ([warmup]), then recheck "
                "again (s)")
    return f"{outcome.description}: see the notes below"


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
                   width: int | None = None, phase: str | None = None) -> str:
    """The result panel. First what matters at the end, so that it is in view at 80×24 without
    scrolling: for a failure what stopped the run; what to do next (every outcome); the outcome and
    the exit code; RMS before / after, the gain, after / oracle; the active table; the report; the
    exact command that resumes. Then the rest.

    ``width``: the panel's width in cells; a long value then goes on under its own column (not
    under the labels). ``phase``: the phase the run was in when it stopped (:func:`failure_kind`)."""
    lines: list[str] = []
    failure = summary.failure
    if failure is not None:
        message, _ = advice(failure, ctx, summary.run_id)
        where = f" at step {step_index + 1}" if step_index is not None else ""
        # the message says who stopped it (the operator, a signal); the head only where
        head = "ABORTED" if summary.outcome is Outcome.ABORTED else f"FAILED — {summary.outcome.name}"
        if failure_kind(summary, phase) == "correction":  # the exit code's name says identification
            head += " while building the correction table"
        lines.append(f"[b $error]{esc(head)}[/]{where}")
        lines.append(esc(message))
    elif summary.not_uploaded_reason == "correction_bound":  # not a failure to resume: the same table again
        lines.append("[b $warning]NOT UPLOADED — no correction table meets the bound[/]")
    lines.append(f"[b]Next:[/] {esc(next_step(summary, ctx, phase))}")  # the panel wraps it at its width
    if failure is not None and failure.log_file and failure.log_file not in failure.message:
        lines.append(f"traceback in {esc(failure.log_file)}")
    # two blocks, each aligned on its own labels: the first one's short labels leave its values room
    # a failure's message says what happened: the outcome's general description (which names every
    # cause of its exit code) would read as advice of its own
    described = "" if failure is not None else f" — {esc(summary.outcome.description)}"
    rows: list[tuple[str, str]] = [
        ("outcome", f"[b]{summary.outcome.name}[/]{described}"),
        ("exit code", f"[b]{summary.exit_code}[/]")]
    figures = [(label, fmt_num(value, unit, digits)) for label, value, unit, digits in summary.figures()]
    rows.extend(f for f in figures if f[0] in HEADLINE_FIGURES)
    if (table := active_table(summary)) is not None:
        rows.append(("active table", esc(table)))
    if summary.report:
        rows.append(("report", esc(summary.report)))
    resumable = summary.run_id is not None and (
        can_continue(summary, phase) or failure_kind(summary, phase) == "correction"
        or summary.not_uploaded_reason == "correction_bound")
    if ctx is not None and resumable:
        rows.append(("command", esc(ctx.command(resume=summary.run_id))))
    lines.extend(_aligned(rows, width))
    first_w = max(len(label) for label, _ in rows)
    rows = _merged({label: text for label, text in figures if label not in HEADLINE_FIGURES})
    if summary.run_id is not None:
        of = ", ".join(f"{key} {esc(value)}" for key in ("robot", "cell") if (value := getattr(summary, key)))
        rows.append(("run", f"#{summary.run_id}" + (f" ({of})" if of else "")))
    if summary.upload_skipped:
        rows.append(("upload", "skipped (the table was not sent)"))
    if summary.simulation:  # a simulated cell's judge's figures (the report's "Simulation" section)
        rows.append(("simulation", esc(", ".join(f"{f.name} {fmt_num(f.value, f.unit, 2 if f.unit == '×' else 1)}"
                                                  for f in summary.simulation))))
    for note in summary.notes:
        rows.append(("note", esc(exact_commands(note, ctx))))
    if summary.db and (failure is not None or summary.report is None):
        rows.append(("database", esc(summary.db)))
    lines.extend(_aligned(rows, width, first_w))
    return "\n".join(lines)


def _merged(figures: dict[str, str]) -> list[tuple[str, str]]:
    """The figures after the headline, two to a row where they belong together (at 80×24 the panel
    holds them without scrolling)."""
    rows = []
    pairs = (("ISO 9283 after", "AP max after (ISO 9283)", "AP max {}", "RP max after (ISO 9283)", "RP max {}"),
             ("identification", "identified parameters", "{} parameters", "identification residual RMS",
              "residual RMS {}"))
    for label, first, first_fmt, second, second_fmt in pairs:
        parts = [fmt.format(figures.pop(key)) for key, fmt in ((first, first_fmt), (second, second_fmt))
                 if key in figures]
        if parts:
            rows.append((label, ", ".join(parts)))
    if (upload := figures.pop("upload (read back, activated)", None)) is not None:
        rows.append(("upload", f"read back, active in {upload}"))
    return rows + list(figures.items())


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
