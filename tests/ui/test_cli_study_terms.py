"""``station study --model auto`` on the SR 800 (issue 38): the SCARA's lift axis carries no
gravity torque, so its compliance term cannot be told from the geometry and the fit leaves it out;
the study then draws and scatters the terms the fit keeps (it stopped with an internal error,
27 Monte Carlo σ beside 26 linear ones)."""

from __future__ import annotations

import json

from station.ui.cli.main import main


def test_auto_study_scatters_the_terms_the_fit_keeps(capsys):
    assert main(["study", "--robot", "sr800", "--model", "auto", "--quick", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    (study,) = doc["studies"]
    figs = study["figures"]
    assert figs["terms_left_out"] == ["compliance.q3"]
    assert "compliance.q3" not in figs["terms"]
    assert [p["parameter"] for p in study["parameters"]] == figs["terms"]
    # 100 sets: the Monte Carlo σ scatters ±7 % (1/√(2·99)); 0.75–1.3 is agreement, a mismatched
    # model would not be
    lo, hi = figs["ratio_mc_linear_all"]
    assert 0.75 < lo <= hi < 1.3, (lo, hi)
