"""Calibration report: ``report.md`` plus PNG plots, in units people read (µm and arc seconds).

The caller (the runner / CLI) fills a :class:`ReportData` from its results; this module only
formats.  Inputs use the station's internal units (mm and rad, see :mod:`station.core.model`) except
the verification errors, which are µm already; the report converts everything to µm and ″.

Plots are drawn with matplotlib's Agg canvas on explicit ``Figure`` objects, chosen inside
:func:`write_report` (no pyplot, no global backend switch), so it is safe in a headless process
or in a worker thread of the UI.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from station.cell.summary import RunSummary
from station.core.units import ARCSEC, DEG, UM
from station.errors import ConfigError

__all__ = ["ReportData", "write_report"]


_PLOT_FILES = {
    "residuals": "residuals.png",
    "parameters": "parameters.png",
    "accuracy": "accuracy.png",
    "verification": "verification.png",
}


def _arr(a: Any, ndim: int | None = None, name: str = "") -> np.ndarray:
    out = np.array(a, dtype=float)
    if ndim is not None and out.ndim != ndim:
        raise ConfigError(f"report: {name} must be {ndim}-dimensional, got shape {out.shape}")
    out.setflags(write=False)
    return out


@dataclass(frozen=True)
class ReportData:
    """Everything a report shows, as plain arrays and strings.

    Units (inputs): parameters, residuals, accuracy in the station's internal **mm and rad**;
    verification errors in **µm**.

    * ``param_names`` (p,), ``param_nominal`` / ``param_identified`` / ``param_sigma`` (p,),
      ``param_is_angle`` (p,) bool: angle parameters are rad, the others mm.  ``param_sigma``
      may hold NaN for parameters that were held (not identified).
    * ``residuals`` (n, 6) [mm, mm, mm, rad, rad, rad] or (n, 3) [mm] — model − measured per
      identification pose (or per distance: (n, 1) [mm]).
    * ``accuracy_xy_mm`` (m, 2) evaluation points over the workspace, ``accuracy_sigma_mm`` (m,)
      predicted position σ of the TCP there.
    * ``errors_before_um`` / ``errors_after_um`` (k,) position error per verification pose,
      ``oracle_after_um`` (k,) or None: the error after correction as the simulator's ground
      truth sees it (simulated runs only).
    * ``summary``: the run's :class:`~station.cell.summary.RunSummary` (figures shown at the top).
    """

    robot_name: str
    run_id: str | int
    param_names: Sequence[str]
    param_nominal: np.ndarray
    param_identified: np.ndarray
    param_sigma: np.ndarray
    param_is_angle: np.ndarray
    residuals: np.ndarray
    accuracy_xy_mm: np.ndarray
    accuracy_sigma_mm: np.ndarray
    errors_before_um: np.ndarray
    errors_after_um: np.ndarray
    oracle_after_um: np.ndarray | None = None
    summary: RunSummary | None = None
    pose_labels: Sequence[str] | None = None  # (n,) labels of the identification poses
    verify_labels: Sequence[str] | None = None  # (k,) labels of the verification poses
    created: str = ""  # timestamp text, set by the caller (kept out for reproducible files)

    def __post_init__(self) -> None:
        names = tuple(str(n) for n in self.param_names)
        object.__setattr__(self, "param_names", names)
        p = len(names)
        for attr in ("param_nominal", "param_identified", "param_sigma"):
            a = _arr(getattr(self, attr), 1, attr)
            if a.shape != (p,):
                raise ConfigError(f"report: {attr} has {a.shape[0]} entries, param_names has {p}")
            object.__setattr__(self, attr, a)
        mask = np.array(self.param_is_angle, dtype=bool).reshape(-1)
        if mask.shape != (p,):
            raise ConfigError(f"report: param_is_angle has {mask.shape[0]} entries, param_names has {p}")
        mask.setflags(write=False)
        object.__setattr__(self, "param_is_angle", mask)

        res = _arr(self.residuals, None, "residuals")
        if res.ndim == 1:
            res = _arr(res.reshape(-1, 1))
        if res.ndim != 2 or res.shape[1] not in (1, 3, 6):
            raise ConfigError(f"report: residuals must be (n, 6), (n, 3) or (n, 1), got {res.shape}")
        object.__setattr__(self, "residuals", res)

        xy = _arr(self.accuracy_xy_mm, 2, "accuracy_xy_mm")
        sig = _arr(self.accuracy_sigma_mm, 1, "accuracy_sigma_mm")
        if xy.shape[1:] != (2,) or sig.shape[0] != xy.shape[0]:
            raise ConfigError(f"report: accuracy_xy_mm {xy.shape} and accuracy_sigma_mm {sig.shape} do not match")
        object.__setattr__(self, "accuracy_xy_mm", xy)
        object.__setattr__(self, "accuracy_sigma_mm", sig)

        before = _arr(self.errors_before_um, 1, "errors_before_um")
        after = _arr(self.errors_after_um, 1, "errors_after_um")
        if after.size and before.shape != after.shape:  # no 'after' when the upload was skipped
            raise ConfigError(f"report: errors_before_um {before.shape} and errors_after_um {after.shape} differ")
        object.__setattr__(self, "errors_before_um", before)
        object.__setattr__(self, "errors_after_um", after)
        if self.oracle_after_um is not None:
            oracle = _arr(self.oracle_after_um, 1, "oracle_after_um")
            if oracle.shape != after.shape:
                raise ConfigError(f"report: oracle_after_um {oracle.shape} and errors_after_um {after.shape} differ")
            object.__setattr__(self, "oracle_after_um", oracle)
        for attr, n in (("pose_labels", res.shape[0]), ("verify_labels", before.shape[0])):
            labels = getattr(self, attr)
            if labels is not None:
                labels = tuple(str(x) for x in labels)
                if len(labels) != n:
                    raise ConfigError(f"report: {attr} has {len(labels)} entries, expected {n}")
                object.__setattr__(self, attr, labels)

    # --- derived figures, in people units --------------------------------------------------
    @property
    def position_residuals_um(self) -> np.ndarray:
        """(n, c) position residual components [µm] (c = 3, or 1 for distances)."""
        r = self.residuals
        return r[:, :3] * (1 / UM) if r.shape[1] >= 3 else r * (1 / UM)

    @property
    def orientation_residuals_arcsec(self) -> np.ndarray | None:
        r = self.residuals
        return r[:, 3:6] * (1 / ARCSEC) if r.shape[1] == 6 else None


def _rms(a: np.ndarray) -> float:
    a = np.asarray(a, dtype=float)
    return float(np.sqrt(np.mean(a**2))) if a.size else float("nan")


def _fmt(v: Any, digits: int = 1) -> str:
    if isinstance(v, (bool, np.bool_)):
        return str(bool(v))
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        return "—" if not math.isfinite(float(v)) else f"{float(v):.{digits}f}"
    return str(v).replace("|", r"\|")


def _param_rows(d: ReportData) -> list[tuple[str, str, str, str, str, str]]:
    """(name, unit, nominal, identified, Δ, σ) with nominal/identified in mm|°, Δ and σ in µm|″."""
    rows = []
    for name, nom, ide, sig, ang in zip(
        d.param_names, d.param_nominal, d.param_identified, d.param_sigma, d.param_is_angle
    ):
        if ang:
            unit, scale_val, scale_small, digits_val = "° / ″", (1 / DEG), (1 / ARCSEC), 5
        else:
            unit, scale_val, scale_small, digits_val = "mm / µm", 1.0, (1 / UM), 4
        delta = (ide - nom) * scale_small
        sigma = "held" if not math.isfinite(sig) else _fmt(sig * scale_small, 1)
        rows.append(
            (name, unit, _fmt(nom * scale_val, digits_val), _fmt(ide * scale_val, digits_val),
             _fmt(delta, 1), sigma)
        )
    return rows


# ----------------------------------------------------------------------------- plots
def _new_figure(w: float, h: float):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(w, h), dpi=110, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _save(fig, path: Path) -> None:
    fig.savefig(path, format="png")


def _plot_residuals(d: ReportData, path: Path) -> None:
    pos = d.position_residuals_um
    ori = d.orientation_residuals_arcsec
    n = pos.shape[0]
    x = np.arange(1, n + 1)
    fig = _new_figure(10, 6.5 if ori is not None else 3.8)
    axes = fig.subplots(2 if ori is not None else 1, 1, sharex=True, squeeze=False)[:, 0]

    def draw(ax, data, unit, what, comps):
        if data.shape[1] == 1:
            ax.bar(x, data[:, 0], color="tab:blue", label="distance residual")
        else:
            norm = np.linalg.norm(data, axis=1)
            ax.bar(x, norm, color="lightgray", edgecolor="gray", label=f"|{what}|")
            for j, c in enumerate(comps[: data.shape[1]]):
                ax.plot(x, data[:, j], "o", ms=4, label=c)
        ax.axhline(0.0, color="black", lw=0.6)
        rms = _rms(np.linalg.norm(data, axis=1)) if data.shape[1] > 1 else _rms(data)
        ax.axhline(rms, color="tab:red", ls="--", lw=1, label=f"RMS |{what}| = {rms:.1f} {unit}")
        ax.set_ylabel(f"{what} residual [{unit}]")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)

    draw(axes[0], pos, "µm", "position", ("x", "y", "z"))
    if ori is not None:
        draw(axes[1], ori, "″", "orientation", ("about x", "about y", "about z"))
    axes[-1].set_xlabel("identification pose")
    if d.pose_labels is not None and n <= 40:
        axes[-1].set_xticks(x, d.pose_labels, rotation=60, ha="right", fontsize=7)
    elif n <= 40:
        axes[-1].set_xticks(x)
    fig.suptitle(f"{d.robot_name} — run {d.run_id}: residuals after identification (model − measured)")
    _save(fig, path)


def _plot_parameters(d: ReportData, path: Path) -> None:
    ang = d.param_is_angle
    groups = [(~ang, (1 / UM), "µm", "length parameters"), (ang, (1 / ARCSEC), "″", "angle parameters")]
    groups = [g for g in groups if g[0].any()]
    fig = _new_figure(9, 3.2 * len(groups) + 0.6)
    axes = fig.subplots(len(groups), 1, squeeze=False)[:, 0]
    names = np.array(d.param_names)
    for ax, (mask, scale, unit, title) in zip(axes, groups):
        delta = (d.param_identified[mask] - d.param_nominal[mask]) * scale
        sigma = d.param_sigma[mask] * scale
        idx = np.arange(mask.sum())
        held = ~np.isfinite(sigma)
        ax.bar(idx, delta, color=np.where(held, "lightgray", "tab:blue"))
        ok = ~held
        if ok.any():
            ax.errorbar(idx[ok], delta[ok], yerr=sigma[ok], fmt="none", ecolor="black", capsize=3)
        for i in np.flatnonzero(held):
            ax.text(i, 0.0, "held", ha="center", va="bottom", fontsize=7, color="gray")
        ax.axhline(0.0, color="black", lw=0.6)
        ax.set_xticks(idx, names[mask], rotation=60, ha="right", fontsize=7)
        ax.set_ylabel(f"identified − nominal [{unit}]")
        ax.set_title(f"{title} (error bars ±1σ; gray: held)", fontsize=9)
        ax.grid(True, axis="y", alpha=0.3)
    fig.suptitle(f"{d.robot_name} — run {d.run_id}: identified parameters")
    _save(fig, path)


def _plot_accuracy(d: ReportData, path: Path) -> None:
    fig = _new_figure(7, 6)
    ax = fig.subplots()
    xy = d.accuracy_xy_mm
    sig = d.accuracy_sigma_mm * (1 / UM)
    if xy.shape[0]:
        sc = ax.scatter(xy[:, 0], xy[:, 1], c=sig, cmap="viridis", s=60, edgecolors="k", linewidths=0.3)
        cb = fig.colorbar(sc, ax=ax)
        cb.set_label("predicted position σ [µm]")
        i = int(np.nanargmax(sig))
        ax.annotate(f"max {sig[i]:.1f} µm", xy[i], xytext=(6, 6), textcoords="offset points", fontsize=8)
    ax.plot([0], [0], "+", color="tab:red", ms=12, mew=2, label="robot base")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="lower left", fontsize=8)
    stats = (f"mean {np.nanmean(sig):.1f} µm, max {np.nanmax(sig):.1f} µm" if sig.size else "no points")
    ax.set_title(f"{d.robot_name} — run {d.run_id}: attainable pose accuracy\n({stats})", fontsize=10)
    _save(fig, path)


def _plot_verification(d: ReportData, path: Path) -> None:
    k = d.errors_before_um.shape[0]
    x = np.arange(1, k + 1)
    fig = _new_figure(10, 4.5)
    ax = fig.subplots()
    floor = 0.1  # µm: keeps zeros visible on a log axis

    def clip(a):
        return np.maximum(a, floor)

    w = 0.38 if d.oracle_after_um is None else 0.28
    ax.bar(x - w / 2 if d.oracle_after_um is None else x - w, clip(d.errors_before_um), w,
           color="tab:orange", label="before correction")
    lines = [(d.errors_before_um, "tab:orange", "RMS before")]
    if d.errors_after_um.size:  # none when the upload was skipped
        ax.bar(x + w / 2 if d.oracle_after_um is None else x, clip(d.errors_after_um), w,
               color="tab:green", label="after correction (measured)")
        lines.append((d.errors_after_um, "tab:green", "RMS after"))
    if d.oracle_after_um is not None:
        ax.bar(x + w, clip(d.oracle_after_um), w, color="tab:purple", label="after correction (oracle)")
        lines.append((d.oracle_after_um, "tab:purple", "RMS oracle"))
    for data, color, label in lines:
        rms = _rms(data)
        if math.isfinite(rms):
            ax.axhline(max(rms, floor), color=color, ls="--", lw=1.2, label=f"{label} = {rms:.1f} µm")
    ax.set_yscale("log")
    ax.set_ylabel("position error [µm] (log)")
    ax.set_xlabel("verification pose")
    if d.verify_labels is not None and k <= 40:
        ax.set_xticks(x, d.verify_labels, rotation=60, ha="right", fontsize=7)
    elif k <= 40:
        ax.set_xticks(x)
    ax.grid(True, which="both", axis="y", alpha=0.3)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    ax.set_title(f"{d.robot_name} — run {d.run_id}: verification before / after correction", fontsize=10)
    _save(fig, path)


# ----------------------------------------------------------------------------- markdown
def _flat_scalars(summary: Mapping[str, Any]) -> list[tuple[str, Any]]:
    """Scalar leaves of the summary, one nesting level deep, as dotted keys (lists skipped)."""
    out = []
    for key, v in summary.items():
        if isinstance(v, Mapping):
            for k2, v2 in v.items():
                if not isinstance(v2, (Mapping, list, tuple, np.ndarray)):
                    out.append((f"{key}.{k2}", v2))
        elif not isinstance(v, (list, tuple, np.ndarray)):
            out.append((str(key), v))
    return out



def _markdown(d: ReportData, files: Mapping[str, str]) -> str:
    L: list[str] = []
    L.append(f"# Calibration report — {d.robot_name}, run {d.run_id}")
    L.append("")
    if d.created:
        L.append(f"Created {d.created}.")
        L.append("")
    L.append("Units: lengths in µm (nominal and identified values in mm), angles in arc seconds ″ "
             "(nominal and identified values in degrees).")
    L.append("")

    # summary
    L.append("## Summary")
    L.append("")
    L.append("| quantity | value |")
    L.append("|---|---|")
    s = d.summary
    if s is not None:
        L.append(f"| outcome | {_fmt(s.outcome.name)} |")
        L.append(f"| robot | {_fmt(s.robot)} |")
        L.append(f"| cell | {_fmt(s.cell)} |")
        for label, value, unit, digits in s.figures():
            L.append(f"| {label} | {_fmt(value, digits)}{(' ' + unit) if unit else ''} |")
        if s.upload_skipped:
            L.append("| upload | skipped (--no-upload): no correction active |")
        L.append(f"| exit code | {s.exit_code} |")
    before, after = d.errors_before_um, d.errors_after_um
    if before.size:
        L.append(f"| verification poses | {before.size} |")
    L.append("")
    details = _flat_scalars(s.to_json()) if s is not None else []
    if details:
        L.append("<details><summary>All summary values</summary>")
        L.append("")
        L.append("| key | value |")
        L.append("|---|---|")
        for key, v in details:
            L.append(f"| {_fmt(key)} | {_fmt(v, 3)} |")
        L.append("")
        L.append("</details>")
        L.append("")

    # parameters
    n_id = int(np.isfinite(d.param_sigma).sum())
    L.append("## Identified parameters")
    L.append("")
    L.append(f"{len(d.param_names)} parameters, {n_id} identified (σ given), the others held at nominal. "
             "Δ = identified − nominal.")
    L.append("")
    L.append("| parameter | unit | nominal | identified | Δ | σ |")
    L.append("|---|---|---:|---:|---:|---:|")
    for row in _param_rows(d):
        L.append("| " + " | ".join(row) + " |")
    L.append("")
    L.append(f"![identified parameters]({files['parameters']})")
    L.append("")

    # residuals
    pos = d.position_residuals_um
    ori = d.orientation_residuals_arcsec
    L.append("## Residuals of the identification")
    L.append("")
    if pos.shape[1] == 1:
        L.append(f"{pos.shape[0]} distances; RMS residual {_rms(pos):.1f} µm, max |r| {np.max(np.abs(pos)) if pos.size else float('nan'):.1f} µm.")
    else:
        norm = np.linalg.norm(pos, axis=1)
        line = f"{pos.shape[0]} poses; RMS position residual {_rms(norm):.1f} µm (max {np.max(norm) if norm.size else float('nan'):.1f} µm)"
        if ori is not None:
            onorm = np.linalg.norm(ori, axis=1)
            line += f", RMS orientation residual {_rms(onorm):.1f} ″ (max {np.max(onorm) if onorm.size else float('nan'):.1f} ″)"
        L.append(line + ".")
    L.append("")
    L.append(f"![residuals per pose]({files['residuals']})")
    L.append("")

    # accuracy
    sig = d.accuracy_sigma_mm * (1 / UM)
    L.append("## Attainable pose accuracy over the workspace")
    L.append("")
    if sig.size:
        L.append(f"Predicted position σ at {sig.size} evaluation points: min {np.nanmin(sig):.1f} µm, "
                 f"mean {np.nanmean(sig):.1f} µm, max {np.nanmax(sig):.1f} µm.")
    else:
        L.append("No evaluation points.")
    L.append("")
    L.append(f"![pose accuracy]({files['accuracy']})")
    L.append("")

    # verification
    L.append("## Verification before and after correction")
    L.append("")
    oracle = d.oracle_after_um
    head = "| pose | before µm | after µm |" + (" oracle µm |" if oracle is not None else "")
    L.append(head)
    L.append("|---|---:|---:|" + ("---:|" if oracle is not None else ""))
    labels = d.verify_labels or tuple(str(i + 1) for i in range(before.size))
    for i in range(before.size):
        line = f"| {_fmt(labels[i])} | {before[i]:.1f} | {f'{after[i]:.1f}' if after.size else '—'} |"
        if oracle is not None:
            line += f" {oracle[i]:.1f} |"
        L.append(line)
    if before.size:
        line = f"| **RMS** | **{_rms(before):.1f}** | **{f'{_rms(after):.1f}' if after.size else '—'}** |"
        if oracle is not None:
            line += f" **{_rms(oracle):.1f}** |"
        L.append(line)
    L.append("")
    L.append(f"![verification errors]({files['verification']})")
    L.append("")
    return "\n".join(L)


def write_report(out_dir: Path, report: ReportData) -> Path:
    """Write ``report.md`` and its PNG plots into ``out_dir`` (created); return the .md path."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    _plot_residuals(report, out_dir / _PLOT_FILES["residuals"])
    _plot_parameters(report, out_dir / _PLOT_FILES["parameters"])
    _plot_accuracy(report, out_dir / _PLOT_FILES["accuracy"])
    _plot_verification(report, out_dir / _PLOT_FILES["verification"])
    md = out_dir / "report.md"
    tmp = md.with_suffix(".md.tmp")
    tmp.write_text(_markdown(report, _PLOT_FILES), encoding="utf-8")
    tmp.replace(md)
    return md
