"""The run summary (station.cell.records.summary): statistics, JSON round trip, figures."""

from __future__ import annotations

import json

import numpy as np
import pytest

from station.cell.records.summary import (
    CorrectionSummary,
    ErrorStats,
    Failure,
    IdentificationSummary,
    ParameterEstimate,
    RunSummary,
    UploadSummary,
)
from station.errors import Outcome


def test_error_stats_iso9283_per_pose():
    errs = {("C1.a", 1): np.array([[0.010, 0, 0], [0.012, 0, 0], [0.011, 0, 0]]),
            ("C2.b", -1): np.array([[0, 0.020, 0], [0, 0.020, 0], [0, 0.020, 0]])}
    st = ErrorStats.from_errors(errs)
    assert st.n == 6
    assert st.ap_max_um == pytest.approx(20.0)  # the second pose's barycentre is 20 µm off
    assert st.max_um == pytest.approx(20.0)
    assert st.rp_max_um > 0 and st.rp_max_um < 5.0
    assert ErrorStats.from_errors({}) is None


def test_one_verification_cycle_gives_ap_without_rp():
    st = ErrorStats.from_errors({("C1.a", 1): np.array([[0.003, 0.004, 0.0]])})
    assert st.ap_max_um == pytest.approx(5.0) and st.rp_max_um is None
    assert json.loads(json.dumps(RunSummary(Outcome.SUCCESS, before=st).to_json()))["before"]["rp_max_um"] is None


def test_json_round_trip_and_derived_figures():
    s = RunSummary(
        outcome=Outcome.TARGET_MISSED, run_id=3, cell="c", robot="r",
        identification=IdentificationSummary("pose", 60, 2, 1.1, 8.0, (4,), (ParameterEstimate("A2.x", 445.0, 0.002),)),
        correction=CorrectionSummary(100, 3.5, "0000abcd"),
        before=ErrorStats(6, 100.0, 150.0, 120.0, 9.0, (1.0,) * 6),
        after=ErrorStats(6, 10.0, 15.0, 12.0, 9.0), oracle=ErrorStats(6, 8.0, 12.0, 10.0, 9.0),
        upload=UploadSummary("0000abcd", 0.25))
    d = json.loads(json.dumps(s.to_json()))  # plain JSON types only
    assert d["outcome"] == "TARGET_MISSED" and d["exit_code"] == 10
    assert d["gain"] == pytest.approx(10.0) and d["after_vs_oracle"] == pytest.approx(1.25)
    assert RunSummary.from_json(d) == s
    labels = [f[0] for f in s.figures()]
    assert labels[:3] == ["RMS before", "RMS after", "improvement ratio"]


def test_failure_summary_has_no_figures():
    s = RunSummary(Outcome.DEVICE_FAULT, failure=Failure("ProbeTimeout", "no reply", "check the cable"))
    assert s.exit_code == 7 and s.gain is None and s.figures() == []
    assert RunSummary.from_json(s.to_json()) == s
    with pytest.raises(AttributeError):
        s.run_id = 4  # frozen
