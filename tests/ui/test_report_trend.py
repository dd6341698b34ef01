"""The report's trend (issue 13, point 4): the robot's calibrations and rechecks up to this run,
as a table and an embedded plot in report.html and the table in report.md; no section for a run
that has no history. Checked on crafted data and on a run database with real runs."""

from __future__ import annotations

import base64

import pytest
from test_report import make_data
from test_report_html import Page, assert_self_contained, column

from station.cell.records.rundb import RunDB
from station.ui.cli.main import main
from station.ui.report.render import plots as report_plots
from station.ui.report.run import report_data_for_run
from station.ui.report.tables import has_trend
from station.ui.report.writer import ReportData, TrendRun, write_report

HISTORY = (
    TrendRun(1, "2026-01-10T08:00:00Z", "calibration", "SUCCESS", rms_after_um=12.5),
    TrendRun(5, "2026-02-10T08:00:00Z", "recheck", "SUCCESS", drift_rms_um=8.0, drift_tolerance_um=30.0, baseline=1),
    TrendRun(9, "2026-03-10T08:00:00Z", "recheck", "DRIFTED", drift_rms_um=41.2, drift_tolerance_um=30.0,
             moved=("A2.yaw", "A3.x"), baseline=1),
)


_PNG = b"\x89PNG\r\n\x1a\n" + b"\0" * 8


@pytest.fixture
def fast_plots(monkeypatch):
    """The other sections' plots as a stub PNG (they have their own tests): the crafted reports
    render in a fraction of a second; the trend plot is drawn for real."""
    for name in ("plot_residuals", "plot_parameters", "plot_accuracy", "plot_verification"):
        monkeypatch.setattr(report_plots, name, lambda *a, **k: _PNG)


def with_trend(trend: tuple[TrendRun, ...]) -> ReportData:
    d = make_data()
    return type(d)(**{**d.__dict__, "trend": trend})


def trend_images(page: Page) -> list[str]:
    return [v for tag, key, v in page.links if tag == "img" and key == "src"]


def test_trend_table_and_plot_from_data(tmp_path, fast_plots):
    this = TrendRun(42, "2026-04-01T09:30:12.5Z", "calibration", "SUCCESS", rms_after_um=11.0)
    d = with_trend((this, *reversed(HISTORY)))  # any order in, run order out
    html = write_report(tmp_path, d).read_text(encoding="utf-8")
    page = Page(html)
    assert page.sections[-2:] == ["trend", "signoff"]  # the trend last before the signatures
    assert_self_contained(page)
    table = page.tables["trend-table"]
    assert column(table, "run") == ["1", "5", "9", "42"]
    assert column(table, "kind") == ["calibration", "recheck of run 1", "recheck of run 1", "calibration"]
    assert column(table, "outcome") == ["SUCCESS", "SUCCESS", "DRIFTED", "SUCCESS"]
    assert column(table, "RMS after / drift RMS µm") == ["12.5", "8.0", "41.2", "11.0"]
    assert column(table, "tolerance µm") == ["—", "30.0", "30.0", "—"]
    assert column(table, "moved parameters") == ["—", "none", "A2.yaw, A3.x", "—"]
    assert column(table, "date (UTC)")[-1] == "2026-04-01 09:30"
    assert page.cell_classes["trend-table"][-1] and "this-run" in html
    # the plot: one more image than without the trend, a PNG data URI, inside the trend section
    trend_html = html[html.index('<section id="trend">'):]
    img = [v for v in trend_images(Page(trend_html))]
    assert len(img) == 1 and img[0].startswith("data:image/png;base64,")
    assert base64.b64decode(img[0].split(",", 1)[1])[:8] == b"\x89PNG\r\n\x1a\n"
    assert len(trend_images(page)) == len(trend_images(Page(write_report(tmp_path / "no", make_data())
                                                            .read_text(encoding="utf-8")))) + 1
    md = (tmp_path / "report.md").read_text(encoding="utf-8")
    assert "## Trend" in md and "| **42** |" in md and "A2.yaw, A3.x" in md


@pytest.mark.parametrize("trend", [(), (TrendRun(42, "2026-04-01T09:30:00Z", "calibration", "SUCCESS", 11.0),)])
def test_no_trend_section_for_a_single_run(tmp_path, trend, fast_plots):
    page = Page(write_report(tmp_path, with_trend(trend)).read_text(encoding="utf-8"))
    assert "trend" not in page.sections and "trend-table" not in page.tables
    assert not any(v == "#trend" for _, _, v in page.links)  # not in the table of contents either
    assert "## Trend" not in (tmp_path / "report.md").read_text(encoding="utf-8")


def test_trend_without_figures_has_table_but_no_plot(tmp_path, fast_plots):
    runs = (TrendRun(1, "", "calibration", "", status="aborted"), TrendRun(2, "", "calibration", "NOT_UPLOADED"))
    page = Page(write_report(tmp_path, with_trend(runs)).read_text(encoding="utf-8"))
    assert column(page.tables["trend-table"], "outcome") == ["unfinished (aborted)", "NOT_UPLOADED"]
    assert len(trend_images(page)) == len(trend_images(Page(write_report(tmp_path / "no", make_data())
                                                            .read_text(encoding="utf-8"))))


# ----------------------------------------------------------------------------- real runs
@pytest.fixture(scope="module")
def history(tmp_path_factory, seed1_run, short_cell):
    """Run 1: a calibration (uploaded; the suite's seed-1 run, copied), run 2: a recheck against it,
    run 3: a calibration without upload whose report is written at its end (the same built-in cell
    with one visit per identification pose and one verification cycle: a trend row is a trend row,
    issue 42)."""
    root = tmp_path_factory.mktemp("trend")
    db = seed1_run.copy_to(root, report_name="rep-1").db
    assert main(["recheck", "--simulated", "--seed", "1", "--db", str(db)]) == 0
    assert main(["calibrate", "--simulated", str(short_cell), "--seed", "1", "--no-upload", "--db", str(db),
                 "--report", str(root / "rep")]) == 11  # NOT_UPLOADED
    return db, root / "rep"


def test_trend_from_the_run_database(history):
    db, rep = history
    html = (rep / "report.html").read_text(encoding="utf-8")
    page = Page(html)
    assert_self_contained(page)
    table = page.tables["trend-table"]
    assert column(table, "run") == ["1", "2", "3"]
    assert column(table, "kind") == ["calibration", "recheck of run 1", "calibration"]
    assert column(table, "outcome")[2] == "NOT_UPLOADED"
    figures = column(table, "RMS after / drift RMS µm")
    assert figures[0] != "—" and figures[1] != "—" and figures[2] == "—"  # run 3: nothing uploaded
    assert column(table, "tolerance µm")[1] != "—" and column(table, "moved parameters")[1] == "none"
    start = html.index('<section id="trend">')  # the trend section alone (the cell's picture follows it)
    trend_img = trend_images(Page(html[start:html.index("</section>", start)]))
    assert len(trend_img) == 1 and trend_img[0].startswith("data:image/png;base64,")
    assert "## Trend" in (rep / "report.md").read_text(encoding="utf-8")
    # run 1: the history up to run 1 is run 1 alone, so its report has no trend section
    with RunDB(db) as d:
        data = report_data_for_run(d, 1)
    assert [(r.run_id, r.kind, r.outcome) for r in data.trend] == [(1, "calibration", "SUCCESS")]
    assert not has_trend(data)
