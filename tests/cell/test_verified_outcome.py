"""A verified run meets the gain target and [verification]'s accuracy specification, or misses."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from station.cell.config.sections import VerificationConfig
from station.cell.pipeline.results import verified_outcome
from station.cell.records.summary import ErrorStats, RunSummary
from station.errors import Outcome


def _summary(after_ap: float, after_rp: float | None) -> RunSummary:
    before = ErrorStats(n=20, rms_um=600.0, max_um=900.0, ap_max_um=850.0, rp_max_um=20.0)
    after = ErrorStats(n=20, rms_um=10.0, max_um=25.0, ap_max_um=after_ap, rp_max_um=after_rp)
    return RunSummary(outcome=Outcome.SUCCESS, run_id=1, before=before, after=after)


@pytest.mark.parametrize("spec, ap, rp, expected, words", [
    (VerificationConfig(), 18.0, 30.0, Outcome.SUCCESS, ()),  # nothing configured: the gain decides
    (VerificationConfig(max_ap_um=20.0, max_rp_um=40.0), 18.0, 30.0, Outcome.SUCCESS, ()),
    (VerificationConfig(max_ap_um=15.0), 18.0, 30.0, Outcome.TARGET_MISSED, ("AP", "18.0 µm", "max_ap_um = 15")),
    (VerificationConfig(max_rp_um=25.0), 18.0, 30.0, Outcome.TARGET_MISSED, ("RP", "30.0 µm", "max_rp_um = 25")),
    (VerificationConfig(max_rp_um=25.0), 18.0, None, Outcome.SUCCESS, ()),  # no pose measured twice: no RP
])
def test_the_accuracy_specification_decides_beside_the_gain(spec, ap, rp, expected, words):
    outcome, notes = verified_outcome(SimpleNamespace(verification=spec), _summary(ap, rp), min_gain=20.0)
    assert outcome is expected
    assert all(w in " ".join(notes) for w in words) and bool(notes) == bool(words)


def test_a_missed_gain_is_missed_whatever_the_specification():
    outcome, notes = verified_outcome(SimpleNamespace(verification=VerificationConfig(max_ap_um=100.0)),
                                      _summary(18.0, 30.0).replace(before=ErrorStats(20, 100.0, 150.0, 140.0, 20.0)),
                                      min_gain=20.0)
    assert outcome is Outcome.TARGET_MISSED and notes == ()
