"""ISO 9283 AP and RP in the certificate carry their expanded uncertainty (issue 41): each figure's
U = k·u with the u the report data computed from the run's cycles, the coverage stated, the
method named in the result's description, and the certificate still valid."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np

from station.cell.records.rundb import RunDB
from station.ui.report.dcc import COVERAGE_FACTOR, validate_dcc
from station.ui.report.run import report_data_for_run
from tests.ui.test_export_dcc import NS, _floats, certified  # noqa: F401 - the module's run, its fixture

SERIES = {("AP", "before correction"): "ap_before_um", ("RP", "before correction"): "rp_before_um",
          ("AP", "after correction"): "ap_after_um", ("RP", "after correction"): "rp_after_um"}


def test_ap_and_rp_carry_their_expanded_uncertainty(certified):  # noqa: F811
    db, _, out = certified
    text = out.read_bytes()
    validate_dcc(text)
    with RunDB(db) as rdb:
        poses = report_data_for_run(rdb, 1).iso_poses
    root = ET.fromstring(text)
    iso = [r for r in root.iterfind(".//dcc:result", NS)
           if r.findtext("dcc:name/dcc:content", namespaces=NS, default="").startswith("ISO 9283")]
    assert len(iso) == 1
    assert "Monte Carlo" in iso[0].findtext("dcc:description/dcc:content", namespaces=NS, default="")
    seen = set()
    for q in iso[0].iterfind(".//dcc:quantity", NS):
        name = q.findtext("dcc:name/dcc:content", namespaces=NS, default="")
        what, status = name.split(" (", 1)
        attr = SERIES[(what, status.rstrip(")"))]
        seen.add(attr)
        lst = q.find("si:realListXMLList", NS)
        assert lst is not None
        have = [p for p in poses if getattr(p, attr) is not None]
        U = _floats(lst.find("si:expandedUncXMLList/si:uncertaintyXMLList", NS))
        u = np.array([getattr(p, f"u_{attr}") for p in have], dtype=float)
        np.testing.assert_allclose(U, COVERAGE_FACTOR * u, rtol=1e-15)
        assert np.all(U > 0)
        assert lst.findtext("si:expandedUncXMLList/si:coverageFactorXMLList", namespaces=NS) == "2.0"
        assert lst.findtext("si:expandedUncXMLList/si:coverageProbabilityXMLList", namespaces=NS) == "0.9545"
    assert seen == set(SERIES.values())
    # several cycles: the barycentre's u (the scatter over √n) is below the scatter RP describes
    multi = [p for p in poses if p.n_after >= 2]
    assert multi and all(0 < p.u_ap_after_um < p.rp_after_um for p in multi)
