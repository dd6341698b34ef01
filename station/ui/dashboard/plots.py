"""A robot's history as inline SVG, drawn on the server (no chart library, no script): after RMS
and worst AP at each calibration, and the drift at each recheck against its tolerance band."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from datetime import datetime, timezone
from html import escape
from typing import Any

__all__ = ["history_svg"]

W, H = 860, 220
PAD_L, PAD_R, PAD_T, PAD_B = 56, 16, 26, 30


def _t(v: Any) -> float:
    if isinstance(v, datetime):
        d = v if v.tzinfo else v.replace(tzinfo=timezone.utc)
    else:
        d = datetime.fromisoformat(str(v).replace("Z", "+00:00"))
    return d.timestamp()


def _nice_max(v: float) -> float:
    """The smallest 1, 2, 2.5 or 5 × 10^e at or above ``v`` (decades outside: 122.7 → 200, not the
    1 000 the mantissa-first loop gave, issue 39)."""
    if not math.isfinite(v) or v <= 0:
        return 1.0
    for e in range(-3, 10):
        for m in (1, 2, 2.5, 5):
            step = m * 10.0 ** e
            if step >= v:
                return step
    return v


def _axes(title: str, t0: float, t1: float, ymax: float, unit: str) -> list[str]:
    out = [f'<text x="{PAD_L}" y="16" class="title">{escape(title)}</text>']
    x0, x1, y0, y1 = PAD_L, W - PAD_R, H - PAD_B, PAD_T
    out.append(f'<line x1="{x0}" y1="{y0}" x2="{x1}" y2="{y0}" class="axis"/>')
    out.append(f'<line x1="{x0}" y1="{y0}" x2="{x0}" y2="{y1}" class="axis"/>')
    for i in range(5):
        v = ymax * i / 4
        y = y0 - (y0 - y1) * i / 4
        out.append(f'<line x1="{x0}" y1="{y:.1f}" x2="{x1}" y2="{y:.1f}" class="grid"/>')
        out.append(f'<text x="{x0 - 6}" y="{y + 4:.1f}" class="tick" text-anchor="end">{v:g}</text>')
    out.append(f'<text x="12" y="{(y0 + y1) / 2:.0f}" class="tick" transform="rotate(-90 12 {(y0 + y1) / 2:.0f})" '
               f'text-anchor="middle">{escape(unit)}</text>')
    for i in range(5):
        t = t0 + (t1 - t0) * i / 4
        x = x0 + (x1 - x0) * i / 4
        label = datetime.fromtimestamp(t, timezone.utc).strftime("%Y-%m-%d")
        anchor = "start" if i == 0 else "end" if i == 4 else "middle"  # the ends stay inside the plot
        out.append(f'<text x="{x:.1f}" y="{y0 + 18}" class="tick" text-anchor="{anchor}">{label}</text>')
    return out


def _panel(title: str, series: Sequence[tuple[str, str, Sequence[tuple[float, float]]]], t0: float, t1: float,
           band: Sequence[tuple[float, float]] = (), unit: str = "µm", test_id: str = "") -> str:
    values = [v for _, _, pts in series for _, v in pts] + [v for _, v in band]
    ymax = _nice_max(max(values, default=1.0) * 1.05)
    span = max(t1 - t0, 1.0)
    x0, x1, y0, y1 = PAD_L, W - PAD_R, H - PAD_B, PAD_T

    def xy(t: float, v: float) -> str:
        return f"{x0 + (x1 - x0) * (t - t0) / span:.1f},{y0 - (y0 - y1) * min(v, ymax) / ymax:.1f}"

    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {W} {H}" class="plot" role="img" '
             f'data-testid="{escape(test_id)}" aria-label="{escape(title)}">']
    parts += _axes(title, t0, t1, ymax, unit)
    if band:  # a step: each recheck's tolerance holds until the next, the first from the axis' start
        steps = [(t0, band[0][1])] + [p for (t, v), (_, prev) in zip(band[1:], band) for p in ((t, prev), (t, v))]
        steps.append((t1, band[-1][1]))
        top = " ".join(xy(t, v) for t, v in steps)
        bottom = " ".join(xy(t, 0.0) for t, _ in reversed(steps))
        parts.append(f'<polygon points="{top} {bottom}" class="band"><title>tolerance</title></polygon>')
    legend_x = W - PAD_R - 10
    for i, (name, css, pts) in enumerate(series):
        if not pts:
            continue
        if len(pts) > 1:
            parts.append(f'<polyline points="{" ".join(xy(t, v) for t, v in pts)}" class="line {css}"/>')
        if len(pts) <= 400:  # markers where they can still be told apart
            parts += [f'<circle cx="{xy(t, v).split(",")[0]}" cy="{xy(t, v).split(",")[1]}" r="2.5" '
                      f'class="dot {css}"/>' for t, v in pts]
        parts.append(f'<text x="{legend_x}" y="{16 + 0 * i}" dx="{-150 * i}" class="legend {css}" '
                     f'text-anchor="end">{escape(name)}</text>')
    if not any(pts for _, _, pts in series):
        parts.append(f'<text x="{W / 2}" y="{H / 2}" class="tick" text-anchor="middle">no data</text>')
    parts.append("</svg>")
    return "".join(parts)


def _points(runs: Sequence[Mapping[str, Any]], key: str) -> list[tuple[float, float]]:
    """(time, value) of the runs with a finite value under ``key`` (a row stored before schema 4's
    checks may hold NaN)."""
    return [(_t(r["finished_utc"]), float(v)) for r in runs
            if isinstance(v := r.get(key), (int, float)) and math.isfinite(v)]


def history_svg(runs: Sequence[Mapping[str, Any]]) -> tuple[str, str]:
    """Two SVG panels (accuracy at calibrations; drift at rechecks with its tolerance band) for a
    robot's runs, oldest first."""
    times = [_t(r["finished_utc"]) for r in runs]
    t0, t1 = (min(times), max(times)) if times else (0.0, 1.0)
    if t1 - t0 < 86400:
        t0, t1 = t0 - 43200, t1 + 43200
    cal = [r for r in runs if r["kind"] == "calibration" and r.get("outcome") == "SUCCESS"]
    rec = [r for r in runs if r["kind"] == "recheck"]
    rms, ap = _points(cal, "rms_after_um"), _points(cal, "ap_max_um")
    drift, band = _points(rec, "drift_rms_um"), _points(rec, "tolerance_um")
    accuracy = _panel("accuracy after calibration", [("RMS after", "rms", rms), ("worst AP", "ap", ap)],
                      t0, t1, test_id="plot-accuracy")
    drifts = _panel("drift at each recheck (band: tolerance)", [("drift RMS", "drift", drift)], t0, t1, band,
                    test_id="plot-drift")
    return accuracy, drifts
