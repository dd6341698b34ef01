"""The report as ONE self-contained HTML file: plots are PNG data URIs, the style sheet is
inline (with a print style), nothing is loaded from elsewhere. Plain f-strings with
:func:`html.escape` on every value: the page is a handful of tables, no template engine needed."""

from __future__ import annotations

import base64
import math
from collections.abc import Callable, Sequence
from html import escape

import numpy as np

from station.ui.report import signoff as so
from station.ui.report import tables as t
from station.ui.report.before_basis import before_basis
from station.ui.report.contents import ReportData
from station.ui.report.render import plots

_CSS = """
:root { --ok: #1b7f3b; --bad: #b3261e; --warn: #8a5a00; --line: #c8c8c8; --muted: #555; }
* { box-sizing: border-box; }
body { font: 14px/1.45 system-ui, -apple-system, "Segoe UI", Roboto, "DejaVu Sans", sans-serif;
       color: #111; margin: 0 auto; max-width: 1120px; padding: 16px 24px 40px; }
h1 { font-size: 22px; margin: 4px 0 2px; }
h2 { font-size: 18px; border-bottom: 2px solid #333; padding-bottom: 2px; margin: 28px 0 8px; }
h3 { font-size: 15px; margin: 16px 0 4px; }
p.meta, p.note, .muted { color: var(--muted); }
p.note { font-size: 13px; margin: 4px 0 8px; }
table { border-collapse: collapse; margin: 6px 0 10px; font-size: 13px; }
th, td { border: 1px solid var(--line); padding: 2px 8px; vertical-align: top; }
th { background: #f0f0f0; text-align: left; }
table:not(.kv) td:first-child { white-space: nowrap; }
td.num, th.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
table.kv th { width: 16em; font-weight: 600; }
.outcome { display: inline-block; padding: 4px 12px; border-radius: 4px; color: #fff; font-weight: 700;
           font-size: 16px; margin: 4px 0 8px; }
.outcome.ok { background: var(--ok); } .outcome.bad { background: var(--bad); } .outcome.warn { background: var(--warn); }
.scope { border-left: 4px solid var(--warn); background: #fff6e0; padding: 6px 10px; margin: 6px 0 10px; }
figure { margin: 8px 0 14px; }
figure img { max-width: 100%; height: auto; border: 1px solid #eee; }
figcaption { font-size: 12px; color: var(--muted); }
pre.config { background: #f7f7f7; border: 1px solid var(--line); padding: 8px; font-size: 11.5px;
             max-height: 420px; overflow: auto; white-space: pre-wrap; word-break: break-all; }
table.corr { font-size: 10.5px; }
table.corr th, table.corr td { padding: 1px 3px; text-align: center; }
table.corr td.strong { font-weight: 700; outline: 2px solid #000; outline-offset: -2px; }
tr.total td { font-weight: 700; border-top: 2px solid #333; }
tr.this-run td { font-weight: 700; background: #f6f9ff; }
td.elbow-pos { color: #1f4e9c; } td.elbow-neg { color: #a1271d; }
nav.toc { font-size: 13px; margin: 6px 0 0; } nav.toc a { margin-right: 10px; }
.sim-banner { background: var(--bad); color: #fff; font-weight: 700; text-align: center; padding: 6px 10px;
              margin: 0 0 8px; border-radius: 3px; }
@media screen { .sim-banner { position: sticky; top: 0; z-index: 10; } }
.watermark { display: none; }
.verdict { display: inline-block; padding: 2px 10px; border-radius: 3px; font-weight: 700; margin-left: 8px; }
.verdict.pass, td.pass { color: var(--ok); } .verdict.fail, td.fail { color: var(--bad); }
.verdict.pass, .verdict.fail { border: 2px solid currentColor; } .verdict.none { color: var(--muted); border: 1px solid var(--line); }
td.pass, td.fail { font-weight: 700; }
table.signature { width: 100%; margin-top: 10px; }
table.signature td { height: 16mm; } table.signature td:first-child { width: 18%; font-weight: 600; }
table.signature th:nth-child(2), table.signature th:nth-child(4) { width: 30%; }
section#signoff { break-inside: avoid; page-break-inside: avoid; }
/* the cell's picture (issue 40) opens a page, its heading never orphaned at the foot of the one before,
   and leaves room for the sign-off under it */
@media print { section#cell { break-before: page; page-break-before: always; } #cell-picture img { max-height: 170mm; } }
@media print {
  @page { size: A4; margin: 12mm; }
  body { max-width: none; padding: 0; font-size: 10pt; }
  table { font-size: 8.5pt; } table.corr { font-size: 6.5pt; } pre.config { font-size: 7.5pt; }
  nav.toc { display: none; }
  /* a heading stays with what it heads: its note and its table's first rows (issue 29) */
  h2, h3, h2 + p.note, h3 + p.note, h2 + p, h3 + p { break-after: avoid; page-break-after: avoid; }
  table + p.note, .scope + p.note { break-before: avoid; page-break-before: avoid; }
  thead { display: table-header-group; } /* a table's header repeats on every page it spans */
  pre.config { background: none; }
  section { break-inside: auto; }
  tr, figure, .scope { break-inside: avoid; page-break-inside: avoid; }
  pre.config { max-height: none; overflow: visible; }
  figure img { max-height: 240mm; }
  a { color: inherit; text-decoration: none; }
  .outcome, .sim-banner, td, th { -webkit-print-color-adjust: exact; print-color-adjust: exact; }
}
"""

#: a simulated run's watermark on every printed page (a fixed element repeats on each), drawn over
#: the content, faint, so that no block with a background hides it
_SIM_CSS = """
@media print {
  .watermark { display: block; position: fixed; top: 40%; left: -20%; right: -20%; text-align: center;
               font: 700 64pt system-ui, "DejaVu Sans", sans-serif; color: rgba(179, 38, 30, 0.10);
               transform: rotate(-30deg); z-index: 1000; pointer-events: none; }
}
"""


def _css_text(text: str) -> str:
    """``text`` as a CSS string literal."""
    return '"' + "".join(c if c.isprintable() and c not in '"\\<>' else f"\\{ord(c):x} " for c in text) + '"'


def page_css(d: ReportData) -> str:
    """The running header and footer of every printed page, as CSS page-margin boxes (Chromium
    131 and later, Chrome and Edge among them, print them; docs/report.md says how to print):
    the document ID and the run at the top, the SIMULATED mark where it applies, "page X of Y"
    at the foot."""
    font = 'font: 8pt system-ui, "DejaVu Sans", sans-serif; color: #333;'
    top_right = (f'@top-right {{ content: {_css_text("SIMULATED: " + so.REHEARSAL)}; {font} color: #b3261e; '
                 f'font-weight: 700; }}') if d.simulated else ""
    created = f", {t.timestamp_text(d.created)}" if d.created else ""
    return f"""
@media print {{
  @page {{ size: A4; margin: 16mm 12mm 14mm;
    @top-left {{ content: {_css_text("Calibration report " + d.document_id)}; {font} }}
    {top_right}
    @bottom-left {{ content: {_css_text(f"{d.robot_name}, run {d.run_id}{created}")}; {font} }}
    @bottom-right {{ content: "page " counter(page) " of " counter(pages); {font} }}
  }}
}}
"""


SECTIONS = (
    ("summary", "Summary"),
    ("conditions", "Test conditions"),
    ("traceability", "Traceability"),
    ("record", "Run record: configuration, station, devices"),
    ("parameters", "Identified parameters"),
    ("residuals", "Residuals of the identification"),
    ("verification", "Verification before and after correction"),
    ("accuracy", "Predicted accuracy over the workspace"),
    ("table", "Correction table and its bound"),
    ("reversal", "Reversal error"),
    ("tools", "Tools after the head"),
    ("simulation", "Simulation"),
    ("trend", "Trend: this robot's calibrations and rechecks"),
    ("cell", "The cell and the plan's poses"),
    ("signoff", "Sign-off"),
)


def _e(v: object) -> str:
    return escape(str(v), quote=True)


def _img(png: bytes | None, alt: str, caption: str = "") -> str:
    if png is None:
        return ""
    data = base64.b64encode(png).decode("ascii")
    cap = f"<figcaption>{_e(caption)}</figcaption>" if caption else ""
    return f'<figure><img alt="{_e(alt)}" src="data:image/png;base64,{data}">{cap}</figure>'


def _kv(rows: Sequence[tuple[str, str]], cls: str = "kv", table_id: str = "") -> str:
    ident = f' id="{_e(table_id)}"' if table_id else ""
    body = "".join(f"<tr><th>{_e(k)}</th><td>{_e(v)}</td></tr>" for k, v in rows)
    return f'<table class="{cls}"{ident}><tbody>{body}</tbody></table>'


def _table(head: Sequence[str], rows: Sequence[Sequence[str]], *, table_id: str = "", num_from: int = 1,
           row_classes: Sequence[str] | None = None) -> str:
    ident = f' id="{_e(table_id)}"' if table_id else ""
    th = "".join(f'<th class="{"num" if i >= num_from else ""}">{_e(h)}</th>' for i, h in enumerate(head))
    trs = []
    for r, row in enumerate(rows):
        cls = f' class="{row_classes[r]}"' if row_classes and row_classes[r] else ""
        tds = "".join(f'<td class="{_cell_class(i, c, num_from)}">{_e(c)}</td>' for i, c in enumerate(row))
        trs.append(f"<tr{cls}>{tds}</tr>")
    return f"<table{ident}><thead><tr>{th}</tr></thead><tbody>{''.join(trs)}</tbody></table>"


def _cell_class(i: int, text: str, num_from: int) -> str:
    cls = ["num"] if i >= num_from else []
    if text in ("+1", "-1"):
        cls.append("elbow-pos" if text == "+1" else "elbow-neg")
    if text == so.PASS or text.startswith(so.FAIL):
        cls.append("pass" if text == so.PASS else "fail")
    return " ".join(cls)


def _section(key: str, body: str) -> str:
    title = dict(SECTIONS)[key]
    return f'<section id="{key}"><h2>{_e(title)}</h2>{body}</section>'


# ----------------------------------------------------------------------------- sections
def _summary(d: ReportData) -> str:
    s = d.summary
    if s is None:
        banner = '<div class="outcome warn">outcome not stored</div>'
    else:
        cls = "ok" if s.ok else ("warn" if s.outcome.name == "NOT_UPLOADED" else "bad")
        banner = f'<div class="outcome {cls}" id="outcome">{_e(s.outcome.name)} — exit code {s.exit_code}</div>'
    notes = t.summary_notes(d)
    note_html = "".join(f"<li>{_e(n)}</li>" for n in notes)
    progress = (f'<div class="scope" id="progress"><b>How far the run got:</b> {_e(d.progress)}</div>'
                if d.progress else "")
    return (banner + progress + _kv(t.summary_rows(d, outcome=s is None), table_id="summary-table")
            + _acceptance(d)
            + (f"<h3>Notes</h3><ul>{note_html}</ul>" if note_html else ""))


def _acceptance(d: ReportData) -> str:
    rows = so.acceptance_rows(d)
    if not rows:
        return ""
    v = so.verdict(d)
    cls = {so.PASS: "pass", so.FAIL: "fail"}.get(v, "none")
    return (f'<h3>Acceptance<span class="verdict {cls}" id="verdict">{_e(so.verdict_text(d))}</span></h3>'
            '<p class="note">The run succeeds only when every criterion passes: the improvement ratio, and the '
            'ISO 9283 limits that [verification] gives, per held-out pose after correction (a miss: '
            'TARGET_MISSED, exit code 10).</p>'
            + _table(so.ACCEPTANCE_HEAD, rows, table_id="acceptance-table", num_from=9))


def _departures(d: ReportData, ident: str) -> str:
    items = "".join(f"<li>{_e(x)}</li>" for x in so.iso_departures(d))
    return f'<p class="note">{_e(so.ISO_DEPARTURE_NOTE)}</p><ul class="note" id="{ident}">{items}</ul>' if items else ""


def _conditions(d: ReportData) -> str:
    out = _kv(so.conditions_rows(d), table_id="conditions-table") + _departures(d, "iso-departures")
    if d.iso_poses:
        out += (f'<h3>Held-out poses</h3><p class="note">{_e(so.POSES_NOTE)}</p>'
                + _table(so.POSES_HEAD, so.pose_rows(d), table_id="poses-table", num_from=2))
    return out


def _traceability(d: ReportData) -> str:
    return (_kv(so.traceability_rows(d), table_id="traceability-table")
            + '<p class="note">Certificates as the head and body files name them when the report is built; the '
              'libraries are those the report recomputed the identification with.</p>')


def _signoff(d: ReportData) -> str:
    verdict = f'<p id="signoff-verdict">Document {_e(d.document_id)}. Verdict: {_e(so.verdict_text(d))}.</p>'
    if d.simulated:  # nothing to sign: the block is replaced, not qualified
        return (verdict + f'<div class="scope" id="rehearsal"><b>{_e(so.REHEARSAL[0].upper() + so.REHEARSAL[1:])}.'
                          f'</b> {_e(so.REHEARSAL_TEXT)}</div>')
    return (verdict + f'<p class="note" id="signature-attests">{_e(so.SIGNATURE_ATTESTS)}</p>'
            + _table(so.SIGNATURE_HEAD, so.signature_rows(), table_id="signature-table", num_from=9)
            .replace("<table", '<table class="signature"', 1))


def _record(d: ReportData) -> str:
    rounded = (f" Numbers with more digits than they mean are shown to {so.SNAPSHOT_DECIMALS} decimals; the run "
               f"database keeps the text as it was." if so.snapshot_changed(d.config_toml) else "")
    cfg = (f'<h3>Configuration snapshot</h3><p class="note">The cell configuration the run used, as stored in '
           f'the run database (TOML).{_e(rounded)}</p><pre class="config" id="config">{_e(so.tidy_config(d.config_toml))}</pre>'
           if d.config_toml else '<p class="note">No configuration snapshot stored.</p>')
    return _kv(t.record_rows(d), table_id="record-table") + cfg


def _not_reached(d: ReportData, what: str) -> str:
    why = next((n for n in d.notes if n.startswith("nothing identified")), "nothing identified")
    return f'<p class="note not-reached">{_e(what)}: {_e(why)}.</p>'


def _parameters(d: ReportData) -> str:
    if not d.param_names:
        return _not_reached(d, "No parameters")
    out = [f'<p class="note">{_e(t.parameter_line(d))} Nominal and identified values in mm and degrees; '
           f'Δ and σ in µm and arc seconds (″).</p>']
    for key, title, what in t.groups_present(d):
        out.append(f"<h3>{_e(title)}</h3><p class=\"note\">{_e(what)}</p>")
        for kind, head in t.PARAM_KINDS:
            rows = t.param_rows(d, key, kind)
            if rows:
                out.append(_table(head, rows, table_id=f"params-{key}-{kind}", num_from=1))
    out.append(_img(plots.plot_parameters(d, ("robot",), "the robot's own parameters"),
                    "the robot's own parameters", "The robot's own parameters, apart from the set-up and "
                    "the head so that their σ is visible; the right column shows σ alone."))
    out.append(_img(plots.plot_parameters(d, ("setup", "head"), "set-up (green) and head / tool (purple)"),
                    "set-up and head parameters", "Set-up R.* and head K.* parameters."))
    out.append(_correlations(d))
    return "".join(out)


def _corr_colour(r: float) -> str:
    if not math.isfinite(r):
        return "#ffffff"
    a = min(abs(r), 1.0)
    light = int(100 - 55 * a)
    hue = 0 if r > 0 else 215
    return f"hsl({hue}, 70%, {light}%)"


def _correlations(d: ReportData) -> str:
    c = d.param_correlation
    out = ["<h3>Correlations</h3>"]
    if c is None:
        return out[0] + '<p class="note">No covariance stored: correlations not available.</p>'
    pairs = t.correlation_pairs(d)
    out.append(f'<p class="note">Correlation coefficients r of the estimates (from the identification\'s '
               f'covariance). |r| &gt; {t.STRONG_CORRELATION} is marked: such parameters are hard to tell apart '
               f'from these poses, and their σ hides how they trade off.</p>')
    if pairs:
        out.append(_table(("parameter", "parameter", "r"), [(a, b, f"{r:+.3f}") for a, b, r in pairs],
                          table_id="strong-correlations", num_from=2))
    else:
        out.append(f'<p id="strong-correlations">No pair with |r| &gt; {t.STRONG_CORRELATION}.</p>')
    names = d.param_names
    th = "".join(f'<th title="{_e(n)}">{_e(t.short_name(n))}</th>' for n in names)
    rows = []
    for i, n in enumerate(names):
        tds = []
        for j in range(len(names)):
            r = float(c[i, j])
            strong = i != j and math.isfinite(r) and abs(r) > t.STRONG_CORRELATION
            text = "1" if i == j else ("—" if not math.isfinite(r) else f"{r:.2f}".replace("0.", "."))
            tds.append(f'<td class="{"strong" if strong else ""}" style="background:{_corr_colour(r if i != j else 0.0)}"'
                       f' title="{_e(n)} / {_e(names[j])}: {r:+.3f}">{_e(text)}</td>')
        rows.append(f"<tr><th>{_e(n)}</th>{''.join(tds)}</tr>")
    out.append(f'<table class="corr" id="correlation-matrix"><thead><tr><th></th>{th}</tr></thead>'
               f"<tbody>{''.join(rows)}</tbody></table>")
    out.append('<p class="note">Red: positive, blue: negative; boxed: |r| &gt; 0.9.</p>')
    return "".join(out)


def _residuals(d: ReportData) -> str:
    if not d.residuals.shape[0]:
        return _not_reached(d, "No residuals")
    groups = t.residual_groups(d)
    ori = any(g.rms_ori_arcsec is not None for g in groups)
    head = ["pose (point, elbow)", "measurements", "RMS |position| µm", "max |position| µm"]
    if ori:
        head.append("RMS |orientation| ″")
    head.append("outliers")
    rows = []
    for g in groups:
        row = [g.label, str(g.n), t.fmt(g.rms_pos_um), t.fmt(g.max_pos_um)]
        if ori:
            row.append(t.fmt(g.rms_ori_arcsec))
        row.append(str(g.outliers) if g.outliers else "")
        rows.append(row)
    return (f'<p>{_e(t.residual_line(d))}</p>'
            + _img(plots.plot_residuals(d), "residuals per identification pose",
                   "Every identification measurement, in the order measured; bars: the residual's length.")
            + "<h3>Per pose</h3>" + _table(head, rows, table_id="residuals-table"))


def _verification(d: ReportData) -> str:
    if not np.isfinite(d.errors_before_um).any():
        return ('<p class="note" id="verification-none">No verification measurements: the run ended before it '
                'measured the held-out poses.</p>')
    after = bool(d.errors_after_um.size)
    oracle = d.oracle_after_um is not None and bool(d.oracle_after_um.size)
    head = ["point", "elbow", "cycles", "before RMS µm"] + (["after RMS µm", "after max µm"] if after else [])
    if oracle:
        head.append("oracle RMS µm")
    rows, classes = [], []
    both = "both" if len(t.per_elbow_rows(d)) > 1 else ""
    for r in [*t.verification_rows(d), t.verification_total(d)]:
        row = [r.point, t.elbow_text(r.elbow) if r.point != "all poses" else both, str(r.n), t.fmt(r.before_rms)]
        if after:
            row += [t.fmt(r.after_rms), t.fmt(r.after_max)]
        if oracle:
            row.append(t.fmt(r.oracle_rms))
        rows.append(row)
        classes.append("total" if r.point == "all poses" else "")
    table = _table(head, rows, table_id="verification-table", num_from=2, row_classes=classes)
    note = ("Held-out poses (not used by the identification), targeted as Cartesian poses in the robot base "
            "frame and measured on the body. Each row: the RMS over the pose's cycles.")
    if not after:
        note += " Nothing was uploaded, so there are no 'after' measurements."
    if oracle:
        note += (" Oracle: the same poses after a correction built from the simulator's true parameters — "
                 "the best any identification could do here.")
    elbow_head = ("elbow", "poses", "before RMS µm", "after RMS µm", "oracle RMS µm")
    iso = (f'<h3>ISO 9283 pose accuracy AP and repeatability RP per pose</h3><p class="note">{_e(so.ISO_NOTE)}</p>'
           + _table(so.ISO_HEAD, so.iso_rows(d), table_id="iso-table", num_from=2,
                    row_classes=["total" if r[0] == "largest" else "" for r in so.iso_rows(d)])
           + ('<p class="note">How this test departs from ISO 9283\'s (cycles, poses, load, speed): see '
              '<a href="#conditions">Test conditions</a>.</p>') if d.iso_poses else "")
    basis = before_basis(d.summary.before if d.summary else None)
    return (f'<p class="note">{_e(note)}</p>'
            + (f'<p class="note" id="before-basis">{_e(basis)}</p>' if basis else "") + "<h3>Per elbow</h3>"
            + _table(elbow_head, t.per_elbow_rows(d), table_id="verification-elbows")
            + "<h3>Per pose</h3>" + table + iso
            + _img(plots.plot_verification(d), "verification errors per pose",
                   "Bars: RMS over each pose's cycles (a log scale where they span more than 20×); dashed: "
                   "RMS over all."))


def _accuracy(d: ReportData) -> str:
    where = d.accuracy_where or "evaluation points over the workspace"
    if not d.accuracy_sigma_mm.size:
        return f'<div class="scope">{_e(t.ACCURACY_SCOPE)}.</div><p>No evaluation points.</p>'
    head = ("elbow", "points", "x-y positions", "min σ µm", "mean σ µm", "max σ µm")
    return (f'<div class="scope" id="accuracy-scope"><b>What this includes:</b> {_e(t.ACCURACY_SCOPE)}. '
            f'It is therefore a lower bound of the accuracy a user gets, not a prediction of the measured error '
            f'(compare below).</div>'
            f'<p class="note">Evaluated at: {_e(where)}.</p>'
            + _table(head, t.accuracy_rows(d), table_id="accuracy-table")
            + "<h3>Read against the measured figures</h3>" + _kv(t.accuracy_comparison(d))
            + _img(plots.plot_accuracy(d), "predicted position sigma over the workspace",
                   "Each square is one x-y position; where several points (heights, yaws) share it, the "
                   "largest σ among them is shown and the panel title gives the count."))


def _table_section(d: ReportData) -> str:
    rows = t.table_rows(d)
    if not rows:
        return '<p>No correction table was built (the run stopped before the correction).</p>'
    return (_kv(rows, table_id="table-facts")
            + '<p class="note">The bound covers the interpolation of the table over cells whose corners are all '
              'reachable; it adds to the identification\'s error, it does not contain it.</p>')


def _reversal(d: ReportData) -> str:
    rows = t.reversal_rows(d)
    if not rows:
        return ('<p id="reversal-none">Not measured in this run (set <code>plan.both_directions = true</code> '
                'to approach every identification pose from both sides).</p>')
    return ('<p class="note">Position difference between approaching each pose from below and from above '
            '(backlash and friction); the correction table does not remove it.</p>'
            + _kv(rows, table_id="reversal-table"))


def _tools(d: ReportData) -> str:
    check = t.tool_check_rows(d)
    return (f'<p class="note">{_e(t.TOOL_NOTE)}</p>' + _table(t.TOOL_HEAD, t.tool_rows(d), table_id="tools-table", num_from=3)
            + ((f'<p class="note">{_e(t.TOOL_CHECK_NOTE)}</p>'
                + _table(t.TOOL_CHECK_HEAD, check, table_id="tools-check-table")) if check else ""))


def _simulation(d: ReportData) -> str:
    return (f'<p class="note">{_e(t.SIMULATION_NOTE)}</p>'
            + _table(t.SIMULATION_HEAD, t.simulation_rows(d), table_id="simulation-table", num_from=2))


def _trend(d: ReportData) -> str:
    this = str(d.run_id)
    rows = t.trend_rows(d)
    classes = ["this-run" if r[0] == this else "" for r in rows]
    return (f'<p class="note">{_e(t.trend_line(d))}</p>'
            + _table(t.TREND_HEAD, rows, table_id="trend-table", num_from=4, row_classes=classes)
            + _img(plots.plot_trend(d), "accuracy per run over time",
                   "One column per run, oldest first; a recheck's red dash is its tolerance."))


def _cell(d: ReportData) -> str:
    data = base64.b64encode((d.cell_svg or "").encode("utf-8")).decode("ascii")
    return ('<p class="note">The cell seen from above and from the side in the robot\'s base frame (mm), as the '
            "collision check sees it: the body's cubes, the obstacles, the arm at the first touch of each pose "
            "family and at the plan's least clearance, every touch of the plan and the travel between the "
            "poses.</p>"
            f'<figure id="cell-picture"><img alt="the cell and the plan\'s poses" '
            f'src="data:image/svg+xml;base64,{data}"></figure>')


def _guarded(key: str, build: Callable[[ReportData], str], d: ReportData) -> str:
    """A section's HTML; a section that cannot be drawn from what the run stored says so and why
    instead of failing the whole report (every run that ends gets one)."""
    try:
        return build(d)
    except Exception as exc:  # noqa: BLE001 - the rest of the report stands; the gap is stated in its place
        return (f'<p class="note section-failed">This section could not be drawn from what the run stored '
                f'({_e(type(exc).__name__)}: {_e(exc)}).</p>')


def render_html(d: ReportData) -> str:
    title = f"Calibration report — {d.robot_name}, run {d.run_id}"
    builders = [("summary", _summary), ("conditions", _conditions), ("traceability", _traceability),
                ("record", _record), ("parameters", _parameters), ("residuals", _residuals),
                ("verification", _verification), ("accuracy", _accuracy), ("table", _table_section),
                ("reversal", _reversal)]
    if t.has_tools(d):  # [[tool]]: each tool's own correction
        builders.append(("tools", _tools))
    if t.has_simulation(d):  # a simulated cell's judge's figures: simulated runs only
        builders.append(("simulation", _simulation))
    if t.has_trend(d):  # one run has no history: no section
        builders.append(("trend", _trend))
    if d.cell_svg is not None:  # the cell's picture (issue 40)
        builders.append(("cell", _cell))
    builders.append(("signoff", _signoff))
    parts = [(key, _guarded(key, build, d)) for key, build in builders]
    shown = {k for k, _ in parts}
    toc = "".join(f'<a href="#{k}">{_e(v)}</a>' for k, v in SECTIONS if k in shown)
    created = f"created {_e(t.timestamp_text(d.created))} · " if d.created else ""
    meta = (f'<p class="meta">{created}station {_e(d.station_version or "version not recorded")} · units: '
            f"µm and arc seconds (″); nominal and identified values in mm and degrees</p>")
    body = "".join(_section(k, b) for k, b in parts)
    if d.simulated:
        title = f"SIMULATED — {title}"
    sim = (f'<div class="sim-banner" id="simulated-banner">{_e(so.SIMULATED_BANNER)}</div>'
           f'<div class="watermark" aria-hidden="true">SIMULATED</div>' if d.simulated else "")
    css = _CSS + page_css(d) + (_SIM_CSS if d.simulated else "")
    return ("<!DOCTYPE html>\n"
            f'<html lang="en"><head><meta charset="utf-8"><meta name="viewport" content="width=device-width">'
            f"<title>{_e(title)}</title><style>{css}</style></head>\n"
            f"<body>{sim}<header><h1>{_e(title)}</h1>{meta}<nav class=\"toc\">{toc}</nav></header>\n"
            f"{body}\n<footer class=\"muted\"><p>End of report · run {_e(d.run_id)}</p></footer></body></html>\n")


__all__ = ["render_html", "SECTIONS"]
