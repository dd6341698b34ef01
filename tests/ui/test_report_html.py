"""The HTML report as a QA record, checked with an HTML parser: sections, no external resources,
parameters split, correlations, both elbows in the verification of a simulated run, and a clear
error for a run that has nothing to report."""

from __future__ import annotations

import base64
import sqlite3
from html.parser import HTMLParser

import numpy as np
import pytest
from test_report import make_data

from station.cell.records.rundb import RunDB
from station.cell.records.summary import ReversalSummary
from station.ui.cli.main import main
from station.ui.report.run import report_data_for_run, report_for_run
from station.ui.report.writer import write_report

SECTIONS = ["summary", "conditions", "traceability", "record", "parameters", "residuals", "verification", "accuracy",
            "table", "reversal", "signoff"]


class Page(HTMLParser):
    """Sections in order, every src/href, images, and each table with an id as rows of cell texts."""

    def __init__(self, text: str):
        super().__init__(convert_charrefs=True)
        self.sections: list[str] = []
        self.links: list[tuple[str, str, str]] = []  # (tag, attribute, value)
        self.tags: list[str] = []
        self.tables: dict[str, list[list[str]]] = {}
        self.cell_classes: dict[str, list[list[str]]] = {}
        self.texts: dict[str, str] = {}
        self._table: str | None = None
        self._row: list[str] | None = None
        self._row_cls: list[str] | None = None
        self._cell: list[str] | None = None
        self._capture: list[tuple[str, str, list[str]]] = []  # (id, tag, text)
        self.feed(text)
        self.close()

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        self.tags.append(tag)
        for key in ("src", "href"):
            if a.get(key) is not None:
                self.links.append((tag, key, a[key]))
        if tag == "section":
            self.sections.append(a.get("id", ""))
        if a.get("id"):
            self._capture.append((a["id"], tag, []))
        if tag == "table" and a.get("id"):
            self._table = a["id"]
            self.tables[self._table] = []
            self.cell_classes[self._table] = []
        elif tag == "tr" and self._table:
            self._row, self._row_cls = [], []
        elif tag in ("td", "th") and self._row is not None:
            self._cell = []
            assert self._row_cls is not None
            self._row_cls.append(a.get("class") or "")

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self._cell is not None and self._row is not None:
            self._row.append("".join(self._cell).strip())
            self._cell = None
        elif tag == "tr" and self._row is not None and self._table:
            self.tables[self._table].append(self._row)
            self.cell_classes[self._table].append(self._row_cls or [])
            self._row = None
        elif tag == "table":
            self._table = None
        if self._capture and self._capture[-1][1] == tag:
            ident, _, text = self._capture.pop()
            self.texts[ident] = "".join(text)

    def handle_data(self, data):
        if self._cell is not None:
            self._cell.append(data)
        for _, _, text in self._capture:
            text.append(data)


def assert_self_contained(page: Page) -> None:
    assert "script" not in page.tags and "link" not in page.tags and "iframe" not in page.tags
    images = [v for tag, key, v in page.links if tag == "img"]
    assert images and all(v.startswith(("data:image/png;base64,", "data:image/svg+xml;base64,")) for v in images)
    for v in images:  # the plots as PNG, the cell's picture as SVG (issue 40)
        data = base64.b64decode(v.split(",", 1)[1])
        assert data[:8] == b"\x89PNG\r\n\x1a\n" if v.startswith("data:image/png") else b"<svg" in data[:400]
    others = [v for tag, key, v in page.links if tag != "img"]
    assert all(v.startswith("#") for v in others), others  # only links within the page
    assert not any("http:" in v or "https:" in v or "file:" in v for _, _, v in page.links)


def column(table: list[list[str]], name: str) -> list[str]:
    i = table[0].index(name)
    return [r[i] for r in table[1:]]


def test_html_structure_from_data(tmp_path):
    d = make_data()
    page = Page(write_report(tmp_path, d).read_text(encoding="utf-8"))
    assert page.sections == SECTIONS  # the summary first
    assert_self_contained(page)
    # parameters: set-up, robot, head apart
    # (lengths and angles apart: one unit per column)
    assert column(page.tables["params-setup-lengths"], "parameter") == ["R.x"]
    assert "params-setup-angles" not in page.tables
    assert column(page.tables["params-robot-lengths"], "parameter") == ["A2.x", "A3.x", "A3.z"]
    assert column(page.tables["params-robot-angles"], "parameter") == ["A1.roll", "A2.pitch"]
    assert page.tables["params-robot-angles"][0] == ["parameter", "nominal °", "identified °", "Δ ″", "σ ″"]
    assert column(page.tables["params-head-lengths"], "parameter") == ["K.z"]
    assert column(page.tables["params-head-angles"], "parameter") == ["K.yaw"]
    # correlations: the matrix is p × p, the strong pair is listed and marked, nothing else is
    m = page.tables["correlation-matrix"]
    assert len(m) == 1 + 8 and all(len(r) == 1 + 8 for r in m)
    assert page.tables["strong-correlations"][1] == ["A2.x", "A2.pitch", "+0.950"]
    strong = [(i, j) for i, r in enumerate(page.cell_classes["correlation-matrix"][1:])
              for j, c in enumerate(r[1:]) if "strong" in c]
    assert sorted(strong) == [(1, 5), (5, 1)]
    # verification: point and elbow per row, both elbows, no row twice
    v = page.tables["verification-table"]
    assert v[0][:3] == ["point", "elbow", "cycles"]
    rows = v[1:-1]
    assert {r[1] for r in rows} == {"+1", "-1"}
    assert len({(r[0], r[1]) for r in rows}) == len(rows) == 4
    assert v[-1][0] == "all poses"
    # the summary shows the outcome once (banner), the figures once each
    summary = page.tables["summary-table"]
    labels = [r[0] for r in summary]
    assert len(labels) == len(set(labels)) and "outcome" not in labels
    assert page.texts["outcome"].startswith("SUCCESS") and "exit code 0" in page.texts["outcome"]
    # what the predicted accuracy includes, and the count of what was evaluated
    scope = page.texts["accuracy-scope"]
    assert "parameter uncertainty only" in scope and "repeatability" in scope and "probe noise" in scope
    acc = page.tables["accuracy-table"]
    assert sum(int(x) for x in column(acc, "points")) == d.accuracy_sigma_mm.size
    # the record: configuration (escaped, intact), version, devices
    assert page.texts["config"] == '[cell]\nname = "test <cell> & co"\n'
    record = dict((r[0], r[1]) for r in page.tables["record-table"])
    assert record["station version"] == "9.9.9" and record["controller map version"] == "3"
    assert "reversal-none" in page.texts  # not measured, and it says so


def test_html_without_upload_and_with_reversal(tmp_path):
    d = make_data(after=False)
    d = type(d)(**{**d.__dict__, "devices": None,
                   "summary": d.summary.replace(reversal=ReversalSummary(8, 95.2, 130.4))})  # type: ignore[union-attr]
    page = Page(write_report(tmp_path, d).read_text(encoding="utf-8"))
    assert_self_contained(page)
    v = page.tables["verification-table"]
    assert v[0] == ["point", "elbow", "cycles", "before RMS µm"]
    assert page.texts["outcome"].startswith("NOT_UPLOADED")
    assert dict(page.tables["reversal-table"])["RMS"] == "95.2 µm"
    record = dict((r[0], r[1]) for r in page.tables["record-table"])
    assert record["devices"].startswith("not recorded")


# ----------------------------------------------------------------------------- a simulated run
@pytest.fixture(scope="module")
def simulated_run(tmp_path_factory, seed1_run):
    run = seed1_run.copy_to(tmp_path_factory.mktemp("report-run"))  # calibrate --seed 1 --report, once
    return run.db, run.report


def test_simulated_run_report(simulated_run):
    db, rep = simulated_run
    html = rep / "report.html"
    assert html.is_file() and (rep / "report.md").is_file()
    page = Page(html.read_text(encoding="utf-8"))
    # a simulated run's judge adds its Simulation section before the sign-off (issue 42); a real run's
    # report has none (test above); a stored run's plan gets the cell's picture (issue 40)
    assert page.sections == [*SECTIONS[:-1], "simulation", "cell", "signoff"]
    assert_self_contained(page)
    assert len([v for tag, _, v in page.links if tag == "img"]) == 6
    with RunDB(db) as d:
        judged = report_data_for_run(d, 1).summary.simulation
    assert judged and [r[0] for r in page.tables["simulation-table"][1:]] == [f.name for f in judged]
    # the verification table shows both elbows, one row per held-out pose
    v = page.tables["verification-table"]
    assert "elbow" in v[0] and "oracle RMS µm" in v[0]
    rows = v[1:-1]
    assert {r[1] for r in rows} == {"+1", "-1"}
    assert len({(r[0], r[1]) for r in rows}) == len(rows)
    assert [r[0] for r in page.tables["verification-elbows"][1:]] == ["+1", "-1"]
    # set-up apart from the robot: R.x (mm off) is not among the robot's own parameters
    assert "R.x" in column(page.tables["params-setup-lengths"], "parameter")
    robot = column(page.tables["params-robot-lengths"], "parameter") + column(page.tables["params-robot-angles"], "parameter")
    assert not any(n.startswith(("R.", "K.")) for n in robot)
    head = column(page.tables["params-head-lengths"], "parameter") + column(page.tables["params-head-angles"], "parameter")
    assert all(n.startswith("K.") for n in head)
    # the record
    record = dict((r[0], r[1]) for r in page.tables["record-table"])
    assert record["station version"] and "DL-RS1A" in record["probe interface"]
    assert "[robot]" in page.texts["config"]
    # the table rebuilt from the stored measurements is the one uploaded
    facts = dict((r[0], r[1]) for r in page.tables["table-facts"])
    assert facts["rebuilt from the stored measurements"] == "same CRC-32"
    # the correlation matrix and its marks agree with the covariance
    with RunDB(db) as d:
        data = report_data_for_run(d, 1)
    c = data.param_correlation
    assert c is not None and c.shape == (len(data.param_names),) * 2
    assert np.allclose(c, c.T, equal_nan=True) and np.allclose(np.diag(c), 1.0)
    strong = {(i, j) for i, r in enumerate(page.cell_classes["correlation-matrix"][1:])
              for j, cls in enumerate(r[1:]) if "strong" in cls}
    expected = {(i, j) for i, j in zip(*np.nonzero(np.abs(c) > 0.9)) if i != j}
    assert strong == expected
    # every evaluated accuracy point is counted, and the labels are what the report says
    acc = page.tables["accuracy-table"]
    assert sum(int(x) for x in column(acc, "points")) == data.accuracy_sigma_mm.size
    assert column(acc, "elbow") == ["+1", "-1"]


def test_rebuilt_report_returns_the_html(simulated_run, tmp_path):
    db, _ = simulated_run
    path = report_for_run(db, 1, tmp_path / "again")
    assert path == tmp_path / "again" / "report.html" and (tmp_path / "again" / "report.md").is_file()


def test_a_run_without_identification_gets_a_report_saying_how_far_it_got(simulated_run, tmp_path, capsys):
    """Every run that ends gets a report (issue 29): one stopped before any measurement says so,
    and how to finish it, instead of exiting without one."""
    db, _ = simulated_run
    copy = tmp_path / "copy.sqlite"
    with sqlite3.connect(db) as src, sqlite3.connect(copy) as dst:
        src.backup(dst)
    with RunDB(copy) as d:
        run = d.run(1)
        rid = d.create_run(run.config_toml, list(run.plan), seed=1)
        d.set_status(rid, "aborted")
    assert main(["report", str(rid), "--db", str(copy), "-o", str(tmp_path / "r2")]) == 0
    assert "Traceback" not in capsys.readouterr().err
    page = Page((tmp_path / "r2" / "report.html").read_text(encoding="utf-8"))
    assert page.texts["progress"].startswith("How far the run got: The run has no stored outcome (database status "
                                             "'aborted'")
    assert f"Steps measured: 0 of {len(run.plan)}" in page.texts["progress"]
    text = (tmp_path / "r2" / "report.md").read_text(encoding="utf-8")
    assert f"--resume {rid}" in text and "No parameters: nothing identified." in text


def test_simulated_run_signoff(simulated_run, tmp_path):
    """The sign-off items of a real (simulated) run: banner, conditions, AP/RP per pose, traceability;
    an --operator is kept with the run for the rebuilt report."""
    db, rep = simulated_run
    page = Page((rep / "report.html").read_text(encoding="utf-8"))
    assert "simulated-banner" in page.texts
    iso = page.tables["iso-table"]
    poses = page.tables["poses-table"]
    assert len(iso) - 2 == len(poses) - 1 == len(page.tables["verification-table"]) - 2  # header, 'largest' / total
    assert all(r[2] == "5 / 5" for r in iso[1:-1])  # the simulated cell's 5 ISO 9283 cycles, before and after
    cond = dict(page.tables["conditions-table"])
    assert "5 ISO 9283 cycles" in cond["verification"] and cond["speed"].endswith("of the robot's maximum")
    tr = dict(page.tables["traceability-table"])
    assert tr["operator"].startswith("not recorded") and tr["Python"][0].isdigit()
    copy = tmp_path / "copy.sqlite"
    with sqlite3.connect(db) as src, sqlite3.connect(copy) as dst:
        src.backup(dst)
    assert main(["report", "1", "--db", str(copy), "-o", str(tmp_path / "a"), "--operator", "J. Smith"]) == 0
    again = report_for_run(copy, 1, tmp_path / "b")  # no --operator: the recorded one
    tr = dict(Page(again.read_text(encoding="utf-8")).tables["traceability-table"])
    assert tr["operator"] == "J. Smith (recorded with the run's report)"
