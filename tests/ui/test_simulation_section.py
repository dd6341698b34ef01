"""A simulated run's judge's figures where people read them (issue 42): the report's "Simulation"
section and the TUI's result panel; a real run's report and panel have neither."""

from __future__ import annotations

import dataclasses

from station.cell.records.judge import JudgeFigure
from station.ui.report.render.html_page import render_html
from station.ui.report.render.markdown_page import render_markdown
from station.ui.tui.result_panel import summary_markup
from tests.ui.test_report import make_data

FIGURES = (JudgeFigure("base_frame_nominal_um", 386.0, "µm", "through the robot file's model"),
           JudgeFigure("base_frame_corrected_um", 166.0, "µm", "through the identified model"),
           JudgeFigure("base_frame_reference_um", 166.2, "µm", "the best a body calibration can reach"),
           JudgeFigure("base_frame_ratio", 0.9988, "×", "corrected ÷ reference"))


def _simulated(d):
    return dataclasses.replace(d, summary=d.summary.replace(simulation=FIGURES))


def test_the_report_has_a_simulation_section_only_for_a_judged_run():
    real = make_data()
    sim = _simulated(real)
    md, html = render_markdown(sim), render_html(sim)
    assert "## Simulation" in md and "| base_frame_ratio | corrected ÷ reference | 1.00 × |" in md
    assert "| base_frame_corrected_um | through the identified model | 166.0 µm |" in md
    assert '<section id="simulation"><h2>Simulation</h2>' in html and 'id="simulation-table"' in html
    assert "Simulation" not in render_markdown(real) and 'id="simulation"' not in render_html(real)


def test_the_result_panel_shows_the_judges_figures_with_units():
    s = make_data().summary
    text = summary_markup(s.replace(simulation=FIGURES), width=200)
    line = next(x for x in text.splitlines() if x.startswith("simulation"))
    assert "base_frame_corrected_um 166.0 µm" in line and "base_frame_ratio 1.00 ×" in line
    assert not any(x.startswith("simulation") for x in summary_markup(s, width=200).splitlines())
