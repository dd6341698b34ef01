"""A TARGET_MISSED run says in its JSON which limit it missed (issue 37, "smaller finds"): a
``failure`` object with each limit missed, the measured value and the limit in their unit, the
setting that governs it and what to do - the facts the notes state, structured - in
``station calibrate --json`` and in the stored run summary, read back alike."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from types import SimpleNamespace

import pytest

from station.cell.config.sections import VerificationConfig
from station.cell.pipeline.results import missed_limits, verified_outcome
from station.cell.records.missed import FAILURE_KIND
from station.cell.records.rundb import RunDB
from station.cell.records.summary import ErrorStats, RunSummary
from station.errors import Outcome
from station.ui.cli.main import main

CELL = Path(__file__).resolve().parents[2] / "examples" / "scara600"


def test_a_simulated_run_that_misses_names_its_limits_in_the_json(tmp_path, capsys):
    """The example cell, rehearsed with an accuracy specification its robot cannot meet: AP of the
    worst pose within 2 µm, RP within 3 µm (the simulated robot repeats to about 10 µm)."""
    cell = tmp_path / "cell"
    shutil.copytree(CELL, cell)
    # one visit per identification pose, two verification cycles (RP needs more than one) and no
    # gripper: which limits the JSON names does not depend on the plan's length (issue 42)
    text = (cell / "cell.toml").read_text(encoding="utf-8")
    text = text[: text.index("[[tool]]")].replace("repeats = 4", "repeats = 1").replace(
        "verification_cycles = 5", "verification_cycles = 2")
    (cell / "cell.toml").write_text(text + "\n[verification]\nmax_ap_um = 2.0\nmax_rp_um = 3.0\n", encoding="utf-8")
    db = tmp_path / "runs.sqlite"
    code = main(["calibrate", "--simulated", str(cell / "cell.toml"), "--json", "--seed", "1", "--time-scale", "0",
                 "--db", str(db)])
    out = json.loads(capsys.readouterr().out)
    assert code == 10 and out["outcome"] == "TARGET_MISSED", out.get("failure")
    failure = out["failure"]
    assert failure["kind"] == FAILURE_KIND and failure["hint"]
    by_id = {m["id"]: m for m in failure["limits"]}
    assert set(by_id) == {"max_ap_um", "max_rp_um"}  # the gain was reached: not a missed limit
    ap, rp = by_id["max_ap_um"], by_id["max_rp_um"]
    # the measured values are the run's own figures, against the configured limits
    assert ap["measured"] == pytest.approx(out["after"]["ap_max_um"]) and ap["limit"] == 2.0 and ap["unit"] == "µm"
    assert rp["measured"] == pytest.approx(out["after"]["rp_max_um"]) and rp["limit"] == 3.0 and rp["unit"] == "µm"
    assert ap["measured"] > 2.0 and rp["measured"] > 3.0
    assert ap["setting"] == "[verification] max_ap_um" and rp["setting"] == "[verification] max_rp_um"
    assert "max_ap_um" in ap["hint"] and "no correction changes" in rp["hint"]
    # the same facts as the notes state
    for m in failure["limits"]:
        assert any(f"{m['measured']:.1f} µm" in n and f"{m['setting']} = {m['limit']:g} µm" in n for n in out["notes"])
    # the stored summary carries it too, and reads back to the same limits (not a stopped run's failure)
    with RunDB(str(db)) as rdb:
        stored = rdb.load_result(out["run_id"], "summary")
    assert stored["failure"] == failure
    back = RunSummary.from_json(stored)
    assert back.failure is None and [m.id for m in back.missed] == ["max_ap_um", "max_rp_um"]
    assert back.to_json()["failure"] == failure


def _summary(before_rms: float, ap: float, rp: float | None) -> RunSummary:
    return RunSummary(Outcome.SUCCESS, before=ErrorStats(20, before_rms, 2 * before_rms, before_rms, 20.0),
                      after=ErrorStats(20, 8.0, 20.0, ap, rp))


def test_a_missed_gain_is_a_limit_with_the_stations_required_gain():
    cfg = SimpleNamespace(verification=VerificationConfig(max_ap_um=10.0))
    s = _summary(100.0, 12.0, None)  # ×12.5 and AP 12 µm: both missed
    outcome, notes = verified_outcome(cfg, s, min_gain=20.0)
    missed = missed_limits(cfg, s, 20.0)
    assert outcome is Outcome.TARGET_MISSED
    assert [m.id for m in missed] == ["min_gain", "max_ap_um"]
    gain = missed[0]
    assert (gain.measured, gain.limit, gain.unit) == (pytest.approx(12.5), 20.0, "×") and "min_gain" in gain.setting
    assert "below" in gain.note and "above" in missed[1].note
    assert notes == (missed[1].note,)  # the gain stands in the figures, as before
    j = s.replace(outcome=outcome, missed=missed).to_json()["failure"]
    assert [m["id"] for m in j["limits"]] == ["min_gain", "max_ap_um"] and j["limits"][0]["at_least"] is True
    # a run that met every limit has none; a SUCCESS never carries a failure object
    assert missed_limits(cfg, _summary(1000.0, 5.0, None), 20.0) == ()
    assert "failure" not in s.replace(missed=missed).to_json()
