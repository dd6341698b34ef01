"""Issue 20, the operator's TUI at 80×24: the last screen holds the headline without scrolling,
notices wrap, a stopped run continues with one key, the command line shown is the exact one,
time left stops with the run, the probe panel shows the head's probes by id, the title names the
cell, and the advice fits the device kind (simulator, serial, TCP)."""

from __future__ import annotations

import html
import re
import tomllib
from collections import defaultdict
from pathlib import Path

import pytest
from test_tui_features import HEAD_IDS, RUNS, SUMMARY, FakeSession, frozen, head_snapshot, report_data, wait_until
from textual.widget import Widget

from drivers.controller_errors import ControllerLinkLost
from drivers.probe_protocol import ProbeTimeout
from station.cell.pipeline.outcomes import failure_summary
from station.cell.records.summary import Failure, RunSummary
from station.cell.run.facts.events import Notice, RunFinished, RunStarted
from station.cell.session.calibrate import CellRequest
from station.errors import Outcome
from station.ui.tui.app import StationApp
from station.ui.tui.launch import cell_context, make_app
from station.ui.tui.result_panel import CellContext, advice, device_kind
from station.ui.tui.widgets import ConfirmScreen, DevicePanel, device_text

ROOT = Path(__file__).resolve().parents[2]
SCARA600 = ROOT / "examples" / "scara600"
SIZE = (80, 24)
CTX = CellContext(name="example SCARA 600 cell", config="examples/scara600/cell.toml", simulated=True,
                  db="runs.sqlite", probe="simulator", controller="simulator")
REPORT = "/srv/station/runs/report-runs-run-7/report.html"
LONG_NOTICE = ("correction.max_interpolation_um = 15 holds for 4 of 5 simulated robots; if the identified "
               "robot is the fifth, the run stops after measuring: a finer grid (yaw_step_deg) avoids that")


# -- what the terminal shows ------------------------------------------------------------------
def screen_lines(app: StationApp) -> list[str]:
    """The terminal's rows as text (from the app's SVG screenshot)."""
    svg = app.export_screenshot()
    rows: dict[int, list[tuple[float, str]]] = defaultdict(list)
    cell_w = 0.0
    for m in re.finditer(r'<text class="[^"]*" x="([\d.]+)" y="[\d.]+" textLength="([\d.]+)" '
                         r'clip-path="url\(#[\w-]+-line-(\d+)\)">(.*?)</text>', svg):
        text = html.unescape(m[4]).replace("\xa0", " ")
        if text and not cell_w:
            cell_w = float(m[2]) / len(text)
        rows[int(m[3])].append((float(m[1]), text))
    lines = []
    for n in sorted(rows):
        line = ""
        for x, text in sorted(rows[n]):
            line = line.ljust(int(round(x / cell_w))) + text
        lines.append(line)
    return lines


def inside(app: StationApp, widget: Widget) -> str:
    """What the screen shows inside ``widget``'s frame, without blanks, borders or scrollbar: a
    text cut by the frame is missing here, a text wrapped at it is whole."""
    r = widget.region
    rows = screen_lines(app)[r.y + 1:r.y + r.height - 1]
    return re.sub(r"[\s│█▁▂▃▄▅▆▇▔▏▕▌▐]", "", "".join(line[r.x + 1:r.x + r.width - 1] for line in rows))


def flat(text: str) -> str:
    return re.sub(r"\s", "", text)


def app_for(session, **kw) -> StationApp:
    kw.setdefault("clock", frozen)
    return StationApp(session, list_runs=lambda: RUNS, load_results=lambda run_id: report_data(),
                      write_report=lambda run_id: Path(REPORT), db_label="runs.sqlite", cell=CTX, **kw)


async def settled(pilot, app: StationApp) -> None:
    await wait_until(pilot, lambda: app.worker is not None and app.worker.is_finished and app.summary is not None,
                     "worker ended")
    for _ in range(3):
        await pilot.pause()


# -- the last screen --------------------------------------------------------------------------
async def test_final_screen_at_80x24_shows_outcome_exit_code_figures_and_report_without_scrolling():
    app = app_for(FakeSession(gated=False, ask=False))
    async with app.run_test(size=SIZE) as pilot:
        await pilot.press("s")
        await wait_until(pilot, lambda: app.report_path is not None, "report written")
        await settled(pilot, app)
        box = app.query_one("#summary-box")
        assert box.scroll_y == 0 and box.region.bottom <= SIZE[1] - 1  # above the footer, not scrolled
        shown = inside(app, box)
        for label, value in (("outcome", "SUCCESS"), ("exitcode", "0"), ("RMSbefore", "683.4µm"),
                             ("RMSafter", "9.9µm"), ("improvementratio", "69.0×"), ("after/oracle", "0.99×"),
                             ("report", flat(REPORT))):
            assert label + value in shown, (label, shown)
        # nothing of the result panel is cut at its frame: every row is whole on the screen
        for line in app.result_text.splitlines():
            assert flat(line) in shown, line


async def test_notices_wrap_at_the_panels_width_while_running_and_after_the_end():
    def start_run(emit, control):
        emit(RunStarted(run_id=7, n_steps=3))
        emit(Notice("warning", LONG_NOTICE))
        control.checkpoint(timeout=10)
        summary = SUMMARY.replace(report=REPORT)
        emit(RunFinished(summary))
        return summary

    app = app_for(start_run)
    async with app.run_test(size=SIZE) as pilot:
        await pilot.press("s")
        await settled(pilot, app)
        notices = app.query_one("#notices")
        assert LONG_NOTICE in notices.text
        # the notice was written while the panel was wider (devices shown); it is whole at its new width
        assert flat(LONG_NOTICE) in inside(app, notices)
        assert notices.region.width < 40


async def test_running_notices_at_80x24_are_whole():
    session = FakeSession(head=True)
    app = app_for(session)
    async with app.run_test(size=SIZE) as pilot:
        await pilot.press("s")
        session.open(4)
        await wait_until(pilot, lambda: app.query_one("#measurements").row_count == 4, "4 rows")
        # the notice is laid out (wrapped to the log's width) on a later refresh than the row lands:
        # wait for the whole of it, not for one pause (a loaded CI machine saw it half drawn)
        whole = flat("probe 4 over range (+2.61 mm > +2.50 mm): tip not in contact")
        await wait_until(pilot, lambda: whole in inside(app, app.query_one("#notices")), "the notice whole")
        app.control.abort()
        session.open()  # the fake's worker waits on its gate: let it reach the checkpoint the abort ends
        await wait_until(pilot, lambda: app.state == "aborted", "aborted")  # the end lands before the app closes


# -- a stopped run: one key continues it; the command line is the exact one --------------------
async def test_after_an_abort_one_key_continues_the_run_and_the_command_is_exact():
    session = FakeSession(ask=False)
    app = app_for(session)
    async with app.run_test(size=SIZE) as pilot:
        await pilot.press("c")  # nothing to continue yet: no run starts
        await pilot.pause()
        assert session.resumed == [] and "Continue" not in screen_lines(app)[-1]
        await pilot.press("s")
        session.open(3)
        await wait_until(pilot, lambda: app.query_one("#measurements").row_count == 3, "3 rows")
        await pilot.press("a")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen), "abort?")
        await pilot.press("y")
        session.open()
        await wait_until(pilot, lambda: app.state == "aborted", "aborted")
        await settled(pilot, app)
        text = app.result_text
        assert ("station calibrate --simulated examples/scara600/cell.toml --db runs.sqlite --resume 7"
                in " ".join(text.split()))
        assert "CONFIG" not in text
        footer = screen_lines(app)[-1]
        assert "c Continue run" in footer and "q Quit" in footer  # 80 columns hold the keys that apply
        assert "c continue run #7" in screen_lines(app)[1]
        await pilot.press("c")
        session.open(10)
        await wait_until(pilot, lambda: app.state == "finished", "finished")
        assert session.resumed == [None, 7]


def test_the_command_line_is_the_one_the_ui_was_started_with():
    request = CellRequest(config="examples/scara600/cell.toml", simulated=True, seed=3, db="/data/my runs.sqlite")
    ctx = cell_context(request)
    assert ctx.command(resume=4) == ("station calibrate --simulated --seed 3 examples/scara600/cell.toml "
                                     "--db '/data/my runs.sqlite' --resume 4")
    assert cell_context(request, recheck=True).command(resume=2).startswith("station recheck --simulated")
    assert CellContext(config="cell.toml", db="runs.sqlite").command("reset") == "station reset cell.toml"
    builtin = cell_context(CellRequest(simulated=True, robot="irb2600", db="r.sqlite"))
    assert builtin.command() == "station calibrate --simulated --robot irb2600 --db r.sqlite"


# -- time left --------------------------------------------------------------------------------
@pytest.mark.parametrize("end", ["abort", "finish"])
async def test_time_left_stops_when_the_run_stops(end):
    session = FakeSession(ask=False)
    now = [0.0]
    app = app_for(session, clock=lambda: now[0])
    async with app.run_test(size=SIZE) as pilot:
        await pilot.press("s")
        for _ in range(2):
            now[0] += 10.0
            session.open()
        await wait_until(pilot, lambda: app.query_one("#measurements").row_count == 2, "2 rows")
        assert app.eta.remaining_s() is not None and "left" in app.eta.text()
        if end == "abort":
            await pilot.press("a")
            await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen), "abort?")
            await pilot.press("y")
            session.open()
        else:
            session.open(10)
        await settled(pilot, app)
        eta = app.query_one("#eta")
        shown = str(eta.render())
        now[0] += 3600.0
        app._show_eta()
        assert str(eta.render()) == shown and shown.startswith("ran ") and "left" not in shown
        assert app.eta.remaining_s() is None and not app.eta.running


# -- the probe panel and the title ------------------------------------------------------------
def test_probe_panel_shows_the_heads_probes_by_id_and_no_unwired_channel():
    text = device_text(head_snapshot(over=True), 44).plain
    for probe in HEAD_IDS:
        assert f"{probe} " in text
    assert "P4" not in text and "P8" not in text and "INVAL" not in text
    assert text.count("OVER") == 1  # the one probe over its range, by its id
    assert re.search(r"X1 ▕▒+▏\s+OVER", text)
    assert max(len(line) for line in text.splitlines()) <= 44


def test_title_names_the_cell_and_devices_have_their_kind(tmp_path):
    ctx = cell_context(CellRequest(config=str(SCARA600 / "cell.toml"), simulated=True))
    assert ctx.name == "example SCARA 600 cell" and ctx.title() == "example SCARA 600 cell · simulated"
    assert ctx.probe == ctx.controller == "simulator"
    real = cell_context(CellRequest(config=str(SCARA600 / "cell.toml")))
    assert real.title() == "example SCARA 600 cell" and real.probe == "serial" and real.controller == "tcp"
    assert device_kind("socket://10.0.0.7:4001") == "tcp" and device_kind("COM3") == "serial"
    # the built-in cell: its configuration is written when a run starts, so the title does not name it
    assert cell_context(CellRequest(simulated=True)).title() == "built-in simulated cell"
    assert cell_context(CellRequest(simulated=True, robot="irb2600")).title() == "built-in simulated cell (irb2600)"
    assert "Recheck" in cell_context(CellRequest(simulated=True), recheck=True).title()


@pytest.mark.slow
async def test_rehearsal_of_the_example_cell_through_the_ui(tmp_path):
    """examples/scara600 rehearsed: the title is its [cell] name, the probe panel its head file's
    seven probes (channel 4 is not wired), and an abort is continued with one key on the same run."""
    db = str(tmp_path / "runs.sqlite")
    app = make_app(CellRequest(config=str(SCARA600 / "cell.toml"), simulated=True, db=db))
    head = tomllib.loads((SCARA600 / "head.toml").read_text(encoding="utf-8"))
    ids = tuple(p["id"] for p in head["probe"])
    assert len(ids) == 7 and 4 not in [p["channel"] for p in head["probe"]]
    async with app.run_test(size=SIZE) as pilot:
        assert str(app.title).startswith("example SCARA 600 cell")
        await pilot.press("s")
        panel = app.query_one(DevicePanel)
        await wait_until(pilot, lambda: panel.snapshot is not None, "a reading", 6000)
        assert panel.snapshot.probe_ids == ids and len(panel.snapshot.probe_mm) == 7
        text = device_text(panel.snapshot, 44).plain
        assert all(f"{i} " in text for i in ids) and "P4" not in text and "INVAL" not in text
        await pilot.press("a")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen), "abort?")
        await pilot.press("y")
        await wait_until(pilot, lambda: app.worker.is_finished and app.summary is not None, "aborted", 6000)
        run_id = app.summary.run_id
        assert app.exit_code == 6 and run_id is not None
        line = " ".join(app.result_text.split())
        assert f"station calibrate --simulated {SCARA600 / 'cell.toml'} --db {db} --resume {run_id}" in line
        await pilot.press("c")
        await wait_until(pilot, lambda: app.running and app.run_id == run_id, "continued", 6000)
        await pilot.press("a")
        await wait_until(pilot, lambda: isinstance(app.screen, ConfirmScreen), "abort?")
        await pilot.press("y")
        await wait_until(pilot, lambda: app.worker.is_finished and app.summary is not None, "aborted again", 6000)
        assert app.summary.run_id == run_id


# -- advice for the device kind ---------------------------------------------------------------
LINK_LOST = ("controller heartbeat did not advance for 3.10 s (limit 3.00 s): the robot program or the link is "
             "down; check the robot program and the link, then start the run again")


def failure_of(exc: BaseException, run_id: int | None = 7) -> Failure:
    """The failure as the session reports it: classified by type in the cell layer."""
    failure = failure_summary(exc, run_id=run_id, log_dir=".").failure
    assert failure is not None
    return failure


def test_a_simulator_gets_no_network_or_api_advice():
    message, hint = advice(failure_of(ControllerLinkLost(LINK_LOST)), CTX, 7)
    for words in ("network", "cable", "connect()", "CONFIG"):
        assert words not in message + hint, words
    assert "simulated controller" in hint and "then press c to continue run #7" in hint
    message, hint = advice(failure_of(ProbeTimeout("no reply within 2 s from socket://127.0.0.1:4711")), CTX, 7)
    assert "simulated probe interface" in hint and "cable" not in hint and "baudrate" not in hint


def test_serial_and_tcp_devices_keep_their_own_advice():
    tcp = CellContext(name="cell", config="cell.toml", db="runs.sqlite", probe="serial", controller="tcp")
    message, hint = advice(failure_of(ControllerLinkLost(LINK_LOST)), tcp, 7)
    assert "connect()" not in message and "network cable" in hint  # a real link: check it
    assert "then press c to continue run #7" in hint
    _, serial_hint = advice(failure_of(ProbeTimeout("no reply within 2 s")), tcp, 7)
    assert "probe cable and [devices].baudrate" in serial_hint
    net = CellContext(name="cell", config="cell.toml", db="runs.sqlite", probe="tcp", controller="tcp")
    _, net_hint = advice(failure_of(ProbeTimeout("no reply within 2 s")), net, 7)
    assert "network link to the probe interface" in net_hint and "baudrate" not in net_hint
    reset = Failure("EmergencyStop", "e-stop", "release it, then 'station reset CONFIG'")
    assert "'station reset cell.toml'" in advice(reset, tcp, 7)[1]


async def test_the_result_panel_of_a_simulated_link_loss_says_what_fits_a_simulator():
    failure = failure_of(ControllerLinkLost(LINK_LOST))

    def start_run(emit, control):
        emit(RunStarted(run_id=7, n_steps=3))
        return RunSummary(Outcome.DEVICE_FAULT, run_id=7, db="runs.sqlite", failure=failure)

    app = app_for(start_run)
    async with app.run_test(size=SIZE) as pilot:
        await pilot.press("s")
        await settled(pilot, app)
        text = app.result_text
        assert app.exit_code == 7 and "simulated controller" in text
        assert "network" not in text and "connect()" not in text
        assert "network" not in app.query_one("#notices").text
