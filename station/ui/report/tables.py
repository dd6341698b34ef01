"""The report's tables as rows of display strings, shared by the HTML and the Markdown so both
files say the same thing. People units: µm and arc seconds (″); nominal and identified values
in mm and degrees."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any

import numpy as np

from station.core.units import ARCSEC, DEG, UM
from station.ui.report.before_basis import before_basis_line
from station.ui.report.contents import ReportData

#: |r| above this marks a strong correlation
STRONG_CORRELATION = 0.9

#: what the predicted accuracy holds, said wherever it is shown
ACCURACY_SCOPE = ("parameter uncertainty only: the identification's covariance propagated to the "
                  "tool position. Not included: probe noise, robot repeatability, reversal error "
                  "(backlash), the table's interpolation error, thermal drift")

_LABEL = re.compile(r"^(?P<point>.+?) elbow (?P<elbow>[+-]?\d+)(?: cycle (?P<pass>\d+))?(?: #(?P<cycle>\d+))?$")

PARAM_GROUPS = (
    ("robot", "Robot's own parameters", "the arm's geometry: what the correction table corrects"),
    ("setup", "Set-up R.*", "the robot base's pose in the calibration body's frame: this cell's "
                            "mounting, not the robot"),
    ("head", "Head / tool K.*", "the probe head on the flange: replaced by the user's tool later"),
)


def fmt(v: Any, digits: int = 1) -> str:
    if v is None:
        return "—"
    if isinstance(v, (bool, np.bool_)):
        return str(bool(v))
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        return "—" if not math.isfinite(float(v)) else f"{float(v):.{digits}f}"
    return str(v)


def rms(a: Any) -> float:
    a = np.asarray(a, dtype=float)
    a = a[np.isfinite(a)]
    return float(np.sqrt(np.mean(a**2))) if a.size else float("nan")


def nanmax(a: Any) -> float:
    a = np.asarray(a, dtype=float)
    a = a[np.isfinite(a)]
    return float(a.max()) if a.size else float("nan")


def split_label(label: str) -> tuple[str, int | None, int | None]:
    """``"C1.b elbow -1 #2"`` → ``("C1.b", -1, 2)`` (a plan label's ``cycle N`` is dropped: the
    pose is the same); a label of another form is all point."""
    m = _LABEL.match(label.strip())
    if not m:
        return label, None, None
    return m["point"], int(m["elbow"]), (int(m["cycle"]) if m["cycle"] else None)


def elbow_text(elbow: int | None) -> str:
    return "—" if elbow is None else f"{elbow:+d}"


_TIMESTAMP = re.compile(r"^(?P<date>\d{4}-\d{2}-\d{2})[T ](?P<time>\d{2}:\d{2}:\d{2})(?:\.\d+)?(?P<z>Z|[+-]00:?00)?$")


def timestamp_text(created: str) -> str:
    """``2026-12-01T23:57:22.702231Z`` → ``2026-12-01 23:57:22 UTC`` (to the second: what a
    record needs); other text as it is, "—" for none."""
    text = created.strip()
    m = _TIMESTAMP.match(text)
    if not m:
        return text or "—"
    return f"{m['date']} {m['time']}" + (" UTC" if m["z"] else "")


# ----------------------------------------------------------------------------- summary
def summary_rows(d: ReportData, *, outcome: bool = True) -> list[tuple[str, str]]:
    """(quantity, value): the outcome, exit code and the summary's figures, each once
    (``outcome=False``: without the outcome and exit code, which the HTML shows as a banner)."""
    rows: list[tuple[str, str]] = []
    s = d.summary
    if s is None:
        rows.append(("outcome", "not stored (the run has no summary)"))
    else:
        if outcome:
            rows.append(("outcome", s.outcome.name))
            rows.append(("exit code", str(s.exit_code)))
        rows.append(("meaning", s.outcome.description))
        for label, value, unit, digits in s.figures():
            rows.append((label, f"{fmt(value, digits)}{(' ' + unit) if unit else ''}"))
        if s.upload_skipped:
            declined = any("declined" in n for n in s.notes)
            rows.append(("upload", ("declined by the operator" if declined else "skipped (--no-upload)")
                         + ": no correction is active"))
        if s.failure is not None:
            rows.append(("stopped by", f"{s.failure.error_type}: {s.failure.message}"))
            if s.failure.hint:
                rows.append(("what to do", s.failure.hint))
    poses = verification_poses(d)
    if poses:
        n_cycles = int(np.isfinite(d.errors_before_um).sum())
        elbows = sorted({e for _, e, _ in poses if e is not None}, reverse=True)
        rows.append(("verification", f"{len(poses)} held-out poses, {n_cycles} measurements; elbows "
                                     f"{', '.join(f'{e:+d}' for e in elbows) or '—'}"))
    if s is not None and (line := before_basis_line(s.before)) is not None:
        rows.append(("'before' measured on", line.removeprefix("before: ")))
    if s is not None and (recentred := s.recentring_text()) is not None:
        rows.append(("re-centred readings", recentred))
    # the shifted verification path's least clearance beside the pre-motion one [mm] (issue 40); a run
    # that designed no table has the pre-motion one alone, which the cell's picture states
    if s is not None and any(c.check != "pre-motion" for c in s.clearances):
        rows.append(("least collision clearance", "; ".join(c.text() for c in s.clearances)))
    return rows


#: how the stored RP note begins (RunSummary.rp_text): the report words it afresh from the figures
_RP_NOTE = "RP (ISO 9283 repeatability"


def summary_notes(d: ReportData) -> list[str]:
    """The run's notes, then the report's own. The RP note is computed again from the summary's
    figures (RunSummary.rp_text), so that a run stored with an older wording never shows a
    statement its numbers contradict."""
    s = d.summary
    rp = s.rp_text() if s is not None else None
    notes = [rp if rp is not None and n.startswith(_RP_NOTE) else n for n in (s.notes if s is not None else ())]
    return notes + list(d.notes)


def record_rows(d: ReportData) -> list[tuple[str, str]]:
    """(item, value): what identifies the run, the station and the devices."""
    s = d.summary
    rows = [("run", str(d.run_id)), ("robot", d.robot_name)]
    if s is not None and s.cell:
        rows.append(("cell", s.cell))
    rows.append(("created", timestamp_text(d.created)))
    if d.run_status:
        rows.append(("run database status", d.run_status))
    rows.append(("station version", d.station_version or "not recorded"))
    if d.devices is None:
        rows.append(("devices", "not recorded (a run from before device identification was stored)"))
    else:
        rows.append(("probe interface", device_text(d.devices.get("probe_interface", "not recorded"))))
        rows.append(("controller map version", d.devices.get("controller_map_version", "not recorded")))
    if s is not None and s.db:
        rows.append(("run database", s.db))
    return rows


_REPR = re.compile(r"^\w+\((?P<fields>.*)\)$")


def device_text(text: str) -> str:
    """``"DeviceInfo(model='SIM-PH6', firmware='1.0.0', channels=6)"`` (a stored repr) →
    ``"model SIM-PH6, firmware 1.0.0, channels 6"``; other text as it is."""
    m = _REPR.match(text.strip())
    if not m:
        return text
    fields = re.findall(r"(\w+)=('[^']*'|\"[^\"]*\"|[^,]+)", m["fields"])
    if not fields:
        return text
    return ", ".join(f"{k} {v.strip().strip(chr(39)).strip(chr(34))}" for k, v in fields)


# ----------------------------------------------------------------------------- parameters
def param_group(name: str) -> str:
    if name.startswith("R."):
        return "setup"
    if name.startswith("K."):
        return "head"
    return "robot"


#: the parameter tables' columns per kind: one unit per column (lengths and angles apart)
PARAM_KINDS = (
    ("lengths", ("parameter", "nominal mm", "identified mm", "Δ µm", "σ µm")),
    ("angles", ("parameter", "nominal °", "identified °", "Δ ″", "σ ″")),
)


def param_rows(d: ReportData, group: str | None = None,
               kind: str | None = None) -> list[tuple[str, str, str, str, str]]:
    """(name, nominal, identified, Δ, σ): lengths in mm, mm, µm, µm; angles in °, °, ″, ″
    (``kind`` "lengths" or "angles" keeps one of them, as :data:`PARAM_KINDS` heads them)."""
    rows = []
    for name, nom, ide, sig, ang in zip(d.param_names, d.param_nominal, d.param_identified,
                                        d.param_sigma, d.param_is_angle):
        if group is not None and param_group(name) != group:
            continue
        if kind is not None and (kind == "angles") != bool(ang):
            continue
        if ang:
            scale_val, scale_small, digits_val = (1 / DEG), (1 / ARCSEC), 5
        else:
            scale_val, scale_small, digits_val = 1.0, (1 / UM), 4
        sigma = "held" if not math.isfinite(sig) else fmt(sig * scale_small, 1)
        rows.append((name, fmt(nom * scale_val, digits_val), fmt(ide * scale_val, digits_val),
                     fmt((ide - nom) * scale_small, 1), sigma))
    return rows


def correlation_pairs(d: ReportData, threshold: float = STRONG_CORRELATION) -> list[tuple[str, str, float]]:
    """Pairs of parameters with |r| > threshold, strongest first."""
    c = d.param_correlation
    if c is None:
        return []
    i, j = np.triu_indices(c.shape[0], 1)
    r = c[i, j]
    keep = np.isfinite(r) & (np.abs(r) > threshold)
    pairs = [(d.param_names[a], d.param_names[b], float(v)) for a, b, v in zip(i[keep], j[keep], r[keep])]
    return sorted(pairs, key=lambda t: -abs(t[2]))


def short_name(name: str) -> str:
    """A column heading for the correlation matrix: ``A2.pitch`` → ``A2.pi``."""
    head, _, tail = name.partition(".")
    return f"{head}.{tail[:2]}" if tail else name


# ----------------------------------------------------------------------------- residuals
@dataclass(frozen=True)
class ResidualGroup:
    label: str  # point and elbow
    n: int
    rms_pos_um: float
    max_pos_um: float
    rms_ori_arcsec: float | None
    outliers: int


def residual_groups(d: ReportData) -> list[ResidualGroup]:
    """The identification residuals per measured pose (point and elbow; its repeats together)."""
    pos = d.position_residuals_um
    norm = np.linalg.norm(pos, axis=1) if pos.shape[1] > 1 else np.abs(pos[:, 0])
    ori = d.orientation_residuals_arcsec
    onorm = np.linalg.norm(ori, axis=1) if ori is not None else None
    labels = d.pose_labels or tuple(str(i + 1) for i in range(norm.size))
    order: dict[str, list[int]] = {}
    for i, lab in enumerate(labels):
        point, elbow, _ = split_label(lab)
        key = point if elbow is None else f"{point} elbow {elbow:+d}"
        order.setdefault(key, []).append(i)
    out = []
    outl = set(d.outliers)
    for key, idx in order.items():
        out.append(ResidualGroup(key, len(idx), rms(norm[idx]), nanmax(norm[idx]),
                                 rms(onorm[idx]) if onorm is not None else None,
                                 sum(1 for i in idx if i in outl)))
    return out


# ----------------------------------------------------------------------------- verification
def verification_poses(d: ReportData) -> list[tuple[str, int | None, list[int]]]:
    """(point, elbow, row indices) per held-out pose, in the order measured."""
    labels = d.verify_labels or tuple(str(i + 1) for i in range(d.errors_before_um.size))
    poses: dict[tuple[str, int | None], list[int]] = {}
    for i, lab in enumerate(labels):
        point, elbow, _ = split_label(lab)
        poses.setdefault((point, elbow), []).append(i)
    return [(p, e, idx) for (p, e), idx in poses.items()]


@dataclass(frozen=True)
class VerificationRow:
    point: str
    elbow: int | None
    n: int  # valid 'before' cycles
    before_rms: float
    after_rms: float | None  # None: nothing uploaded
    after_max: float | None
    oracle_rms: float | None


def verification_rows(d: ReportData) -> list[VerificationRow]:
    """One row per held-out pose (point, elbow): RMS over its cycles before / after / oracle."""
    b, a, o = d.errors_before_um, d.errors_after_um, d.oracle_after_um
    rows = []
    for point, elbow, idx in verification_poses(d):
        rows.append(VerificationRow(
            point, elbow, int(np.isfinite(b[idx]).sum()), rms(b[idx]),
            rms(a[idx]) if a.size else None, nanmax(a[idx]) if a.size else None,
            rms(o[idx]) if o is not None and o.size else None))
    return rows


def verification_total(d: ReportData) -> VerificationRow:
    a, o = d.errors_after_um, d.oracle_after_um
    return VerificationRow("all poses", None, int(np.isfinite(d.errors_before_um).sum()), rms(d.errors_before_um),
                           rms(a) if a.size else None, nanmax(a) if a.size else None,
                           rms(o) if o is not None and o.size else None)


def per_elbow_rows(d: ReportData) -> list[tuple[str, str, str, str, str]]:
    """(elbow, poses, before RMS, after RMS, oracle RMS) per elbow, so a missing one shows."""
    out = []
    poses = verification_poses(d)
    a, o = d.errors_after_um, d.oracle_after_um
    for elbow in sorted({e for _, e, _ in poses if e is not None}, reverse=True):
        idx = [i for _, e, ix in poses if e == elbow for i in ix]
        out.append((f"{elbow:+d}", str(sum(1 for _, e, _ in poses if e == elbow)),
                    fmt(rms(d.errors_before_um[idx])), fmt(rms(a[idx])) if a.size else "—",
                    fmt(rms(o[idx])) if o is not None and o.size else "—"))
    return out


# ----------------------------------------------------------------------------- accuracy
def xy_positions(xy: np.ndarray, tol_mm: float = 0.5) -> np.ndarray:
    """Index of the distinct x-y position of each point (points within ``tol_mm`` coincide)."""
    if not xy.shape[0]:
        return np.zeros(0, dtype=int)
    key = np.round(xy / tol_mm).astype(np.int64)
    _, inverse = np.unique(key, axis=0, return_inverse=True)
    return np.asarray(inverse).reshape(-1)


def accuracy_rows(d: ReportData) -> list[tuple[str, str, str, str, str, str]]:
    """(elbow, points, x-y positions, min, mean, max σ [µm]) per elbow (one row without elbows)."""
    sig = d.accuracy_sigma_mm * (1 / UM)
    elbows = d.accuracy_elbows
    groups: list[tuple[str, np.ndarray]] = []
    if elbows is None:
        groups.append(("—", np.ones(sig.size, dtype=bool)))
    else:
        e = np.asarray(elbows)
        groups.extend((f"{v:+d}", e == v) for v in sorted(set(elbows), reverse=True))
    out = []
    for name, m in groups:
        s = sig[m]
        n_xy = int(np.unique(xy_positions(d.accuracy_xy_mm[m])).size)
        out.append((name, str(int(m.sum())), str(n_xy),
                    fmt(np.nanmin(s) if s.size else math.nan), fmt(np.nanmean(s) if s.size else math.nan),
                    fmt(nanmax(s))))
    return out


def accuracy_comparison(d: ReportData) -> list[tuple[str, str]]:
    """Measured figures that hold what the prediction leaves out, to read it against."""
    s = d.summary
    out: list[tuple[str, str]] = []
    sig = d.accuracy_sigma_mm * (1 / UM)
    if sig.size:
        out.append(("predicted σ (parameters only), largest", f"{fmt(nanmax(sig))} µm"))
    if s is not None and s.after is not None:
        out.append(("measured RMS after correction", f"{fmt(s.after.rms_um)} µm"))
        if s.after.rp_max_um is not None:
            out.append(("measured repeatability RP max (ISO 9283)", f"{fmt(s.after.rp_max_um)} µm"))
    if s is not None and s.identification is not None:
        out.append(("identification residual RMS (noise, repeatability, what the model leaves out)",
                    f"{fmt(s.identification.rms_residual_um)} µm"))
        if s.identification.sigma_scaled_by != 1.0:  # the a-posteriori check scaled the σ (issue 38)
            out.append(("σ scaled by the a-posteriori variance factor s0 (residuals above the assumed noise, "
                        "χ² test at 5 %)", f"× {s.identification.sigma_scaled_by:.2f}"))
    if s is not None and s.correction is not None:
        out.append(("table interpolation bound", f"{fmt(s.correction.interpolation_bound_um)} µm"))
    if s is not None and s.reversal is not None:
        out.append(("reversal error RMS", f"{fmt(s.reversal.rms_um)} µm"))
    return out


# ----------------------------------------------------------------------------- table, reversal
def table_rows(d: ReportData) -> list[tuple[str, str]]:
    s = d.summary
    t = d.table_info or {}
    rows: list[tuple[str, str]] = []
    c = s.correction if s is not None else None
    if c is None and not t and (s is None or s.upload is None):
        return rows
    if "grid" in t:
        rows.append(("grid (robot base frame)", str(t["grid"])))
    if "grid_shape" in t:
        rows.append(("nodes per elbow", " × ".join(str(n) for n in t["grid_shape"])
                     + f" (x, y, z, yaw); elbows {t.get('elbows', '—')}"))
    if c is not None:
        rows.append(("values", str(c.n_values)))
        rows.append(("interpolation bound", f"{fmt(c.interpolation_bound_um)} µm"))
    if "interpolation_bound_arcsec" in t:
        rows.append(("interpolation bound, orientation", f"{fmt(t['interpolation_bound_arcsec'], 2)} ″"))
    if "unreachable_nodes" in t:
        rows.append(("unreachable nodes (nearest value; not covered by the bound)", str(t["unreachable_nodes"])))
    if "max_correction" in t:
        rows.append(("largest correction per joint", str(t["max_correction"])))
    if c is not None:
        rows.append(("CRC-32 of the table", c.crc32))
    if "crc32" in t and c is not None:
        same = t["crc32"] == c.crc32
        rows.append(("rebuilt from the stored measurements", "same CRC-32" if same else
                     f"CRC-32 {t['crc32']} differs from the run's {c.crc32}: the station version changed"))
    if s is not None and s.upload is not None:
        rows.append(("upload", f"CRC-32 {s.upload.crc32}, read back identical, activated "
                               f"({'verified' if s.upload.verified else 'NOT verified'}) in {fmt(s.upload.seconds, 2)} s"))
    elif s is not None and s.upload_skipped:
        rows.append(("upload", "not uploaded: no correction is active on the controller"))
    return rows


def reversal_rows(d: ReportData) -> list[tuple[str, str]]:
    s = d.summary
    if s is None or s.reversal is None:
        return []
    r = s.reversal
    return [("poses approached from both sides", str(r.n)), ("RMS", f"{fmt(r.rms_um)} µm"),
            ("max", f"{fmt(r.max_um)} µm")]


def residual_line(d: ReportData) -> str:
    pos = d.position_residuals_um
    ori = d.orientation_residuals_arcsec
    if pos.shape[1] == 1:
        return (f"{pos.shape[0]} distances; RMS residual {rms(pos):.1f} µm, "
                f"max |r| {nanmax(np.abs(pos)):.1f} µm.")
    norm = np.linalg.norm(pos, axis=1)
    line = f"{pos.shape[0]} poses; RMS position residual {rms(norm):.1f} µm (max {nanmax(norm):.1f} µm)"
    if ori is not None:
        onorm = np.linalg.norm(ori, axis=1)
        line += f", RMS orientation residual {rms(onorm):.1f} ″ (max {nanmax(onorm):.1f} ″)"
    if d.outliers:
        line += f"; {len(d.outliers)} flagged as outliers"
    return line + "."


def parameter_line(d: ReportData) -> str:
    n_id = int(np.isfinite(d.param_sigma).sum())
    return (f"{len(d.param_names)} parameters, {n_id} identified (σ given), the others held at nominal. "
            "Δ = identified − nominal.")


def groups_present(d: ReportData) -> list[tuple[str, str, str]]:
    have = {param_group(n) for n in d.param_names}
    return [g for g in PARAM_GROUPS if g[0] in have]



# ----------------------------------------------------------------------------- trend
TREND_HEAD = ("run", "date (UTC)", "kind", "outcome", "RMS after / drift RMS µm", "tolerance µm", "moved parameters")


def has_trend(d: ReportData) -> bool:
    """The trend is shown from two runs of the robot on (one run has no history)."""
    return len(d.trend) > 1


def trend_date(created: str) -> str:
    """``2026-11-22T05:32:27.905242Z`` → ``2026-11-22 05:32``; other text as it is."""
    text = created.strip().rstrip("Z")
    if len(text) >= 16 and text[10] in "T ":
        return f"{text[:10]} {text[11:16]}"
    return text or "—"


def trend_rows(d: ReportData) -> list[tuple[str, str, str, str, str, str, str]]:
    """Per run (oldest first): run, date, kind, outcome, its accuracy figure (a calibration's RMS
    after correction, a recheck's drift RMS), a recheck's tolerance, the parameters it found moved."""
    rows = []
    for r in d.trend:
        outcome = r.outcome or (f"unfinished ({r.status})" if r.status else "unfinished")
        if r.is_recheck:
            kind = f"recheck of run {r.baseline}" if r.baseline is not None else "recheck"
            moved = ", ".join(r.moved) if r.moved else ("none" if r.outcome else "—")
            tol = fmt(r.drift_tolerance_um)
        else:
            kind, moved, tol = "calibration", "—", "—"
        rows.append((str(r.run_id), trend_date(r.created), kind, outcome, fmt(r.figure_um), tol, moved))
    return rows


def trend_line(d: ReportData) -> str:
    n_cal = sum(1 for r in d.trend if not r.is_recheck)
    n_re = len(d.trend) - n_cal
    return (f"The runs of this cell and robot in the run database up to and including run {d.run_id}: "
            f"{n_cal} calibration{'s' if n_cal != 1 else ''} and {n_re} recheck{'s' if n_re != 1 else ''}. "
            "A calibration's figure is the RMS position error at the held-out poses after correction (none "
            "when nothing was uploaded); a recheck's is the RMS position drift against its baseline "
            "calibration, beside the tolerance it was judged by.")


# -- tools after the head ([[tool]], station/cell/correction/robot_tools.py) ----------------------------------------

TOOL_HEAD = ("tool", "TCP x, y, z mm", "correction", "bound µm", "flange shift µm", "flange rotation ″",
             "head's correction, predicted RMS µm", "max µm")
TOOL_CHECK_HEAD = ("tool", "targets", "own RMS µm", "own max µm", "oracle RMS µm", "oracle max µm",
                   "head's RMS µm", "head's max µm", "own / oracle")


#: what the simulation section says first (a simulated cell's judge, station/cell/records/judge.py)
SIMULATION_NOTE = ("Simulated run: the simulator knows the robot it plays. These figures judge the identified "
                   "model against that robot; a real cell's report has no such section.")
SIMULATION_HEAD = ("figure", "what it is", "value")


def has_simulation(d: ReportData) -> bool:
    return d.summary is not None and bool(d.summary.simulation)


def simulation_rows(d: ReportData) -> list[tuple[str, str, str]]:
    """The judge's figures: name, caption, value with its unit (the summary's ``simulation``)."""
    if d.summary is None:
        return []
    return [(f.name, f.caption, f"{f.value:.2f} {f.unit}" if f.unit == "×" else f"{f.value:.1f} {f.unit}")
            for f in d.summary.simulation]


def has_tools(d: ReportData) -> bool:
    return d.summary is not None and bool(d.summary.tools)


def tool_rows(d: ReportData) -> list[tuple[str, ...]]:
    """Per configured tool: its TCP, its own correction (table CRC or compensated targets), the
    identified tool-mount frame against the nominal, and what the head's correction would leave."""
    if d.summary is None:
        return []
    out: list[tuple[str, ...]] = []
    for s in d.summary.tools:
        x, y, z = s.tcp_mm_deg[:3]
        corr = f"table {s.crc32}" if s.crc32 else f"{s.n_targets} compensated targets"
        out.append((s.name, f"{x:g}, {y:g}, {z:g}", corr, fmt(s.interpolation_bound_um), fmt(s.flange_shift_um),
                    fmt(s.flange_rotation_arcsec), fmt(s.head_predicted_rms_um), fmt(s.head_predicted_max_um)))
    return out


def tool_check_rows(d: ReportData) -> list[tuple[str, ...]]:
    """Simulation only: per tool, the real robot's error over the tool's verification targets
    with its own correction, the oracle's and the head's (empty for a real cell)."""
    if d.summary is None:
        return []
    return [(s.name, str(s.n_after), fmt(s.after_rms_um), fmt(s.after_max_um), fmt(s.oracle_rms_um),
             fmt(s.oracle_max_um), fmt(s.head_rms_um), fmt(s.head_max_um), fmt(s.after_vs_oracle, 2))
            for s in d.summary.tools if s.after_rms_um is not None]


TOOL_NOTE = ("Each tool's correction is built for the controller's nominal model with that tool "
             "(K·H⁻¹·T, K the head transform, H the head in the flange frame, T the tool's TCP), from the "
             "identified K: the identified flange differs from the nominal one by what K absorbed. The head's "
             "table stays the uploaded one; when a tool goes on, upload its own table "
             "('station export --tool NAME'). The head's correction used for a tool leaves the error shown.")
TOOL_CHECK_NOTE = ("Simulated check over the held-out verification poses re-expressed as the tool's TCP: the "
                   "simulator's true robot with the true tool, its joints scattering with the robot's "
                   "repeatability, driven with each correction.")
