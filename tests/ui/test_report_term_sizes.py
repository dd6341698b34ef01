"""The run's note in the report gives each kept term's physical size with σ, judged against the
robot's class (issue 38): the simulated SCARA's once-per-turn gear error of joint 1 (25″)."""

from __future__ import annotations

import re

from station.cell.pipeline.terms import error_model_record, error_model_summary, terms_note
from tests.cell.scara_terms import scara_terms


def test_the_runs_note_and_record_carry_the_kept_terms_sizes():
    s = scara_terms()
    note = terms_note(error_model_summary(s.cfg, s.sel))
    assert "cyclic.q1" in s.sel.chosen and "sizes (small arm" in note
    m = re.search(r"joint 1 cyclic: up to ([\d.]+) ± ([\d.]+)″", note)
    assert m is not None and 15.0 < float(m.group(1)) < 35.0 and 0 < float(m.group(2)) < 5.0  # the simulated 25″
    assert "IMPLAUSIBLE" not in note
    rec = error_model_record(s.cfg, s.sel)
    z = next(z for z in rec["term_sizes"] if z["joint"] == 1 and z["kind"] == "cyclic")
    assert z["plausible"] and z["units"]["largest_turn_arcsec"] == "″" and rec["robot_class"]["class"] == "small"
