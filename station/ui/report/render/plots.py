"""The report's plots as PNG bytes (embedded in the HTML as data URIs).

Explicit ``Figure`` objects on matplotlib's Agg canvas: no pyplot, no global backend switch.
"""

from __future__ import annotations

import io
from typing import Any

import numpy as np

from station.core.units import ARCSEC, UM
from station.ui.report.contents import ReportData
from station.ui.report.tables import (
    ACCURACY_SCOPE,
    elbow_text,
    nanmax,
    param_group,
    rms,
    verification_rows,
    xy_positions,
)

DPI = 150
#: every figure is drawn at the printed width (A4 less the page margins), so that a font size here
#: is the size on paper: no text under MIN_FONT points (issue 29: legends were 5 pt in print)
PRINT_WIDTH_IN = 7.0
MIN_FONT = 8
_ELBOW_COLOURS = {1: "tab:blue", -1: "tab:red"}


def _new_figure(w: float, h: float) -> Any:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    scale = PRINT_WIDTH_IN / w  # the callers' proportions, at the printed width
    fig = Figure(figsize=(PRINT_WIDTH_IN, h * scale * 1.25), dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _png(fig: Any) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()


def plot_residuals(d: ReportData) -> bytes:
    pos = d.position_residuals_um
    ori = d.orientation_residuals_arcsec
    n = pos.shape[0]
    x = np.arange(1, n + 1)
    fig = _new_figure(10, 6.0 if ori is not None else 3.6)
    axes = fig.subplots(2 if ori is not None else 1, 1, sharex=True, squeeze=False)[:, 0]

    def draw(ax: Any, data: np.ndarray, unit: str, what: str, comps: tuple[str, ...]) -> None:
        if data.shape[1] == 1:
            ax.bar(x, data[:, 0], color="tab:blue", label="distance residual")
            level = rms(data)
        else:
            norm = np.linalg.norm(data, axis=1)
            ax.bar(x, norm, color="lightgray", edgecolor="gray", label=f"|{what}|")
            for j, c in enumerate(comps[: data.shape[1]]):
                ax.plot(x, data[:, j], "o", ms=3, label=c)
            level = rms(norm)
        if d.outliers:
            out = np.array(d.outliers) + 1
            ax.plot(out, np.zeros(out.size), "x", color="black", ms=8, label="outlier")
        ax.axhline(0.0, color="black", lw=0.6)
        ax.axhline(level, color="tab:red", ls="--", lw=1, label=f"RMS |{what}| = {level:.1f} {unit}")
        ax.set_ylabel(f"{what} residual [{unit}]")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=MIN_FONT)

    draw(axes[0], pos, "µm", "position", ("x", "y", "z"))
    if ori is not None:
        draw(axes[1], ori, "″", "orientation", ("about x", "about y", "about z"))
    axes[-1].set_xlabel("identification pose (in the order measured)")
    if d.pose_labels is not None and n <= 40:
        axes[-1].set_xticks(x, d.pose_labels, rotation=60, ha="right", fontsize=MIN_FONT)
    fig.suptitle(f"{d.robot_name}, run {d.run_id}: residuals after identification (model − measured)", fontsize=10)
    return _png(fig)


def plot_parameters(d: ReportData, groups: tuple[str, ...], title: str) -> bytes | None:
    """Δ = identified − nominal with ±σ (left) and σ alone (right), lengths [µm] and angles [″]
    in their own rows, for the parameters of ``groups`` only (so that a set-up offset of a few
    mm does not flatten the robot's own µm). None when no parameter is in ``groups``."""
    names = np.array(d.param_names)
    in_group = np.array([param_group(n) in groups for n in names], dtype=bool)
    ang = d.param_is_angle
    kinds = [(in_group & ~ang, 1 / UM, "µm", "lengths"), (in_group & ang, 1 / ARCSEC, "″", "angles")]
    kinds = [k for k in kinds if k[0].any()]
    if not kinds:
        return None
    fig = _new_figure(10, 2.8 * len(kinds) + 0.5)
    axes = fig.subplots(len(kinds), 2, squeeze=False, width_ratios=[3, 2])
    for (mask, scale, unit, what), (ax_d, ax_s) in zip(kinds, axes):
        delta = (d.param_identified[mask] - d.param_nominal[mask]) * scale
        sigma = d.param_sigma[mask] * scale
        idx = np.arange(mask.sum())
        held = ~np.isfinite(sigma)
        colours = ["lightgray" if h else ("tab:green" if param_group(n) == "setup" else
                                          "tab:purple" if param_group(n) == "head" else "tab:blue")
                   for n, h in zip(names[mask], held)]
        ax_d.bar(idx, delta, color=colours)
        ok = ~held
        if ok.any():
            ax_d.errorbar(idx[ok], delta[ok], yerr=sigma[ok], fmt="none", ecolor="black", capsize=3)
        ax_d.axhline(0.0, color="black", lw=0.6)
        ax_d.set_xticks(idx, names[mask], rotation=60, ha="right", fontsize=MIN_FONT)
        ax_d.set_ylabel(f"Δ [{unit}]")
        ax_d.set_title(f"{what}: identified − nominal (±1σ)", fontsize=9)
        ax_d.grid(True, axis="y", alpha=0.3)
        ax_s.bar(idx[ok], sigma[ok], color=[c for c, k in zip(colours, ok) if k])
        for i in np.flatnonzero(held):
            ax_s.text(i, 0.0, "held", ha="center", va="bottom", fontsize=MIN_FONT, color="gray", rotation=90)
        ax_s.set_xticks(idx, names[mask], rotation=60, ha="right", fontsize=MIN_FONT)
        ax_s.set_ylabel(f"σ [{unit}]")
        ax_s.set_title(f"{what}: standard uncertainty σ", fontsize=9)
        ax_s.grid(True, axis="y", alpha=0.3)
    fig.suptitle(f"{d.robot_name}, run {d.run_id}: {title}", fontsize=10)
    return _png(fig)


def plot_accuracy(d: ReportData) -> bytes:
    """Predicted σ over the workspace, one panel per elbow. Points that share an x-y position
    (other heights, yaws) are drawn once, with the largest σ there, and the title says so."""
    xy = d.accuracy_xy_mm
    sig = d.accuracy_sigma_mm * (1 / UM)
    elbows = np.asarray(d.accuracy_elbows) if d.accuracy_elbows is not None else np.zeros(sig.size, dtype=int)
    panels = sorted(set(elbows.tolist()), reverse=True) or [0]
    fig = _new_figure(5.2 * len(panels) + 1.2, 5.4)
    axes = fig.subplots(1, len(panels), squeeze=False)[0]
    finite = sig[np.isfinite(sig)]
    vmin, vmax = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
    sc = None
    for ax, elbow in zip(axes, panels):
        m = elbows == elbow
        pxy, psig = xy[m], sig[m]
        pos = xy_positions(pxy)
        n_pos = int(pos.max()) + 1 if pos.size else 0
        gxy = np.zeros((n_pos, 2))
        gsig = np.full(n_pos, -np.inf)
        count = np.zeros(n_pos, dtype=int)
        for i, g in enumerate(pos):
            gxy[g] = pxy[i]
            count[g] += 1
            if np.isfinite(psig[i]):
                gsig[g] = max(gsig[g], psig[i])
        gsig[~np.isfinite(gsig)] = np.nan
        if n_pos:
            sc = ax.scatter(gxy[:, 0], gxy[:, 1], c=gsig, cmap="viridis", vmin=vmin, vmax=vmax, s=46,
                            marker="s", edgecolors="k", linewidths=0.2)
            j = int(np.nanargmax(gsig)) if np.isfinite(gsig).any() else 0
            ax.annotate(f"max {gsig[j]:.1f} µm", gxy[j], xytext=(6, 6), textcoords="offset points", fontsize=8)
        ax.plot([0], [0], "+", color="tab:red", ms=12, mew=2, label="robot base (joint 1 axis)")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel("x [mm] (robot base frame)")
        ax.set_ylabel("y [mm]")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="lower left", fontsize=MIN_FONT)
        # one line each: at the printed width two panels' titles side by side would overlap
        per = f"\nup to {count.max()} per position (largest σ shown)" if n_pos and count.max() > 1 else ""
        head = f"elbow {elbow_text(int(elbow))}: " if d.accuracy_elbows is not None else ""
        ax.set_title(f"{head}{int(m.sum())} points at\n{n_pos} x-y positions{per}", fontsize=MIN_FONT)
    if sc is not None:
        cb = fig.colorbar(sc, ax=list(axes))
        cb.set_label("predicted position σ [µm]")
    fig.suptitle(f"{d.robot_name}, run {d.run_id}: predicted position σ — {ACCURACY_SCOPE.split(':')[0]}",
                 fontsize=10)
    return _png(fig)


def _value_axis(ax: Any, values: np.ndarray, what: str) -> None:
    """A linear axis from 0 where the values span less than :data:`LOG_RATIO`, else a log axis
    with minor ticks labelled at 2 and 5 of each decade, so that a value can be read off."""
    v = values[np.isfinite(values) & (values > 0)]
    if v.size and float(v.max()) / float(v.min()) < LOG_RATIO:
        ax.set_ylim(bottom=0.0)
        ax.set_ylabel(f"{what} [µm]")
        return
    from matplotlib.ticker import FuncFormatter, LogLocator

    ax.set_yscale("log")
    ax.yaxis.set_minor_locator(LogLocator(base=10.0, subs=(2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0)))
    ax.yaxis.set_minor_formatter(FuncFormatter(lambda y, _: f"{y:g}" if f"{y:.0e}"[0] in "25" else ""))
    ax.tick_params(axis="y", which="minor", labelsize=MIN_FONT)
    ax.set_ylabel(f"{what} [µm] (log)")


#: values spanning less than this factor get a linear axis
LOG_RATIO = 20.0


def plot_verification(d: ReportData) -> bytes | None:
    """Per held-out pose (point, elbow): RMS over its cycles before / after / oracle; a log axis
    where they span more than :data:`LOG_RATIO`. None without a verification measurement."""
    if not np.isfinite(d.errors_before_um).any():
        return None
    rows = verification_rows(d)
    k = len(rows)
    x = np.arange(k)
    fig = _new_figure(10, 4.4)
    ax = fig.subplots()
    floor = 0.1  # µm: keeps zeros visible on a log axis
    series: list[tuple[str, str, list[float | None], np.ndarray]] = [
        ("before correction", "tab:orange", [r.before_rms for r in rows], d.errors_before_um)]
    if d.errors_after_um.size:
        series.append(("after correction (measured)", "tab:green", [r.after_rms for r in rows], d.errors_after_um))
    if d.oracle_after_um is not None and d.oracle_after_um.size:
        series.append(("after, true parameters (oracle)", "tab:purple", [r.oracle_rms for r in rows], d.oracle_after_um))
    w = 0.8 / len(series)
    for s, (label, colour, values, every) in enumerate(series):
        v = np.array([np.nan if val is None else val for val in values], dtype=float)
        ax.bar(x - 0.4 + w * (s + 0.5), np.maximum(v, floor), w, color=colour, label=label)
        level = rms(every)
        ax.axhline(max(level, floor), color=colour, ls="--", lw=1.0, label=f"RMS {label.split(' (')[0]} = {level:.1f} µm")
    drawn = np.array([v for _, _, values, _ in series for v in values if v is not None], dtype=float)
    _value_axis(ax, drawn, "position error, RMS over cycles")
    ax.set_xticks(x, [f"{r.point}\nelbow {elbow_text(r.elbow)}" for r in rows], fontsize=MIN_FONT,
                  rotation=0 if k <= 14 else 60)
    for tick, r in zip(ax.get_xticklabels(), rows):
        tick.set_color(_ELBOW_COLOURS.get(r.elbow or 0, "black"))
    ax.grid(True, which="both", axis="y", alpha=0.3)
    ax.legend(fontsize=MIN_FONT, loc="upper center", bbox_to_anchor=(0.5, -0.22), ncol=2)
    worst = f" (max after correction: {nanmax(d.errors_after_um):.1f} µm)" if d.errors_after_um.size else " (nothing uploaded)"
    ax.set_title(f"{d.robot_name}, run {d.run_id}: verification per held-out pose{worst}", fontsize=10)
    return _png(fig)


def plot_trend(d: ReportData) -> bytes | None:
    """The robot's accuracy per run, in run order: calibrations' RMS after correction, rechecks'
    drift RMS with their tolerance (a drifted recheck filled red). None without a history (one
    run) or without any figure to draw."""
    runs = list(d.trend)
    if len(runs) < 2 or not any(r.figure_um is not None or r.drift_tolerance_um is not None for r in runs):
        return None
    x = np.arange(len(runs))
    fig = _new_figure(10, 3.8)
    ax = fig.subplots()

    def pick(cond: Any, value: Any) -> tuple[list[int], list[float]]:
        xs, ys = [], []
        for i, r in enumerate(runs):
            v = value(r)
            if cond(r) and v is not None:
                xs.append(i)
                ys.append(v)
        return xs, ys

    cx, cy = pick(lambda r: not r.is_recheck, lambda r: r.rms_after_um)
    if cx:
        ax.plot(cx, cy, "o-", color="tab:green", label="calibration: RMS after correction")
    rx, ry = pick(lambda r: r.is_recheck, lambda r: r.drift_rms_um)
    if rx:
        ax.plot(rx, ry, "s--", color="tab:blue", label="recheck: drift RMS")
    dx, dy = pick(lambda r: r.is_recheck and r.outcome == "DRIFTED", lambda r: r.drift_rms_um)
    if dx:
        ax.plot(dx, dy, "s", color="tab:red", ms=9, label="recheck: drifted")
    tx, ty = pick(lambda r: r.is_recheck, lambda r: r.drift_tolerance_um)
    if tx:
        ax.plot(tx, ty, "_", color="tab:red", ms=22, mew=2, ls="none", label="recheck: tolerance")
    for i, r in enumerate(runs):
        if not r.is_recheck and r.rms_after_um is None:
            ax.annotate("no upload" if r.outcome == "NOT_UPLOADED" else "no figure", (i, 0.0),
                        xytext=(0, 4), textcoords="offset points", ha="center", fontsize=MIN_FONT, color="gray")
    ax.set_xlim(-0.5, len(runs) - 0.5)
    ax.set_ylim(bottom=0.0)
    ax.set_xticks(x, [f"run {r.run_id}\n{r.created[:10]}" for r in runs], fontsize=MIN_FONT,
                  rotation=0 if len(runs) <= 12 else 60)
    for tick, r in zip(ax.get_xticklabels(), runs):
        if r.run_id == _int_or_none(d.run_id):
            tick.set_fontweight("bold")
    ax.set_ylabel("position error [µm]")
    ax.grid(True, axis="y", alpha=0.3)
    ax.legend(fontsize=MIN_FONT, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    ax.set_title(f"{d.robot_name}: accuracy per run, oldest first (this report: run {d.run_id})", fontsize=10)
    return _png(fig)


def _int_or_none(v: Any) -> int | None:
    try:
        return int(v)
    except (TypeError, ValueError):
        return None
