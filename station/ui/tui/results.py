"""The results view of the operator UI: what a run identified and what it gained.

Reads a :class:`~station.ui.report.writer.ReportData` (built from the run database in a worker, by the
caller) and shows, in tabs: the parameters with their σ in µm and arc seconds and the strong
correlations (|r| > 0.9) marked, the residual per identification pose, the verification before
/ after / oracle per pose, and the predicted accuracy over the workspace.  Plots are
textual-plotext (terminal plots, no image files).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from rich.text import Text
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import VerticalScroll
from textual.screen import Screen
from textual.widgets import DataTable, Footer, Header, Static, TabbedContent, TabPane
from textual_plotext import PlotextPlot

from station.core.units import ARCSEC, DEG, UM
from station.ui.report.writer import ReportData
from station.ui.tui.widgets import esc, fmt_num

__all__ = ["ResultsScreen", "STRONG_CORRELATION", "parameter_rows", "strong_pairs", "accuracy_text"]

STRONG_CORRELATION = 0.9


def strong_pairs(data: ReportData, limit: float = STRONG_CORRELATION) -> dict[int, list[tuple[int, float]]]:
    """Per parameter index, the other parameters it correlates with at |r| > ``limit``
    (empty when the data carries no correlation matrix)."""
    corr = getattr(data, "param_correlation", None)
    out: dict[int, list[tuple[int, float]]] = {}
    if corr is None:
        return out
    r = np.asarray(corr, dtype=float)
    p = len(data.param_names)
    if r.shape != (p, p):
        return out
    for i in range(p):
        for j in range(p):
            if i != j and math.isfinite(r[i, j]) and abs(r[i, j]) > limit:
                out.setdefault(i, []).append((j, float(r[i, j])))
    return out


def parameter_rows(data: ReportData) -> list[tuple[str, str, str, str, str, str]]:
    """(name, nominal, identified, Δ, σ, strongly correlated with) per parameter; lengths in mm
    with Δ and σ in µm, angles in degrees with Δ and σ in arc seconds."""
    pairs = strong_pairs(data)
    rows = []
    for i, name in enumerate(data.param_names):
        angle = bool(data.param_is_angle[i])
        nom, ide, sig = float(data.param_nominal[i]), float(data.param_identified[i]), float(data.param_sigma[i])
        if angle:
            value = (f"{nom / DEG:.4f}°", f"{ide / DEG:.4f}°")
            delta, sigma = (ide - nom) / ARCSEC, sig / ARCSEC
            unit = "″"
        else:
            value = (f"{nom:.3f} mm", f"{ide:.3f} mm")
            delta, sigma = (ide - nom) / UM, sig / UM
            unit = "µm"
        sigma_text = f"{sigma:.2f} {unit}" if math.isfinite(sigma) else "held"
        partners = ", ".join(f"{data.param_names[j]} {r:+.2f}" for j, r in pairs.get(i, []))
        rows.append((name, value[0], value[1], f"{delta:+.1f} {unit}", sigma_text, partners))
    return rows


def _position_residuals_um(residuals: np.ndarray) -> np.ndarray:
    r = np.asarray(residuals, dtype=float)
    if r.ndim == 1:
        r = r[:, None]
    return np.linalg.norm(r[:, :3], axis=1) / UM


def _rms(a: np.ndarray) -> float:
    a = np.asarray(a, dtype=float)
    return float(np.sqrt(np.mean(a**2))) if a.size else math.nan


def accuracy_text(data: ReportData) -> str:
    sigma = np.asarray(data.accuracy_sigma_mm, dtype=float) / UM
    if not sigma.size:
        return "no workspace points"
    return (f"predicted position σ of the TCP at {sigma.size} points over the workspace:\n"
            f"  min {sigma.min():.2f} µm · median {float(np.median(sigma)):.2f} µm · max {sigma.max():.2f} µm\n"
            f"[dim]It holds the parameter uncertainty only: no probe noise, repeatability or backlash.\n"
            f"Measured after correction: {fmt_num(_rms(data.errors_after_um), 'µm')} RMS.[/]")


def verification_text(data: ReportData) -> str:
    rows = [("before correction", data.errors_before_um), ("after correction", data.errors_after_um)]
    if data.oracle_after_um is not None:
        rows.append(("true correction (oracle)", data.oracle_after_um))
    lines = [f"{label:<25} RMS {fmt_num(_rms(np.asarray(v)), 'µm'):>10}   max "
             f"{fmt_num(float(np.max(v)) if len(v) else math.nan, 'µm'):>10}   ({len(v)} poses)"
             for label, v in rows]
    return "\n".join(lines)


class ResultsScreen(Screen[None]):
    """Full-screen results of one run; Esc or v goes back."""

    BINDINGS = [Binding("escape,v,q", "close", "Back"),
                Binding("1", "tab('parameters')", "Params"), Binding("2", "tab('residuals')", "Residuals"),
                Binding("3", "tab('verification')", "Verification"), Binding("4", "tab('accuracy')", "Accuracy")]

    DEFAULT_CSS = """
    ResultsScreen #results-head { height: auto; padding: 0 1; }
    ResultsScreen TabbedContent { height: 1fr; }  /* the head stays in view: the screen never scrolls */
    ResultsScreen DataTable { height: 1fr; }
    ResultsScreen PlotextPlot { height: 1fr; min-height: 8; }
    ResultsScreen .text { height: auto; padding: 0 1; }
    """

    def __init__(self, data: ReportData) -> None:
        super().__init__()
        self.data = data

    def compose(self) -> ComposeResult:
        data = self.data
        yield Header()
        s = data.summary
        head = f"run #{esc(data.run_id)} · {esc(data.robot_name)}"
        if s is not None:
            head += f" · [b]{s.outcome.name}[/] (exit code {s.exit_code})"
        yield Static(head, id="results-head")
        with TabbedContent(initial="parameters"):
            with TabPane("Parameters", id="parameters"):
                yield DataTable(id="params", zebra_stripes=True, cursor_type="row")
                yield Static("", id="corr-note", classes="text")
            with TabPane("Residuals", id="residuals"):
                yield Static("", id="residual-text", classes="text")
                yield PlotextPlot(id="residual-plot")
            with TabPane("Verification", id="verification"):
                yield Static(verification_text(data), id="verify-text", classes="text")
                yield PlotextPlot(id="verify-plot")
            with TabPane("Accuracy", id="accuracy"):
                with VerticalScroll():
                    yield Static(accuracy_text(data), id="accuracy-text", classes="text")
                    yield PlotextPlot(id="accuracy-plot")
        yield Footer()

    def on_mount(self) -> None:
        data = self.data
        table = self.query_one("#params", DataTable)
        table.add_columns("parameter", "nominal", "identified", "Δ", "σ", "|r| > 0.9 with")
        strong = strong_pairs(data)
        for i, row in enumerate(parameter_rows(data)):
            style = "bold yellow" if i in strong else ""
            table.add_row(*(Text(c, style=style) for c in row), key=str(i))
        note = self.query_one("#corr-note", Static)
        if getattr(data, "param_correlation", None) is None:
            note.update("[dim]correlations: not stored for this run[/]")
        else:
            n_pairs = sum(len(v) for v in strong.values()) // 2
            note.update(f"{n_pairs} strongly correlated pair(s) (|r| > {STRONG_CORRELATION}) marked in yellow")

        res = _position_residuals_um(data.residuals)
        self.query_one("#residual-text", Static).update(
            f"position residual per identification pose: RMS {_rms(res):.2f} µm over {res.size} poses")
        self._plot("#residual-plot", "pose", "µm", [("residual", res)])
        lines = [("before", np.asarray(data.errors_before_um)), ("after", np.asarray(data.errors_after_um))]
        if data.oracle_after_um is not None:
            lines.append(("oracle", np.asarray(data.oracle_after_um)))
        self._plot("#verify-plot", "verification pose", "µm (log)", lines, log=True)
        acc = self.query_one("#accuracy-plot", PlotextPlot)
        xy = np.asarray(data.accuracy_xy_mm, dtype=float)
        if xy.size:
            acc.plt.scatter(xy[:, 0].tolist(), (np.asarray(data.accuracy_sigma_mm) / UM).tolist(), marker="dot")
            acc.plt.xlabel("x of the TCP [mm]")
            acc.plt.ylabel("σ [µm]")

    def _plot(self, sel: str, xlabel: str, ylabel: str, series: list[tuple[str, Any]], log: bool = False) -> None:
        plot = self.query_one(sel, PlotextPlot)
        plt = plot.plt
        for label, values in series:
            v = np.asarray(values, dtype=float)
            if v.size:
                plt.plot(list(range(1, v.size + 1)), v.tolist(), label=label, marker="braille")
        if log:
            plt.yscale("log")
        plt.xlabel(xlabel)
        plt.ylabel(ylabel)

    def action_tab(self, tab: str) -> None:
        self.query_one(TabbedContent).active = tab

    def action_close(self) -> None:
        self.dismiss(None)
