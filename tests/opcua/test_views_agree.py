"""No view computes or re-reads a figure another view shows (issue 42): one simulated calibration of
the served cell, and the table's interpolation bound, the RMS before and after and the gain as the
terminal UI states them (its lines from the stream's events, its upload and keep questions), as the
``--json`` object and the run database hold them, as the report shows them and as a real OPC UA
client reads them (over SignAndEncrypt, from the service started on that run database, then from
the run's RunFinished): one stored value each. The same table's bound once read 5.6 µm in the TUI's
upload question and 4.7 µm in the report."""

from __future__ import annotations

import asyncio

import pytest

from station.cell.records.rundb import RunDB
from station.cell.run.facts import events as ev
from station.cell.run.questions import KeepCorrection, UploadProposal
from station.cell.session.calibrate import CellRequest, run_calibration_session
from station.errors import Outcome
from station.ui.opcua.server import ServeOptions, build_server
from station.ui.report.run import report_data_for_run
from station.ui.report.tables import fmt, table_rows
from station.ui.simulated_cell import load_cell
from station.ui.tui.run_facts import fact_line
from station.ui.tui.widgets import fmt_num
from tests.opcua.clients import CONFIG, PASSWORDS, connected, read, station
from tests.opcua.conftest import free_port
from tests.short_plan import example_short

pytestmark = [pytest.mark.timeout(600)]


async def _until_read(node, idx, path: tuple[str, ...], expected, what: str) -> None:
    for _ in range(400):
        if await read(node, idx, *path) == expected:
            return
        await asyncio.sleep(0.02)
    raise AssertionError(f"timed out waiting for {what}")


async def test_the_tui_the_json_the_report_and_opc_ua_show_the_one_stored_bound(pki, tmp_path) -> None:
    db_path = tmp_path / "runs.sqlite"
    events: list[ev.Event] = []
    asked: list[object] = []

    def confirm(question: object) -> bool:  # the TUI's questions, answered yes
        asked.append(question)
        return True

    # the served cell with one visit per identification pose and one verification cycle: one stored
    # figure shown by every view is as well shown on the shorter run (issue 42: the suite's time)
    cell = example_short(CONFIG, tmp_path)
    request = CellRequest(config=str(cell), simulated=True, seed=1, db=str(db_path))
    summary = await asyncio.to_thread(run_calibration_session, request, events.append, None, confirm, load_cell)
    assert summary.outcome in (Outcome.SUCCESS, Outcome.TARGET_MISSED), summary.failure
    json = summary.to_json()  # what --json prints
    with RunDB(db_path) as db:
        stored = db.load_result(summary.run_id, "summary")
        grid = db.load_result(summary.run_id, "correction_grid")
        report = report_data_for_run(db, summary.run_id)
    bound, before, after, gain = (stored["correction"]["interpolation_bound_um"], stored["before"]["rms_um"],
                                  stored["after"]["rms_um"], stored["gain"])
    assert json.pop("db") == str(db_path)  # the session's --json names the run database it stored the run in
    assert json == stored and grid["bound_um"] == bound

    # the terminal UI: its lines are the events', its questions carry the run's figures
    (designed,) = [e for e in events if isinstance(e, ev.TableDesigned)]
    (verified,) = [e for e in events if isinstance(e, ev.Verified)]
    assert designed.correction.interpolation_bound_um == bound
    assert f"interpolation bound {fmt_num(bound, 'µm')}" in (fact_line(designed) or "")
    assert (verified.before.rms_um, verified.after.rms_um, verified.gain) == (before, after, gain)
    (proposal,) = [q for q in asked if isinstance(q, UploadProposal)]
    (keep,) = [q for q in asked if isinstance(q, KeepCorrection)]
    assert proposal.interpolation_bound_um == bound and proposal.crc32 == stored["correction"]["crc32"]
    assert (keep.rms_before_um, keep.rms_after_um, keep.gain, keep.crc32) == (before, after, gain, proposal.crc32)

    # the report: the stored summary's figures, and the parameters as the run identified and stored them
    assert report.summary is not None and report.summary.to_json() == stored
    assert ("interpolation bound", f"{fmt(bound)} µm") in table_rows(report)
    estimates = json["identification"]["parameters"]
    assert list(report.param_names) == [p["name"] for p in estimates]
    assert list(report.param_identified) == [p["value"] for p in estimates]
    assert list(report.param_sigma) == [p["sigma"] for p in estimates]
    with RunDB(db_path) as db:  # read, not computed again: a stored σ changed is the σ the report shows
        ident = db.load_result(summary.run_id, "identification")
        db.save_result(summary.run_id, "identification", {**ident, "sigma": [2 * v for v in ident["sigma"]]})
        assert list(report_data_for_run(db, summary.run_id).param_sigma) == [2 * p["sigma"] for p in estimates]
        # a stored record of other parameters is not shown as this fit's: identified again, and said
        db.save_result(summary.run_id, "identification", {**ident, "chosen": ident["chosen"][::-1]})
        again = report_data_for_run(db, summary.run_id)
        assert list(again.param_sigma) == pytest.approx([p["sigma"] for p in estimates], rel=1e-6)
        assert any("does not match the parameters" in n for n in again.notes)
        db.save_result(summary.run_id, "identification", ident)

    # OPC UA: from the run database when the service starts, then from the run's end as streamed
    opts = ServeOptions(config=str(cell), users=str(pki.users), pki=str(pki.root / "server"), host="127.0.0.1",
                        port=free_port(), simulated=True, db=str(db_path))
    server, service, url = await build_server(opts)
    async with server:
        await service.start()
        try:
            async with connected(url, pki.client_cert, pki.client_key, user="watch",
                                 password=PASSWORDS["watch"]) as client:
                idx, node = await station(client)
                last = ("LastCalibration", "InterpolationBoundMicrometre")
                await _until_read(node, idx, ("LastCalibration", "RunId"), summary.run_id, "the stored run")
                assert await read(node, idx, *last) == bound
                assert await read(node, idx, "LastCalibration", "RmsAfterMicrometre") == after
                assert await read(node, idx, "LastCalibration", "Gain") == gain
                (end,) = [e for e in events if isinstance(e, ev.RunFinished)]
                service.stream(ev.RunStarted(summary.run_id, 1))
                service.stream(end)
                await _until_read(node, idx, ("LastCalibration", "Outcome"), stored["outcome"], "the streamed end")
                assert await read(node, idx, *last) == bound
                assert await read(node, idx, "LastCalibration", "RmsBeforeMicrometre") == before
        finally:
            await service.stop()
