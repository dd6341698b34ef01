"""The report's tables as Markdown (``report.md``): the same rows as the HTML, no plots, so that
two runs' reports diff line by line. The HTML is the QA record."""

from __future__ import annotations

from collections.abc import Sequence

from station.ui.report import signoff as so
from station.ui.report import tables as t
from station.ui.report.before_basis import before_basis
from station.ui.report.contents import HTML_NAME, ReportData


def _cell(v: object) -> str:
    return str(v).replace("|", r"\|").replace("\n", " ")


def _table(head: Sequence[str], rows: Sequence[Sequence[object]], num_from: int = 1) -> list[str]:
    out = ["| " + " | ".join(_cell(h) for h in head) + " |",
           "|" + "|".join("---:" if i >= num_from else "---" for i in range(len(head))) + "|"]
    out += ["| " + " | ".join(_cell(c) for c in r) + " |" for r in rows]
    return out + [""]


def render_markdown(d: ReportData) -> str:
    L: list[str] = []
    for part in (_front, _parameters, _verification, _correction_and_after):
        L += part(d)
    return "\n".join(L)


def _front(d: ReportData) -> list[str]:
    """Title, summary and acceptance, test conditions, traceability and the run record."""
    L: list[str] = [f"# {'SIMULATED — ' if d.simulated else ''}Calibration report — {d.robot_name}, run {d.run_id}", ""]
    if d.simulated:
        L += [f"> **{so.SIMULATED_BANNER}**", ""]
    if d.created:
        L += [f"Created {t.timestamp_text(d.created)}.", ""]
    L += [f"The QA record with plots is `{HTML_NAME}` beside this file. Units: lengths in µm (nominal and "
          "identified values in mm), angles in arc seconds ″ (nominal and identified values in degrees).", ""]

    L += [f"Document {d.document_id}.", ""]
    L += ["## Summary", ""]
    if d.progress:
        L += [f"**How far the run got:** {d.progress}", ""]
    L += _table(("quantity", "value"), t.summary_rows(d), num_from=9)
    notes = t.summary_notes(d)
    if notes:
        L += [f"- {n}" for n in notes] + [""]
    acceptance = so.acceptance_rows(d)
    if acceptance:
        L += [f"### Acceptance: {so.verdict_text(d)}", ""]
        L += _table(so.ACCEPTANCE_HEAD, acceptance, num_from=9)

    L += ["## Test conditions", ""]
    L += _table(("item", "value"), so.conditions_rows(d), num_from=9)
    if so.iso_departures(d):
        L += [so.ISO_DEPARTURE_NOTE, ""] + [f"- {x}" for x in so.iso_departures(d)] + [""]
    if d.iso_poses:
        L += [so.POSES_NOTE, ""]
        L += _table(so.POSES_HEAD, so.pose_rows(d), num_from=2)

    L += ["## Traceability", ""]
    L += _table(("item", "value"), so.traceability_rows(d), num_from=9)

    L += ["## Run record", ""]
    L += _table(("item", "value"), t.record_rows(d), num_from=9)
    if d.config_toml:
        rounded = (f" (numbers shown to {so.SNAPSHOT_DECIMALS} decimals; the run database keeps the text as it was)"
                   if so.snapshot_changed(d.config_toml) else "")
        L += [f"Configuration snapshot{rounded}:", "", "```toml", so.tidy_config(d.config_toml).rstrip("\n"), "```", ""]
    return L


def _parameters(d: ReportData) -> list[str]:
    """The identified parameters with their σ, strong correlations and the residuals."""
    L: list[str] = []
    L += ["## Identified parameters", "", t.parameter_line(d) if d.param_names else "No parameters: nothing identified.", ""]
    for key, title, what in t.groups_present(d):
        L += [f"### {title}", "", f"{what}.", ""]
        for kind, kind_head in t.PARAM_KINDS:
            rows_p = t.param_rows(d, key, kind)
            if rows_p:
                L += _table(kind_head, rows_p)
    if d.param_correlation is not None:
        pairs = t.correlation_pairs(d)
        L += ["### Strong correlations", ""]
        if pairs:
            L += _table(("parameter", "parameter", "r"), [(a, b, f"{r:+.3f}") for a, b, r in pairs], num_from=2)
        else:
            L += [f"No pair with |r| > {t.STRONG_CORRELATION}.", ""]

    L += ["## Residuals of the identification", "", t.residual_line(d) if d.residuals.shape[0] else "None.", ""]
    groups = t.residual_groups(d) if d.residuals.shape[0] else []
    ori = any(g.rms_ori_arcsec is not None for g in groups)
    head = ["pose", "n", "RMS µm", "max µm"] + (["RMS ″"] if ori else []) + ["outliers"]
    L += _table(head, [[g.label, g.n, t.fmt(g.rms_pos_um), t.fmt(g.max_pos_um)]
                       + ([t.fmt(g.rms_ori_arcsec)] if ori else []) + [g.outliers or ""] for g in groups])
    return L


def _verification(d: ReportData) -> list[str]:
    """Before and after correction per elbow and per point, and ISO 9283 per pose."""
    L: list[str] = []
    L += ["## Verification before and after correction", ""]
    if (basis := before_basis(d.summary.before if d.summary else None)) is not None:
        L += [basis, ""]
    L += _table(("elbow", "poses", "before RMS µm", "after RMS µm", "oracle RMS µm"), t.per_elbow_rows(d))
    oracle = d.oracle_after_um is not None and bool(d.oracle_after_um.size)
    after = bool(d.errors_after_um.size)
    head = (["point", "elbow", "cycles", "before µm"] + (["after µm", "after max µm"] if after else [])
            + (["oracle µm"] if oracle else []))
    rows: list[list[object]] = []
    for r in t.verification_rows(d):
        rows.append([r.point, t.elbow_text(r.elbow), r.n, t.fmt(r.before_rms)]
                    + ([t.fmt(r.after_rms), t.fmt(r.after_max)] if after else [])
                    + ([t.fmt(r.oracle_rms)] if oracle else []))
    tot = t.verification_total(d)
    rows.append(["**all poses**", "", tot.n, f"**{t.fmt(tot.before_rms)}**"]
                + ([f"**{t.fmt(tot.after_rms)}**", t.fmt(tot.after_max)] if after else [])
                + ([f"**{t.fmt(tot.oracle_rms)}**"] if oracle else []))
    if not after:
        L += ["Nothing was uploaded: no 'after' measurements.", ""]
    L += _table(head, rows, num_from=2)
    if d.iso_poses:
        L += ["### ISO 9283 pose accuracy AP and repeatability RP per pose", "", so.ISO_NOTE, ""]
        L += _table(so.ISO_HEAD, so.iso_rows(d), num_from=2)
    return L


def _correction_and_after(d: ReportData) -> list[str]:
    """Predicted accuracy, the correction table, the reversal error, tools, the simulation's
    figures, the trend and the sign-off."""
    L: list[str] = []
    L += ["## Predicted accuracy over the workspace", "", f"Includes the {t.ACCURACY_SCOPE}.", ""]
    if d.accuracy_where:
        L += [f"Evaluated at: {d.accuracy_where}.", ""]
    if d.accuracy_sigma_mm.size:
        L += _table(("elbow", "points", "x-y positions", "min σ µm", "mean σ µm", "max σ µm"), t.accuracy_rows(d))
        L += _table(("measured, for comparison", "value"), t.accuracy_comparison(d), num_from=9)
    else:
        L += ["No evaluation points.", ""]

    L += ["## Correction table and its bound", ""]
    rows_t = t.table_rows(d)
    L += _table(("item", "value"), rows_t, num_from=9) if rows_t else ["No correction table was built.", ""]

    L += ["## Reversal error", ""]
    rows_r = t.reversal_rows(d)
    L += _table(("item", "value"), rows_r, num_from=9) if rows_r else ["Not measured in this run.", ""]

    if t.has_tools(d):  # [[tool]]: each tool's own correction
        L += ["## Tools after the head", "", t.TOOL_NOTE, ""]
        L += _table(t.TOOL_HEAD, t.tool_rows(d), num_from=3)
        if t.tool_check_rows(d):
            L += [t.TOOL_CHECK_NOTE, ""]
            L += _table(t.TOOL_CHECK_HEAD, t.tool_check_rows(d))

    if t.has_simulation(d):  # a simulated cell's judge's figures: simulated runs only
        L += ["## Simulation", "", t.SIMULATION_NOTE, ""]
        L += _table(t.SIMULATION_HEAD, t.simulation_rows(d), num_from=2)

    if t.has_trend(d):  # one run has no history: no section
        L += ["## Trend: this robot's calibrations and rechecks", "", t.trend_line(d), ""]
        this = str(d.run_id)
        L += _table(t.TREND_HEAD, [(f"**{r[0]}**" if r[0] == this else r[0], *r[1:]) for r in t.trend_rows(d)],
                    num_from=4)

    L += ["## Sign-off", "", f"Document {d.document_id}. Verdict: {so.verdict_text(d)}.", ""]
    if d.simulated:  # nothing to sign: the block is replaced
        L += [f"**{so.REHEARSAL[0].upper()}{so.REHEARSAL[1:]}.** {so.REHEARSAL_TEXT}", ""]
    else:
        L += [so.SIGNATURE_ATTESTS, ""]
        L += _table(so.SIGNATURE_HEAD, so.signature_rows(), num_from=9)
    return L
