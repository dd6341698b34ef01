"""The Digital Calibration Certificate of a simulated calibration (issue 41): it validates
offline against the kept DCC and D-SI schemas, the same run gives the same bytes, the figures
are the report's, a damaged certificate fails validation and a bad issuer file is a typed error."""

from __future__ import annotations

import shutil
import sqlite3
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from station.cell.records.rundb import RunDB
from station.ui.cli.main import main
from station.ui.report.dcc import COVERAGE_FACTOR, DccInputError, DccInvalidError, read_issuer, run_hash, validate_dcc
from station.ui.report.run import report_data_for_run

NS = {"dcc": "https://ptb.de/dcc", "si": "https://ptb.de/si"}
ISSUER = """
[certificate]
robot_manufacturer = "Example Robotics"
performance_location = "customer"
approver = "B. Approver"

[laboratory]
name = "Example calibration laboratory"
email = "lab@example.org"
city = "Braunschweig"
country = "DE"

[customer]
name = "Example plant"
email = "qa@example.com"
city = "Stuttgart"
country = "DE"
"""


@pytest.fixture(scope="module")
def certified(tmp_path_factory, seed1_run):
    root = tmp_path_factory.mktemp("dcc")
    db = seed1_run.copy_to(root).db  # calibrate --simulated --seed 1 --report, run once for the suite
    issuer = root / "issuer.toml"
    issuer.write_text(ISSUER)
    out = root / "run1.xml"
    assert main(["export-dcc", "1", "--db", str(db), "--issuer", str(issuer), "-o", str(out)]) == 0
    return db, issuer, out


def _floats(el: ET.Element | None) -> np.ndarray:
    assert el is not None and el.text is not None
    return np.array([float(v) for v in el.text.split()])


@pytest.mark.slow  # an end-to-end session: the slow tier (README), run by CI
def test_certificate_validates_and_holds_the_reports_figures(certified):
    db, _, out = certified
    text = out.read_bytes()
    validate_dcc(text)  # offline, against the kept XSD files
    with RunDB(db) as rdb:
        data = report_data_for_run(rdb, 1)
        digest = run_hash(rdb, 1)
    root = ET.fromstring(text)
    ids = [e.text for e in root.iterfind(".//dcc:coreData/dcc:identifications/dcc:identification/dcc:value", NS)]
    assert digest in ids and len(digest) == 64
    lst = root.find(".//dcc:result/dcc:data/dcc:quantity/si:realListXMLList", NS)
    assert lst is not None
    labels = lst.findtext("si:labelXMLList", namespaces=NS).split()
    assert labels == list(data.param_names)
    np.testing.assert_array_equal(_floats(lst.find("si:valueXMLList", NS)), data.param_identified)
    units = lst.findtext("si:unitXMLList", namespaces=NS).split()
    assert units == ["\\radian" if a else "\\milli\\metre" for a in data.param_is_angle]
    U = _floats(lst.find("si:expandedUncXMLList/si:uncertaintyXMLList", NS))
    np.testing.assert_allclose(U, COVERAGE_FACTOR * data.param_sigma, rtol=1e-15)
    cols = lst.findall("si:ellipsoidalRegionXMLList/si:covarianceMatrix/si:column", NS)
    cov = np.array([[float(c.findtext("si:value", namespaces=NS)) for c in col.findall("si:covariance", NS)]
                    for col in cols])
    p = len(labels)
    assert cov.shape == (p, p)
    np.testing.assert_allclose(cov, cov.T, rtol=0, atol=0)
    np.testing.assert_allclose(np.sqrt(np.diag(cov)), data.param_sigma, rtol=1e-12)
    assert np.all(np.linalg.eigvalsh(cov) > -1e-18)
    ap_after = [q for q in root.iterfind(".//dcc:quantity", NS)
                if q.findtext("dcc:name/dcc:content", namespaces=NS) == "AP (after correction)"]
    assert len(ap_after) == 1
    vals = _floats(ap_after[0].find("si:realListXMLList/si:valueXMLList", NS))
    assert np.allclose(sorted(vals), sorted(p.ap_after_um for p in data.iso_poses if p.ap_after_um is not None))
    names = [e.findtext("dcc:person/dcc:name/dcc:content", namespaces=NS) for e in root.iterfind(".//dcc:respPerson", NS)]
    assert "B. Approver" in names


def test_same_run_same_bytes(certified, tmp_path):
    db, issuer, out = certified
    again = tmp_path / "again.xml"
    assert main(["export-dcc", "1", "--db", str(db), "--issuer", str(issuer), "-o", str(again)]) == 0
    assert again.read_bytes() == out.read_bytes()


def test_a_changed_measurement_changes_the_hash(certified, tmp_path):
    db, _, _ = certified
    copy = tmp_path / "copy.sqlite"
    shutil.copy(db, copy)
    with RunDB(copy) as rdb:
        before = run_hash(rdb, 1)
    with sqlite3.connect(copy) as conn:
        conn.execute("UPDATE measurements SET message = message || ' edited' WHERE rowid = "
                     "(SELECT MIN(rowid) FROM measurements)")
    with RunDB(copy) as rdb:
        assert run_hash(rdb, 1) != before


@pytest.mark.parametrize("damage", ["value", "element", "country", "truncated"])
def test_a_damaged_certificate_fails_validation(certified, damage):
    _, _, out = certified
    text = out.read_text(encoding="utf-8")
    if damage == "value":  # a number that is no number
        i = text.index("<si:valueXMLList>") + len("<si:valueXMLList>")
        text = text[:i] + "twelve " + text[i:]
    elif damage == "element":  # a required element gone
        i, j = text.index("<dcc:uniqueIdentifier>"), text.index("</dcc:uniqueIdentifier>")
        text = text[:i] + text[j + len("</dcc:uniqueIdentifier>"):]
    elif damage == "country":  # a country code the schema refuses
        text = text.replace("<dcc:countryCodeISO3166_1>DE<", "<dcc:countryCodeISO3166_1>Germany<", 1)
    else:
        text = text[: len(text) // 2]
    with pytest.raises(DccInvalidError):
        validate_dcc(text.encode())


@pytest.mark.parametrize("edit, words", [
    (lambda t: t.replace('country = "DE"', 'country = "Germany"', 1), "ISO 3166-1"),
    (lambda t: t.replace('performance_location = "customer"', 'performance_location = "garage"'), "performance_location"),
    (lambda t: t.replace('email = "lab@example.org"', ""), "[laboratory] email"),
    (lambda t: t.replace("[customer]", "[client]"), "[customer]"),
    (lambda t: t + "\n[[", "not a TOML file"),
])
def test_a_bad_issuer_file_is_a_typed_error(tmp_path, edit, words):
    f = tmp_path / "issuer.toml"
    f.write_text(edit(ISSUER))
    with pytest.raises(DccInputError) as exc:
        read_issuer(f)
    assert words in str(exc.value) and exc.value.hint
