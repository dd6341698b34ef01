"""``station study`` shows its progress on stderr and keeps stdout the JSON (issue 38)."""

from __future__ import annotations

import json

from station.ui.cli.main import main


def test_study_reports_each_study_as_it_ends_and_the_json_stays_clean(capsys):
    assert main(["study", "--robot", "sr800", "--quick", "--json"]) == 0
    out, err = capsys.readouterr()
    doc = json.loads(out)  # nothing but the JSON on stdout
    lines = [x for x in err.splitlines() if x.startswith("study ")]
    assert [x.split()[1] for x in lines] == [f"{k}/7" for k in range(1, 8)]
    assert lines[0].endswith(doc["studies"][0]["study"])
    figs = doc["studies"][0]["figures"]
    # the fast Monte Carlo still scatters as the linear σ says (noise only, 200 sets: ±10 % per σ)
    ratio = [p["ratio_mc_linear"] for p in doc["studies"][0]["parameters"]]
    assert 0.75 < min(ratio) <= max(ratio) < 1.3, ratio
    assert figs["monte_carlo_pose_models"] == figs["monte_carlo_sets"] == 200
