"""The report's sign-off parts as rows of display strings, shared by the HTML and the Markdown:
the simulated-run banner, the test conditions, ISO 9283 AP and RP per pose, the acceptance
against the specification, the traceability block and the signature block; and the display
forms of timestamps and of the configuration snapshot's numbers.

People units: µm, mm, degrees, seconds; one unit per column, named in its heading.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable

from station.ui.report.contents import IsoPose, ReportData
from station.ui.report.tables import elbow_text, fmt

PASS, FAIL, NOT_JUDGED = "PASS", "FAIL", "not judged"

SIMULATED_BANNER = ("SIMULATED RUN: simulators stood in for the robot, the probe head and the body. "
                    "Not a calibration of a real robot; not for sign-off.")

SIGNATURE_ROLES = ("Operator", "Reviewed (QA)", "Approved")
SIGNATURE_HEAD = ("role", "name", "date", "signature")

POSES_HEAD = ("point", "elbow", "x mm", "y mm", "z mm", "cycles before", "cycles after")
ISO_HEAD = ("point", "elbow", "cycles before / after", "AP before µm", "RP before µm", "AP after µm", "RP after µm", "result")
ACCEPTANCE_HEAD = ("criterion", "required", "measured", "result")

POSES_NOTE = ("Held-out poses: never used by the identification. Position: the commanded TCP (the head frame's "
              "origin at the touch) in the calibration body's frame, from its CMM report; the robot is commanded "
              "to it as a Cartesian target in its base frame.")
ISO_NOTE = ("ISO 9283 pose characteristics per held-out pose, over its cycles: AP, pose accuracy, the distance "
            "from the commanded position to the barycentre of the attained ones; RP, pose repeatability, "
            "l̄ + 3·S_l of the attained positions' distances from their barycentre (two cycles at least). "
            "The whole-body figures (RMS over every pose and cycle) are in the table above.")

# a float literal with more digits than any measurement holds (a computed value written with repr)
_LONG_FLOAT = re.compile(r"(?<![\w.])-?\d+\.\d{7,}(?:[eE][+-]?\d+)?(?![\w.])|(?<![\w.])-?\d+(?:\.\d+)?[eE]-\d+(?![\w.])")
#: the snapshot's numbers are shown to this many decimals: nm for mm, µ° for degrees
SNAPSHOT_DECIMALS = 6


def _short_float(m: re.Match[str]) -> str:
    v = round(float(m.group(0)), SNAPSHOT_DECIMALS)
    out = f"{v:.{SNAPSHOT_DECIMALS}f}".rstrip("0")
    out = out + "0" if out.endswith(".") else out
    return "0.0" if out in ("-0.0", "0.0") else out


def tidy_config(text: str) -> str:
    """The configuration snapshot for display: float literals with more digits than a length or
    an angle means (``-170.00000000000003``, ``-3.55e-15``) rounded to
    :data:`SNAPSHOT_DECIMALS` decimals; quoted strings are left as they are."""
    out = []
    for line in text.splitlines(keepends=True):
        parts = line.split('"')
        parts[::2] = [_LONG_FLOAT.sub(_short_float, p) for p in parts[::2]]  # outside the quotes
        out.append('"'.join(parts))
    return "".join(out)


def snapshot_changed(text: str) -> bool:
    return tidy_config(text) != text


# ----------------------------------------------------------------------------- test conditions
def conditions_rows(d: ReportData) -> list[tuple[str, str]]:
    c = d.conditions
    if c is None:
        return [("conditions", "not recorded (the run's configuration could not be read)")]
    n_cyc = sum(p.n_before for p in d.iso_poses)
    rows = [
        ("identification", f"{c.identification_poses} poses (point and elbow), {c.repeats} visits each: "
                           f"{c.identification_measurements} measurements planned"
                           + ("; every pose approached from both sides" if c.both_directions else "")),
        ("verification", f"{c.verification_poses} held-out poses, {c.verification_cycles} ISO 9283 cycles each "
                         f"before and after correction ({n_cyc} valid before)"),
        ("elbows", ", ".join(f"{e:+d}" for e in c.elbows) or "—"),
        ("speed", f"{c.speed * 100:.0f} % of the robot's maximum"),
        ("settling before a reading", f"{c.settle_s:g} s; {c.samples} probe snapshots averaged"),
        ("load on the flange", (c.load or "the probe head") + (f"; {c.load_kg:g} kg" if c.load_kg is not None
                                                              else "; mass not recorded ([verification] load_kg)")),
        ("warm-up", c.warmup or "none configured ([warmup] enabled = false)"),
        ("air temperature", f"{c.temperature_c:.1f} °C ([verification] temperature_c)" if c.temperature_c is not None
         else "not recorded ([verification] temperature_c)"),
    ]
    return rows


def _mm(v: float) -> str:
    """A position [mm] to the µm the body's CMM report gives (never "-0.000")."""
    text = f"{v:.3f}"
    return "0.000" if text == "-0.000" else text


def pose_rows(d: ReportData) -> list[tuple[str, ...]]:
    return [(p.point, elbow_text(p.elbow), *(_mm(v) for v in p.target_mm),
             str(p.n_before), str(p.n_after) if d.errors_after_um.size else "—") for p in d.iso_poses]


# ----------------------------------------------------------------------------- ISO 9283 per pose
def _pose_result(d: ReportData, p: IsoPose) -> str:
    a = d.acceptance
    if a is None or (a.max_ap_um is None and a.max_rp_um is None) or not p.n_after:
        return "—"
    failed = []
    if a.max_ap_um is not None and (p.ap_after_um is None or p.ap_after_um > a.max_ap_um):
        failed.append("AP")
    if a.max_rp_um is not None and p.rp_after_um is not None and p.rp_after_um > a.max_rp_um:
        failed.append("RP")
    return f"{FAIL} ({', '.join(failed)})" if failed else PASS


def iso_rows(d: ReportData) -> list[tuple[str, ...]]:
    """Per held-out pose: AP and RP before and after correction [µm], and its result against
    the specification; the last row: the largest over the poses."""
    after = bool(d.errors_after_um.size)
    rows: list[tuple[str, ...]] = []
    for p in d.iso_poses:
        rows.append((p.point, elbow_text(p.elbow), f"{p.n_before}" + (f" / {p.n_after}" if after else ""),
                     fmt(p.ap_before_um), fmt(p.rp_before_um), fmt(p.ap_after_um) if after else "—",
                     fmt(p.rp_after_um) if after else "—", _pose_result(d, p)))
    if d.iso_poses:
        rows.append(("largest", "", "", fmt(_max(p.ap_before_um for p in d.iso_poses)),
                     fmt(_max(p.rp_before_um for p in d.iso_poses)),
                     fmt(_max(p.ap_after_um for p in d.iso_poses)) if after else "—",
                     fmt(_max(p.rp_after_um for p in d.iso_poses)) if after else "—", ""))
    return rows


def _max(values: Iterable[float | None]) -> float | None:
    vals = [v for v in values if v is not None and math.isfinite(v)]
    return max(vals) if vals else None


def _worst(d: ReportData, attr: str) -> tuple[float | None, IsoPose | None]:
    best: tuple[float | None, IsoPose | None] = (None, None)
    for p in d.iso_poses:
        v = getattr(p, attr)
        if v is not None and (best[0] is None or v > best[0]):
            best = (v, p)
    return best


# ----------------------------------------------------------------------------- acceptance
def acceptance_rows(d: ReportData) -> list[tuple[str, str, str, str]]:
    """(criterion, required, measured, result): the improvement ratio the outcome requires, and
    ``[verification]``'s AP and RP per pose after correction."""
    a = d.acceptance
    if a is None:
        return []
    s = d.summary
    gain = s.gain if s is not None else None
    rows = [("improvement ratio (RMS before / RMS after), the outcome's target", f"≥ {a.min_gain:g} ×",
             f"{fmt(gain)} ×" if gain is not None else "—",
             NOT_JUDGED if gain is None else (PASS if gain >= a.min_gain else FAIL))]
    after = bool(d.errors_after_um.size) and any(p.n_after for p in d.iso_poses)
    for label, limit, attr, key in (("AP after correction, every pose (ISO 9283)", a.max_ap_um, "ap_after_um", "max_ap_um"),
                                    ("RP after correction, every pose (ISO 9283)", a.max_rp_um, "rp_after_um", "max_rp_um")):
        worst, pose = _worst(d, attr)
        where = f" at {pose.point} elbow {pose.elbow:+d}" if pose is not None else ""
        measured = f"largest {fmt(worst)} µm{where}" if worst is not None else "—"
        if limit is None:
            rows.append((label, f"not specified ([verification] {key})", measured, NOT_JUDGED))
        elif not after:
            rows.append((label, f"≤ {limit:g} µm", "no measurements after correction", NOT_JUDGED))
        elif worst is None:
            rows.append((label, f"≤ {limit:g} µm", "RP needs two cycles per pose", NOT_JUDGED))
        else:
            judged = [p for p in d.iso_poses if getattr(p, attr) is not None]
            ok = sum(1 for p in judged if getattr(p, attr) <= limit)
            rows.append((label, f"≤ {limit:g} µm", f"{measured}; {ok} of {len(judged)} poses within",
                         PASS if ok == len(judged) else FAIL))
    return rows


def verdict(d: ReportData) -> str:
    """PASS when every judged criterion passes, FAIL when one fails, else "not judged"."""
    results = [r[3] for r in acceptance_rows(d)]
    if FAIL in results:
        return FAIL
    return PASS if PASS in results else NOT_JUDGED


#: the criteria's short names in the verdict, in acceptance_rows' order
_CRITERIA = ("gain", "AP", "RP")


def _why_not_judged(required: str, measured: str) -> str:
    if required.startswith("not specified"):
        return "no limit set"
    if measured in ("—", "no measurements after correction"):
        return "no measurements after correction"
    return measured


def verdict_text(d: ReportData) -> str:
    """The verdict and exactly what was judged: ``"PASS (gain); AP, RP not judged: no limit set"``,
    ``"FAIL (AP); passed: gain, RP"``; "not judged: …" when nothing was."""
    rows = acceptance_rows(d)
    if not rows:
        return f"{NOT_JUDGED}: no acceptance criteria (the run's configuration could not be read)"
    failed = [n for n, r in zip(_CRITERIA, rows) if r[3] == FAIL]
    passed = [n for n, r in zip(_CRITERIA, rows) if r[3] == PASS]
    why: dict[str, list[str]] = {}
    for n, r in zip(_CRITERIA, rows):
        if r[3] == NOT_JUDGED:
            why.setdefault(_why_not_judged(r[1], r[2]), []).append(n)
    parts = []
    if failed:
        parts.append(f"{FAIL} ({', '.join(failed)})" + (f"; passed: {', '.join(passed)}" if passed else ""))
    elif passed:
        parts.append(f"{PASS} ({', '.join(passed)})")
    parts += [f"{', '.join(names)} {NOT_JUDGED}: {reason}" for reason, names in why.items()]
    return "; ".join(parts) if (failed or passed) else f"{NOT_JUDGED}: " + "; ".join(
        f"{', '.join(names)}: {reason}" for reason, names in why.items())


# ----------------------------------------------------------------------------- ISO 9283's own test
#: what ISO 9283 (1998, §§ 6.3, 6.6, 6.8, 7.2) prescribes for the pose accuracy and repeatability test
ISO_CYCLES, ISO_POSES = 30, 5


def iso_departures(d: ReportData) -> list[str]:
    """How this run's AP/RP test departs from ISO 9283's (cycles, poses, load, speed), one
    sentence each; empty without test conditions."""
    c = d.conditions
    if c is None:
        return []
    out = []
    if c.verification_cycles != ISO_CYCLES:
        out.append(f"cycles: {c.verification_cycles} per pose, where ISO 9283 measures {ISO_CYCLES}; RP from "
                   f"{c.verification_cycles} cycles scatters more from pose to pose than the standard's figure")
    out.append(f"poses: {c.verification_poses} held-out poses at the calibration body's measuring points, not the "
               f"standard's {ISO_POSES} poses P1 … P5 on a diagonal plane of the test cube")
    load = f"{c.load_kg:g} kg" if c.load_kg is not None else "a mass not recorded ([verification] load_kg)"
    out.append(f"load: the probe head on the flange ({load}), not the robot's rated load that ISO 9283 tests at")
    if c.speed < 1.0:
        out.append(f"speed: {c.speed * 100:.0f} % of the robot's maximum, where ISO 9283 tests at the rated speed "
                   f"(100 %; 50 % and 10 % as options)")
    return out


ISO_DEPARTURE_NOTE = ("AP and RP are computed as ISO 9283 defines them, but the test is the calibration's own, "
                      "not the standard's pose test; it departs from it in:")

#: what a signature on a real run's report attests
SIGNATURE_ATTESTS = ("A signature attests that the signer has read this report; that the run was made as the test "
                     "conditions state, on the robot, probe head and body that the traceability block names; and "
                     "that the verdict was judged against the limits stated under Acceptance. It does not attest "
                     "what the report marks not judged or not recorded.")
#: a simulated run's sign-off, in place of the signature block
REHEARSAL = "rehearsal: not for sign-off"
REHEARSAL_TEXT = ("A simulated run: simulators stood in for the robot, the probe head and the body, so there is "
                  "nothing to sign. Use it to rehearse the procedure and to read the report; sign the report of "
                  "a run on the real cell.")


# ----------------------------------------------------------------------------- traceability
def _cert(cid: str, date: str) -> str:
    if not cid and not date:
        return ""
    return f"certificate {cid or '(no ID given)'}" + (f", measured {date}" if date else ", date not given")


def traceability_rows(d: ReportData) -> list[tuple[str, str]]:
    t = d.traceability
    if t is None:
        return [("traceability", "not recorded")]
    rows = [("robot", d.robot_name), ("robot serial number", t.robot_serial or "not recorded ([cell] robot_serial)"),
            ("controller", t.controller or "not recorded ([cell] controller)"),
            ("operator", f"{t.operator} ({t.operator_from})" if t.operator
             else "not recorded (--operator NAME, or [cell] operator)")]
    head_cert = _cert(t.head_certificate_id, t.head_certificate_date)
    rows.append(("probe head", f"'{t.head}', file {t.head_file}: " + (
        head_cert or "no CMM certificate in the file ([head] certificate_id, certificate_date)") if t.head_file
        else f"'{t.head}': the built-in reference head (no head file, no certificate)"))
    body_cert = _cert(t.body_certificate_id, t.body_certificate_date)
    rows.append(("calibration body", f"{t.body}, file {t.body_file}: " + (
        body_cert or "no CMM certificate in the file (# certificate_id: and # certificate_date: lines)")
        if t.body_file else f"{t.body} inline in the configuration (no body file, no certificate)"))
    rows += list(t.software)
    return rows


def signature_rows() -> list[tuple[str, str, str, str]]:
    return [(role, "", "", "") for role in SIGNATURE_ROLES]
