"""A finished calibration as a PTB Digital Calibration Certificate (DCC, XML with D-SI units).

The certificate is built from the same :class:`~station.ui.report.contents.ReportData` the
report shows (nothing is recomputed differently for it) plus the *issuer file*, a small TOML
file of what no cell file states: the laboratory, the customer, the robot's manufacturer, the
country and the approver (``docs/exports.md``). Its rings (DCC documentation, "administrative
data" and "measurement results"):

* administrativeData: the station and its libraries (dccSoftware), the run's document ID as the
  unique identifier and the SHA-256 of the run's record (:func:`run_hash`) as an
  identification, the robot (serial, controller), the laboratory and customer from the issuer
  file, the operator and the approver as responsible persons, the verdict as a conformity
  statement;
* measurementResults: the method (the chapter's six-parameter transforms, least squares on the
  pose closure, ISO 9283), the probe head and the body with their CMM certificates, the test
  conditions, and the results: the identified parameters in ``si:realListXMLList`` with their
  expanded uncertainty (k = 2, p = 0.9545, normal) and their covariance as an
  ``si:ellipsoidalRegionXMLList``; the nominal values; ISO 9283 AP and RP per held-out pose
  before and after correction.

Units (D-SI, BIPM SI brochure 9th ed. as D-SI 2.1.0 writes them): lengths ``\\milli\\metre``
(the station's own, so that no number is converted), angles ``\\radian``, AP and RP
``\\micro\\metre``. Output is deterministic: elements in a fixed order, floats written with
``repr`` (shortest round-trip), no time of export: the same run and issuer file give the same
bytes.

Schema: the XSD files kept in ``dcc_schema/`` (with their LGPL v3 licence) are checked offline
with xmlschema, which reads nothing from the network here (``allow="local"``: local files only).
"""

from __future__ import annotations

import hashlib
import json
import math
import tomllib
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from station.cell.records.rundb import RunDB
from station.errors import ConfigError
from station.ui.report.contents import IsoPose, ReportData
from station.ui.report.signoff import FAIL, PASS, verdict, verdict_text

__all__ = ["SCHEMA_VERSION", "COVERAGE_FACTOR", "COVERAGE_PROBABILITY", "Issuer", "read_issuer", "run_hash",
           "dcc_xml", "validate_dcc", "DccInvalidError"]

DCC_NS = "https://ptb.de/dcc"
SI_NS = "https://ptb.de/si"
XSI_NS = "http://www.w3.org/2001/XMLSchema-instance"
#: the DCC schema the certificate is written for and validated against: the newest release whose
#: XSD could be obtained for offline validation (3.3.0's could not: docs/exports.md)
SCHEMA_VERSION = "3.1.2"
SCHEMA_DIR = Path(__file__).resolve().parent / "dcc_schema"
#: GUM (JCGM 100:2008) §6.2-6.3: U = k·u with k = 2 for a normal distribution, p ≈ 95.45 %
COVERAGE_FACTOR = 2.0
COVERAGE_PROBABILITY = 0.9545
MM, RAD, UM_UNIT = "\\milli\\metre", "\\radian", "\\micro\\metre"
_LOCATIONS = ("laboratory", "customer", "laboratoryBranch", "customerBranch", "other")

ET.register_namespace("dcc", DCC_NS)
ET.register_namespace("si", SI_NS)
ET.register_namespace("xsi", XSI_NS)


class DccInputError(ConfigError):
    """What the certificate needs is missing or malformed; ``hint`` says what to write."""

    def __init__(self, message: str, hint: str):
        super().__init__(message)
        self.hint = hint


class DccInvalidError(DccInputError):
    """A certificate that does not validate against the kept schema (a station bug, or a damaged file)."""


@dataclass(frozen=True)
class Contact:
    name: str
    email: str
    city: str
    country: str  # ISO 3166-1 alpha-2


@dataclass(frozen=True)
class Issuer:
    """What the certificate states that no cell file holds (the issuer file, ``--issuer``)."""

    laboratory: Contact
    customer: Contact
    robot_manufacturer: str
    performance_location: str  # DCC's enumeration: laboratory, customer, ...
    approver: str = ""


def _text(table: dict[str, Any], key: str, where: str, path: Path) -> str:
    v = table.get(key)
    if not isinstance(v, str) or not v.strip():
        raise DccInputError(f"{path}: [{where}] {key} is missing or empty",
                            f"write {key} = \"...\" under [{where}] (docs/exports.md shows an issuer file)")
    return v.strip()


def _contact(data: dict[str, Any], section: str, path: Path) -> Contact:
    t = data.get(section)
    if not isinstance(t, dict):
        raise DccInputError(f"{path}: no [{section}] section", "docs/exports.md shows an issuer file")
    country = _text(t, "country", section, path)
    if len(country) != 2 or not country.isascii() or not country.isupper():
        raise DccInputError(f"{path}: [{section}] country {country!r} is not an ISO 3166-1 alpha-2 code",
                            "two capital letters, e.g. \"DE\"")
    return Contact(_text(t, "name", section, path), _text(t, "email", section, path), _text(t, "city", section, path),
                   country)


def read_issuer(path: str | Path) -> Issuer:
    """The issuer file; :class:`ConfigError` naming the key for anything missing or malformed."""
    p = Path(path)
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except OSError as exc:
        raise DccInputError(f"cannot read the issuer file {p}: {exc.strerror or exc}",
                            "give the file with --issuer (docs/exports.md)") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise DccInputError(f"{p}: not a TOML file ({exc})", "docs/exports.md shows an issuer file") from None
    cert = data.get("certificate", {})
    if not isinstance(cert, dict):
        raise DccInputError(f"{p}: [certificate] must be a table", "docs/exports.md shows an issuer file")
    where = _text(cert, "performance_location", "certificate", p)
    if where not in _LOCATIONS:
        raise DccInputError(f"{p}: [certificate] performance_location {where!r} is not one of the DCC's",
                            f"use one of {', '.join(_LOCATIONS)}")
    approver = cert.get("approver", "")
    if not isinstance(approver, str):
        raise DccInputError(f"{p}: [certificate] approver must be a string", "approver = \"A. Name\"")
    return Issuer(_contact(data, "laboratory", p), _contact(data, "customer", p),
                  _text(cert, "robot_manufacturer", "certificate", p), where, approver.strip())


# ------------------------------------------------------------------------------------- the run's hash
def _array(a: Any) -> Any:
    return None if a is None else [repr(float(v)) for v in np.asarray(a, dtype=float).reshape(-1)]


def run_hash(db: RunDB, run_id: int) -> str:
    """SHA-256 (hex) of the run's record: its configuration snapshot, plan, creation, station
    version and every measurement as stored (joints, raw probe frames, readings, poses, status).
    A changed measurement, configuration or plan changes it; a rebuilt certificate keeps it."""
    run = db.run(run_id)
    h = hashlib.sha256()
    head = {"run": run.id, "created_utc": run.created_utc, "station_version": run.station_version,
            "config_toml": run.config_toml, "plan": run.plan, "seed": run.seed}
    h.update(json.dumps(head, sort_keys=True, default=str).encode())
    for m in db.measurements(run_id):
        rec = {"step": m.step_index, "kind": m.kind, "point": m.point_id, "label": m.label,
               "q_cmd": _array(m.joints_commanded), "q_read": _array(m.joints_read), "raw": m.raw_frames.hex(),
               "readings": _array(m.readings_mm), "status": m.channel_status, "pose": _array(m.pose),
               "residual": m.pose_residual_um, "ok": m.ok, "message": m.message, "t": m.t_utc}
        h.update(json.dumps(rec, sort_keys=True, default=str).encode())
    return h.hexdigest()


# ------------------------------------------------------------------------------------ XML helpers
def _d(tag: str) -> str:
    return f"{{{DCC_NS}}}{tag}"


def _s(tag: str) -> str:
    return f"{{{SI_NS}}}{tag}"


def _sub(parent: ET.Element, tag: str, text: str | None = None) -> ET.Element:
    e = ET.SubElement(parent, tag)
    if text is not None:
        e.text = text
    return e


def _texts(parent: ET.Element, tag: str, text: str) -> ET.Element:
    """A dcc:textType element (one English content)."""
    e = _sub(parent, _d(tag))
    _sub(e, _d("content"), text).set("lang", "en")
    return e


def _num(v: float) -> str:
    if not math.isfinite(v):
        raise DccInputError(f"a certificate value is not finite ({v})", "the run's figures are damaged")
    return repr(float(v))


def _real(parent: ET.Element, label: str, value: float, unit: str) -> ET.Element:
    r = _sub(parent, _s("real"))
    _sub(r, _s("label"), label)
    _sub(r, _s("value"), _num(value))
    _sub(r, _s("unit"), unit)
    return r


def _quantity(data: ET.Element, name: str, label: str, value: float, unit: str) -> None:
    q = _sub(data, _d("quantity"))
    _texts(q, "name", name)
    _real(q, label, value, unit)


def _date(stamp: str) -> str:
    return stamp[:10]


# ------------------------------------------------------------------------------ administrative data
def _contact_el(parent: ET.Element, tag: str, c: Contact) -> None:
    e = _sub(parent, _d(tag))
    _texts(e, "name", c.name)
    _sub(e, _d("eMail"), c.email)
    loc = _sub(e, _d("location"))
    _sub(loc, _d("city"), c.city)
    _sub(loc, _d("countryCode"), c.country)


def _identification(parent: ET.Element, issuer: str, value: str, name: str) -> None:
    i = _sub(parent, _d("identification"))
    _sub(i, _d("issuer"), issuer)
    _sub(i, _d("value"), value)
    _texts(i, "name", name)


def _person(parent: ET.Element, name: str, role: str, main: bool) -> None:
    r = _sub(parent, _d("respPerson"))
    p = _sub(r, _d("person"))
    _texts(p, "name", name)
    _sub(r, _d("role"), role)
    _sub(r, _d("mainSigner"), "true" if main else "false")


def _administrative(root: ET.Element, d: ReportData, issuer: Issuer, digest: str, end: str) -> None:
    adm = _sub(root, _d("administrativeData"))
    sw = _sub(adm, _d("dccSoftware"))
    for name, release in (d.traceability.software if d.traceability else ()):
        s = _sub(sw, _d("software"))
        _texts(s, "name", name)
        _sub(s, _d("release"), release)
    core = _sub(adm, _d("coreData"))
    _sub(core, _d("countryCodeISO3166_1"), issuer.laboratory.country)
    _sub(core, _d("usedLangCodeISO639_1"), "en")
    _sub(core, _d("mandatoryLangCodeISO639_1"), "en")
    _sub(core, _d("uniqueIdentifier"), d.document_id)
    ids = _sub(core, _d("identifications"))
    _identification(ids, "calibrationLaboratory", digest, "SHA-256 of the run's record (station run database)")
    _identification(ids, "calibrationLaboratory", str(d.run_id), "run number in the station's run database")
    _sub(core, _d("beginPerformanceDate"), _date(d.created))
    _sub(core, _d("endPerformanceDate"), _date(end or d.created))
    _sub(core, _d("performanceLocation"), issuer.performance_location)
    _items(adm, d, issuer)
    lab = _sub(adm, _d("calibrationLaboratory"))
    _contact_el(lab, "contact", issuer.laboratory)
    persons = _sub(adm, _d("respPersons"))
    t = d.traceability
    if t is not None and t.operator:
        _person(persons, t.operator, "operator", not issuer.approver)
    if issuer.approver:
        _person(persons, issuer.approver, "approver", True)
    _contact_el(adm, "customer", issuer.customer)
    _statements(adm, d)


def _items(adm: ET.Element, d: ReportData, issuer: Issuer) -> None:
    items = _sub(adm, _d("items"))
    item = _sub(items, _d("item"))
    _texts(item, "name", f"industrial robot {d.robot_name}")
    man = _sub(item, _d("manufacturer"))
    _texts(man, "name", issuer.robot_manufacturer)
    _sub(item, _d("model"), d.robot_name)
    ids = _sub(item, _d("identifications"))
    t = d.traceability
    _identification(ids, "manufacturer", t.robot_serial if t and t.robot_serial else "not recorded",
                    "robot serial number ([cell] robot_serial)")
    if t is not None and t.controller:
        _identification(ids, "manufacturer", t.controller, "controller ([cell] controller)")


def _statements(adm: ET.Element, d: ReportData) -> None:
    st = _sub(adm, _d("statements"))
    s = _sub(st, _d("statement"))
    _sub(s, _d("norm"), "ISO 9283:1998")
    decl = _sub(s, _d("declaration"))
    _sub(decl, _d("content"), f"verification's verdict: {verdict_text(d)}").set("lang", "en")
    v = verdict(d)
    if v in (PASS, FAIL):
        _sub(s, _d("conformity"), "pass" if v == PASS else "fail")
    if d.simulated:
        s2 = _sub(st, _d("statement"))
        decl = _sub(s2, _d("declaration"))
        _sub(decl, _d("content"), "SIMULATED RUN: the figures come from the station's simulated cell, "
             "not from a robot").set("lang", "en")


# ------------------------------------------------------------------------------ measurement results
_METHODS = (
    ("kinematic model", "Each transform (set-up R, joints A1..Ag, head K) is Trans(x,y,z)·Rz(yaw)·Ry(pitch)·Rx(roll), "
     "a revolute joint adding to the rotation about its local z, a prismatic one to the translation along it; the "
     "identifiable minimal set (4R + 2P + 6 parameters) chosen from the identification Jacobian's singular values "
     "(docs/method.md; the dissertation chapter's eq. 7.1, sections 2.4 and 3.3)."),
    ("objective", "Weighted least squares on the pose closure Pose(K·T(S)·R·I) = measured pose of each "
     "identification measurement; the parameters' covariance from the Jacobian at the solution (docs/method.md)."),
    ("verification", "Pose accuracy AP and pose repeatability RP (ISO 9283:1998, 7.2 and 7.2.2) at poses held out "
     "of the identification, measured before and after the correction was applied."),
)


def _methods(mr: ET.Element, d: ReportData) -> None:
    um = _sub(mr, _d("usedMethods"))
    for name, text in _METHODS:
        m = _sub(um, _d("usedMethod"))
        _texts(m, "name", name)
        desc = _sub(m, _d("description"))
        _sub(desc, _d("content"), text).set("lang", "en")
        if name == "verification":
            _sub(m, _d("norm"), "ISO 9283:1998")
    c = d.conditions
    if c is not None:
        m = _sub(um, _d("usedMethod"))
        _texts(m, "name", "poses")
        desc = _sub(m, _d("description"))
        _sub(desc, _d("content"), f"{c.identification_poses} identification poses ({c.identification_measurements} "
             f"measurements, {c.repeats} visit(s) each); {c.verification_poses} verification poses of "
             f"{c.verification_cycles} cycles").set("lang", "en")


def _equipment(mr: ET.Element, d: ReportData) -> None:
    t = d.traceability
    if t is None:
        return
    me = _sub(mr, _d("measuringEquipments"))
    for name, file, cid, cdate in ((f"probe head {t.head}", t.head_file, t.head_certificate_id, t.head_certificate_date),
                                   (f"calibration body ({t.body})", t.body_file, t.body_certificate_id,
                                    t.body_certificate_date)):
        e = _sub(me, _d("measuringEquipment"))
        _texts(e, "name", name)
        desc = _sub(e, _d("description"))
        cert = f"CMM certificate {cid}" + (f" of {cdate}" if cdate else "") if cid else "no CMM certificate recorded"
        _sub(desc, _d("content"), f"{cert}; file: {file or 'built in'}").set("lang", "en")
        if cid:
            ids = _sub(e, _d("identifications"))
            _identification(ids, "other", cid, "CMM certificate" + (f" of {cdate}" if cdate else ""))


def _conditions(mr: ET.Element, d: ReportData) -> None:
    c = d.conditions
    if c is None:
        return
    ic = _sub(mr, _d("influenceConditions"))
    rows: list[tuple[str, str, float, str]] = [
        ("speed", "fraction of the robot's maximum speed", c.speed, "\\one"),
        ("settling time", "settle", c.settle_s, "\\second"),
        ("probe samples", "samples averaged per reading", float(c.samples), "\\one")]
    if c.load_kg is not None:
        rows.append(("load", c.load or "load on the flange", c.load_kg, "\\kilogram"))
    if c.temperature_c is not None:
        rows.append(("temperature", "air temperature", c.temperature_c, "\\degreecelsius"))
    for name, label, value, unit in rows:
        cond = _sub(ic, _d("influenceCondition"))
        _texts(cond, "name", name)
        _quantity(_sub(cond, _d("data")), name, label.replace(" ", "_"), value, unit)


def _label(name: str) -> str:
    return name.replace(" ", "_")  # an XML list is split at blanks


def covariance(d: ReportData) -> np.ndarray:
    """(p, p) covariance [mm², mm·rad, rad²] of the identified parameters, from the report's σ and
    correlation (the identification's covariance scaled to unit diagonal: exact up to round-off)."""
    s = d.param_sigma
    corr = d.param_correlation if d.param_correlation is not None else np.eye(s.size)
    cov = corr * np.outer(s, s)
    return (cov + cov.T) / 2  # symmetric to the last bit: the stored correlation is, to round-off


def _parameters(results: ET.Element, d: ReportData) -> None:
    units = [RAD if a else MM for a in d.param_is_angle]
    sigma = d.param_sigma
    if not np.all(np.isfinite(sigma)):
        raise DccInputError("the run's identification has parameters without a standard uncertainty",
                            "a certificate needs every identified parameter's uncertainty; rebuild the report "
                            "(station report) to see which")
    res = _sub(results, _d("result"))
    _texts(res, "name", "identified kinematic parameters")
    desc = _sub(res, _d("description"))
    _sub(desc, _d("content"), "R.* set-up (robot base in the calibration body's frame), K.* probe head, the others "
         "the robot's joint transforms; expanded uncertainty U = k·u (GUM 6.2), covariance of the estimates "
         "(standard uncertainties) in the ellipsoidal region").set("lang", "en")
    q = _sub(_sub(res, _d("data")), _d("quantity"))
    _texts(q, "name", "identified parameters")
    lst = _sub(q, _s("realListXMLList"))
    _sub(lst, _s("labelXMLList"), " ".join(_label(n) for n in d.param_names))
    _sub(lst, _s("valueXMLList"), " ".join(_num(v) for v in d.param_identified))
    _sub(lst, _s("unitXMLList"), " ".join(units))
    unc = _sub(lst, _s("expandedUncXMLList"))
    _sub(unc, _s("uncertaintyXMLList"), " ".join(_num(COVERAGE_FACTOR * v) for v in sigma))
    _sub(unc, _s("coverageFactorXMLList"), _num(COVERAGE_FACTOR))
    _sub(unc, _s("coverageProbabilityXMLList"), str(COVERAGE_PROBABILITY))
    _sub(unc, _s("distributionXMLList"), "normal")
    region = _sub(lst, _s("ellipsoidalRegionXMLList"))
    cm = _sub(region, _s("covarianceMatrix"))
    cov = covariance(d)
    for j in range(cov.shape[1]):
        col = _sub(cm, _s("column"))
        for i in range(cov.shape[0]):
            c = _sub(col, _s("covariance"))
            _sub(c, _s("value"), _num(cov[i, j]))
            _sub(c, _s("unit"), _product_unit(units[i], units[j]))
    _sub(region, _s("coverageFactor"), _num(COVERAGE_FACTOR))
    _sub(region, _s("coverageProbability"), str(COVERAGE_PROBABILITY))
    _sub(region, _s("distribution"), "normal")
    nom = _sub(results, _d("result"))
    _texts(nom, "name", "nominal kinematic parameters (the robot file)")
    lst = _sub(_sub(_sub(nom, _d("data")), _d("quantity")), _s("realListXMLList"))
    _sub(lst, _s("labelXMLList"), " ".join(_label(n) for n in d.param_names))
    _sub(lst, _s("valueXMLList"), " ".join(_num(v) for v in d.param_nominal))
    _sub(lst, _s("unitXMLList"), " ".join(units))


def _product_unit(a: str, b: str) -> str:
    if a == b:
        return f"{a}\\tothe{{2}}"
    return f"{MM}{RAD}"


def _iso_list(data: ET.Element, name: str, poses: Sequence[IsoPose], attr: str, status: str) -> None:
    have = [p for p in poses if getattr(p, attr) is not None]
    if not have:
        return
    q = _sub(data, _d("quantity"))
    _texts(q, "name", f"{name} ({status})")
    lst = _sub(q, _s("realListXMLList"))
    _sub(lst, _s("labelXMLList"), " ".join(_label(f"{p.point}_elbow{p.elbow:+d}") for p in have))
    _sub(lst, _s("valueXMLList"), " ".join(_num(getattr(p, attr)) for p in have))
    _sub(lst, _s("unitXMLList"), " ".join(UM_UNIT for _ in have))
    u = [getattr(p, f"u_{attr}") for p in have]
    if all(v is not None for v in u):  # every figure has one (AP: always; RP: with its two cycles)
        unc = _sub(lst, _s("expandedUncXMLList"))
        _sub(unc, _s("uncertaintyXMLList"), " ".join(_num(COVERAGE_FACTOR * v) for v in u))
        _sub(unc, _s("coverageFactorXMLList"), _num(COVERAGE_FACTOR))
        _sub(unc, _s("coverageProbabilityXMLList"), str(COVERAGE_PROBABILITY))
        _sub(unc, _s("distributionXMLList"), "normal")


def _iso(results: ET.Element, d: ReportData) -> None:
    if not d.iso_poses:
        return
    res = _sub(results, _d("result"))
    _texts(res, "name", "ISO 9283 pose accuracy and repeatability at the held-out poses")
    desc = _sub(res, _d("description"))
    _sub(desc, _d("content"), "AP and RP per pose (ISO 9283:1998, 7.2.1 and 7.2.2) before and after the correction; "
         "RP needs two cycles of a pose. Expanded uncertainty U = k·u (GUM 6.2), u by first-order propagation "
         "(GUM 5.1.2) per pose: for AP the barycentre's u per axis from the cycles' scatter (Type A, s/√n; with one "
         "cycle the configured σ of one reading) and the body point's CMM σ (Type B, shared by every cycle); for RP "
         "by Monte Carlo (JCGM 101:2008): the spread of RP over 2000 seeded sets of n cycles drawn from the normal "
         "distribution with the pose's own sample covariance (larger than the true spread with few cycles). With "
         "few cycles the degrees of freedom are few and the coverage probability is approximate (GUM G.4); "
         "ISO 9283 asks for 30 cycles").set("lang", "en")
    data = _sub(res, _d("data"))
    for attr, name, status in (("ap_before_um", "AP", "before correction"), ("rp_before_um", "RP", "before correction"),
                               ("ap_after_um", "AP", "after correction"), ("rp_after_um", "RP", "after correction")):
        _iso_list(data, name, d.iso_poses, attr, status)
    if not len(data):
        _sub(_sub(data, _d("text")), _d("content"), "no pose was measured in full").set("lang", "en")
    _sub(_sub(data, _d("text")), _d("content"), f"verdict: {verdict_text(d)}").set("lang", "en")


def _measurement_results(root: ET.Element, d: ReportData) -> None:
    mr = _sub(_sub(root, _d("measurementResults")), _d("measurementResult"))
    _texts(mr, "name", f"kinematic calibration of {d.robot_name}")
    _methods(mr, d)
    _equipment(mr, d)
    _conditions(mr, d)
    results = _sub(mr, _d("results"))
    _parameters(results, d)
    _iso(results, d)


def dcc_xml(d: ReportData, issuer: Issuer, digest: str, end: str = "") -> bytes:
    """The certificate of the run ``d`` (a finished calibration's report data), ``digest`` its
    :func:`run_hash`, ``end`` the time of its last measurement ("" : its creation). UTF-8 bytes,
    validated against the kept schema (:class:`DccInvalidError` if not)."""
    if not d.param_names:
        raise DccInputError(f"run {d.run_id} identified nothing: there is no calibration to certify",
                            "finish the run first (station resume), then export its certificate")
    root = ET.Element(_d("digitalCalibrationCertificate"))
    root.set("schemaVersion", SCHEMA_VERSION)
    root.set(f"{{{XSI_NS}}}schemaLocation", f"{DCC_NS} https://ptb.de/dcc/v{SCHEMA_VERSION}/dcc.xsd")
    _administrative(root, d, issuer, digest, end)
    _measurement_results(root, d)
    ET.indent(root, space=" ")
    text = ET.tostring(root, encoding="utf-8", xml_declaration=True) + b"\n"
    validate_dcc(text)
    return text


_SCHEMA: Any = None


def _schema() -> Any:
    global _SCHEMA
    if _SCHEMA is None:
        import xmlschema

        # the D-SI import names its URL: mapped to the kept file, and "local" forbids any remote
        # read, so validation never touches the network
        _SCHEMA = xmlschema.XMLSchema(str(SCHEMA_DIR / "dcc.xsd"), allow="local",
                                      locations={SI_NS: str(SCHEMA_DIR / "SI_Format.xsd")})
    return _SCHEMA


def validate_dcc(text: bytes | str) -> None:
    """:class:`DccInvalidError` naming the first reason when ``text`` is no valid DCC."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise DccInvalidError(f"the certificate is not well-formed XML: {exc}", "the file is damaged") from None
    errors = list(_schema().iter_errors(root))
    if errors:
        first = errors[0]
        raise DccInvalidError(f"the certificate does not validate against DCC {SCHEMA_VERSION} ({len(errors)} "
                              f"error(s)): {first.reason} at {first.path}",
                              "the file is damaged, or this is a station bug: please report it")


def dcc_for_run(db: RunDB, run_id: int, issuer: Issuer, operator: str | None = None) -> bytes:
    """The certificate of run ``run_id`` (see :func:`dcc_xml`)."""
    from station.ui.report.run import report_data_for_run

    data = report_data_for_run(db, run_id, operator=operator)
    if data.progress:
        raise DccInputError(f"run {run_id} did not finish ({data.progress}): a certificate is for a finished "
                            f"calibration", "finish the run first (station resume), then export its certificate")
    stamps = [m.t_utc for m in db.measurements(run_id) if m.t_utc]
    return dcc_xml(data, issuer, run_hash(db, run_id), max(stamps) if stamps else "")
