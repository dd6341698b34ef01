"""Calibration report: one self-contained ``report.html`` (the QA record: plots embedded as PNG
data URIs, printable) and ``report.md`` beside it (the same tables as text, for diffs).

The caller (:mod:`station.ui.report.run` for a stored run) fills a :class:`ReportData`
(:mod:`~station.ui.report.contents`); the other ``report_*`` modules only format it, in a tree with
this module at its top: :mod:`~station.ui.report.tables` (rows shared by both files) and
:mod:`~station.ui.report.render.plots` read the data, :mod:`~station.ui.report.render.html_page` and
:mod:`~station.ui.report.render.markdown_page` read those, and this module writes the files. Inputs use the
station's internal units (mm and rad, see :mod:`station.core.kinematics.model`) except the verification
errors, which are µm already; the report shows µm and arc seconds.

Plots are drawn with matplotlib's Agg canvas on explicit ``Figure`` objects (no pyplot, no
global backend switch), so writing a report is safe in a headless process or a UI worker.
"""

from __future__ import annotations

from pathlib import Path

from station.ui.report.contents import HTML_NAME, MARKDOWN_NAME, ReportData, TrendRun
from station.ui.report.render.html_page import render_html
from station.ui.report.render.markdown_page import render_markdown

__all__ = ["ReportData", "TrendRun", "write_report", "HTML_NAME", "MARKDOWN_NAME"]


def _write_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(path)


def write_report(out_dir: Path, report: ReportData, *, markdown: bool = True) -> Path:
    """Write ``report.html`` (self-contained) and, with ``markdown``, ``report.md`` into
    ``out_dir`` (created); return the HTML path."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    html_path = out_dir / HTML_NAME
    _write_atomic(html_path, render_html(report))
    if markdown:
        _write_atomic(out_dir / MARKDOWN_NAME, render_markdown(report))
    return html_path
