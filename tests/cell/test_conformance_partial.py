"""station conformance says what it did not check (issue 37, "smaller finds"): a requirement of
which a part could not be checked is reported "partly checked" - in the text, and in the JSON with
the parts it did not check - never "passed"; a part that can be checked later in the run (the
TABLE_NOT_STAGED refusal behind the operator's staged table) is checked then. And the claim the kit
lets lapse on purpose in its watchdog check is that step's expected outcome, not a warning of the
run."""

from __future__ import annotations

import json
import logging

from simulators.controller_server import SimulatedController
from station.cell.config.cell_config import parse_text
from station.cell.conformance import suite as cf
from station.ui.cli.main import main
from tests.cell.test_conformance import _load_slots, config_text

NOT_STAGED = "TABLE_NOT_STAGED for TABLE_ACTIVATE with nothing staged"


def test_the_watchdog_check_lapses_the_claim_without_a_warning(tmp_path, capsys, caplog):
    with SimulatedController(time_scale=1.0) as sim:
        p = tmp_path / "cell.toml"
        p.write_text(config_text(sim.port))
        with caplog.at_level(logging.INFO):
            assert main(["conformance", str(p)]) == 0
    err = capsys.readouterr().err
    lapsed = [r.getMessage() for r in caplog.records if "lapsed" in r.getMessage()]
    assert not lapsed, lapsed
    assert "lapsed" not in err
    # the step says what happened, as the expected outcome
    assert "the watchdog freed the kit's silent claim" in err and "as this check expects" in err


def test_a_check_the_kit_could_not_make_leaves_error_codes_partly_checked(tmp_path, capsys):
    """The robot is not in its park zone: the zero-speed refusal needs a (no-motion) MOVE_JOINTS,
    which the kit does not send; BAD_COMMAND and TABLE_NOT_STAGED are checked."""
    with SimulatedController(time_scale=0.0) as sim:
        p = tmp_path / "cell.toml"
        p.write_text(config_text(sim.port, park="[30.0, 0.0, -1.0, 0.0]"))
        assert main(["conformance", str(p), "--json"]) == 7
        out = json.loads(capsys.readouterr().out)
        assert main(["conformance", str(p)]) == 7
        text = capsys.readouterr().out
    ec = next(r for r in out["requirements"] if r["id"] == "error_codes")
    assert ec["status"] == cf.PARTLY_CHECKED
    assert ec["not_checked"] == ["BAD_COMMAND for cmd_speed 0"]
    assert any("unknown command code 99: BAD_COMMAND" in d for d in ec["detail"])
    assert any("TABLE_ACTIVATE with nothing staged: TABLE_NOT_STAGED" in d for d in ec["detail"])
    assert any("jog" in f for f in ec["fix"])  # what to do so that it can be checked
    assert "[PARTLY CHECKED] error_codes" in text and "[passed] error_codes" not in text
    assert "partly checked" in text.splitlines()[-1]


def test_the_operators_staged_table_is_not_an_unchecked_refusal():
    """The kit found a staged table: TABLE_ACTIVATE would activate it, so TABLE_NOT_STAGED is
    checked after the slot rules, which leave nothing staged (the slots are put back after it)."""
    with SimulatedController(time_scale=0.0) as sim:
        before = _load_slots(sim.port)
        report = cf.run_conformance(parse_text(config_text(sim.port)))
        after = {k: sim.register(f"table_{k}_crc") for k in ("staged", "active", "previous")}
    ec = report.requirement("error_codes")
    assert ec.status == cf.PASSED and not ec.unchecked, "\n".join(report.describe())
    assert not any(d.startswith("not checked") for d in ec.detail)
    assert "TABLE_ACTIVATE with nothing staged: TABLE_NOT_STAGED" in ec.detail
    assert after == before and report.passed


def test_a_program_without_slot_reads_gets_table_not_staged_as_not_checked():
    with SimulatedController(time_scale=0.0, quirks={"no_slot_reads"}) as sim:
        _load_slots(sim.port)  # tables the kit cannot read back, so it must not risk them
        report = cf.run_conformance(parse_text(config_text(sim.port)))
    ec = report.requirement("error_codes")
    assert ec.status == cf.PARTLY_CHECKED and ec.unchecked == [NOT_STAGED]
    assert ec.to_json()["not_checked"] == [NOT_STAGED]
    assert any("never destroys a table it could not put back" in d for d in ec.detail)


def test_a_program_that_activates_nothing_fails_error_codes():
    """The deferred check is a real check: a program that accepts TABLE_ACTIVATE with nothing
    staged fails it (and gets its slots back)."""
    with SimulatedController(time_scale=0.0, quirks={"activate_unstaged"}) as sim:
        before = _load_slots(sim.port)
        report = cf.run_conformance(parse_text(config_text(sim.port)))
        after = {k: sim.register(f"table_{k}_crc") for k in ("staged", "active", "previous")}
    ec = report.requirement("error_codes")
    assert ec.status == cf.FAILED and "TABLE_NOT_STAGED (8)" in " ".join(ec.fix)
    assert after == before
