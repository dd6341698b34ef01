"""The operator UI states the run's figures from the run's stream (issue 42): the table's bound,
the identification's residual, the upload's CRC and the verification's gain are the events'
figures, shown while the run goes on (headless, with Textual's Pilot)."""

from __future__ import annotations

from station.cell.records.summary import (
    CorrectionSummary,
    ErrorStats,
    IdentificationSummary,
    ParameterEstimate,
    RunSummary,
    UploadSummary,
)
from station.cell.run.facts.events import (
    Identified,
    PhaseChanged,
    RunFinished,
    RunStarted,
    TableDesigned,
    Uploaded,
    Verified,
)
from station.cell.run.facts.stream import RunStream
from station.errors import Outcome
from station.ui.tui.app import StationApp
from station.ui.tui.run_facts import fact_line
from tests.ui.test_tui import wait_until

IDENT = IdentificationSummary(objective="pose", n_measurements=48, n_parameters=20, rms_normalized=1.07,
                              rms_residual_um=8.64, outliers=(), parameters=(ParameterEstimate("A2.x", 445.01, 2e-3),))
TABLE = CorrectionSummary(n_values=31680, interpolation_bound_um=4.73, crc32="1a2b3c4d", predicted_bound_um=5.2,
                          grid_shape=(12, 11, 3, 8), limit_um=10.0)
UPLOAD = UploadSummary(crc32="1a2b3c4d", seconds=1.87)
BEFORE = ErrorStats(n=24, rms_um=612.3, max_um=900.0, ap_max_um=700.0, rp_max_um=None)
AFTER = ErrorStats(n=24, rms_um=17.25, max_um=30.0, ap_max_um=20.0, rp_max_um=None)
SUMMARY = RunSummary(outcome=Outcome.SUCCESS, run_id=5, identification=IDENT, correction=TABLE, upload=UPLOAD,
                     before=BEFORE, after=AFTER)
FACTS = (Identified(IDENT, (0.0,) * 36), TableDesigned(TABLE), Uploaded(UPLOAD, "1a2b3c4d", "none"),
         Verified(BEFORE, AFTER, SUMMARY.gain))


def test_each_figure_line_states_its_events_figures():
    ident, table, upload, verified = (fact_line(e) for e in FACTS)
    assert ident is not None and "20 parameters from 48 measurements" in ident and "8.6 µm" in ident
    assert table == ("correction table: grid 12×11×3×8, 31680 values, CRC-32 1a2b3c4d, interpolation bound 4.7 µm "
                     "(limit 10.0 µm)")
    assert upload is not None and "1a2b3c4d" in upload and "1.87 s" in upload
    assert verified == "verified: RMS before 612.3 µm, after 17.2 µm, gain 35.5 ×"
    assert fact_line(PhaseChanged("identify")) is None


async def test_the_tui_shows_the_events_figures_as_the_run_streams_them():
    seen: list[object] = []

    def start_run(emit, control):
        stream = RunStream(emit)  # the session's stream: the TUI and another view subscribe alike
        stream.subscribe(seen.append, TableDesigned)
        stream(RunStarted(run_id=5, n_steps=1))
        stream(PhaseChanged("correct"))
        for fact in FACTS:
            stream(fact)
        stream(RunFinished(SUMMARY))
        return SUMMARY

    app = StationApp(start_run)
    async with app.run_test(size=(120, 40)) as pilot:
        await pilot.press("s")
        await wait_until(pilot, lambda: app.state == "finished", "run finished")
        notices = " ".join(app.query_one("#notices").text.split())
    assert seen == [FACTS[1]]
    for fact in FACTS:
        line = fact_line(fact)
        assert line is not None and " ".join(line.split()) in notices
    assert "interpolation bound 4.7 µm" in notices  # the event's bound, the one the run stored
