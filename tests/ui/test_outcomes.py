"""One source of truth for outcomes: the README's table, the classification by type, and the
exit code that the CLI returns and ``--json`` reports for the same run."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from drivers.controller_errors import (
    ControllerConnectionError,
    DriveFault,
    EmergencyStop,
    HandshakeTimeout,
    MotionRejected,
)
from drivers.correction_table import TableError, TableVerifyError
from drivers.probe_protocol import ProbeDisconnected, ProbeTimeout
from station.cell.config.template import TEMPLATE
from station.cell.pipeline.outcomes import classify, hint_for
from station.cell.records.run_records import RunDatabaseError
from station.errors import ConfigError, IdentificationError, Outcome, RunAborted, UnreachableError
from station.ui.cli.main import main

# the template's example controller is on a private network: tests never reach out to it
LOOPBACK_CONTROLLER = '"127.0.0.1:9"'

ROOT = Path(__file__).resolve().parents[2]


def test_readme_exit_code_table_is_the_outcome_enum():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    rows = re.findall(r"^\| (\d+) \| `([A-Z_]+)` \| (.*) \|$", text, flags=re.M)
    assert {(int(c), n, d) for c, n, d in rows} == {(int(o), o.name, o.description) for o in Outcome}


@pytest.mark.parametrize("exc, outcome", [
    (RunAborted("operator"), Outcome.ABORTED),
    (EmergencyStop("e-stop", 3, 1), Outcome.SAFETY_STOP),
    (DriveFault("axis 2", 4, 1), Outcome.SAFETY_STOP),
    (TableVerifyError("differs"), Outcome.UPLOAD_FAILED),
    (TableError("refused"), Outcome.UPLOAD_FAILED),
    (HandshakeTimeout("no ack"), Outcome.DEVICE_FAULT),
    (MotionRejected("soft limit", 2, 1), Outcome.DEVICE_FAULT),
    (ControllerConnectionError("refused"), Outcome.DEVICE_FAULT),
    (ProbeTimeout("no reply"), Outcome.DEVICE_FAULT),
    (ProbeDisconnected("gone"), Outcome.DEVICE_FAULT),
    (ConfigError("bad key"), Outcome.CONFIG_ERROR),
    (IdentificationError("rank"), Outcome.IDENTIFICATION_FAILED),
    (UnreachableError("limits"), Outcome.UNREACHABLE),
    (RunDatabaseError("locked"), Outcome.DATABASE_ERROR),
    (ZeroDivisionError("bug"), Outcome.INTERNAL_ERROR),
])
def test_classification_by_type(exc, outcome):
    assert classify(exc) is outcome


def test_a_subclass_named_like_another_error_is_classified_by_its_type():
    # matching by class name would call this a safety stop
    EmergencyStopLookalike = type("EmergencyStop", (RuntimeError,), {})
    assert classify(EmergencyStopLookalike("x")) is Outcome.INTERNAL_ERROR


def test_hints_name_the_run_to_resume():
    assert "--resume 12" in hint_for(HandshakeTimeout("no ack"), run_id=12)


def _run_json(capsys, argv):
    code = main([*argv, "--json"])
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 1, out  # exactly one JSON object
    return code, json.loads(out[0])


def _template(tmp_path, **replace):
    text = TEMPLATE.replace('"192.168.0.10:502"', LOOPBACK_CONTROLLER)
    for old, new in replace.items():
        text = text.replace(old, new)
    path = tmp_path / "cell.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize("case, expected", [
    ("device fault", Outcome.DEVICE_FAULT),
    ("configuration", Outcome.CONFIG_ERROR),
    ("database", Outcome.DATABASE_ERROR),
])
def test_cli_exit_code_and_json_agree(tmp_path, capsys, case, expected):
    db = tmp_path / "runs.sqlite"
    if case == "device fault":
        cfg = _template(tmp_path, **{'"/dev/ttyUSB0"': f'"{tmp_path / "no-tty"}"'})
    elif case == "configuration":
        cfg = _template(tmp_path, **{"[limits]": "[limits]\nbogus = 1"})
    else:
        cfg = _template(tmp_path, **{'"/dev/ttyUSB0"': f'"{tmp_path / "no-tty"}"'})
        db = tmp_path  # a directory is no database
    code, summary = _run_json(capsys, ["calibrate", str(cfg), "--db", str(db)])
    assert code == summary["exit_code"] == int(expected)
    assert summary["outcome"] == expected.name
    assert summary["failure"]["message"] and "Traceback" not in summary["failure"]["message"]


@pytest.mark.slow  # an end-to-end session: the slow tier (README), run by CI
def test_cli_exit_code_and_json_agree_on_success(tmp_path, capsys):
    code, summary = _run_json(capsys, ["calibrate", "--simulated", "--seed", "2", "--db", str(tmp_path / "r.sqlite")])
    assert code == summary["exit_code"] == 0 and summary["outcome"] == "SUCCESS"
    assert summary["upload"]["seconds"] > 0  # the verified upload's real duration
    assert summary["gain"] >= 20 and summary["units"]["lengths"].startswith("µm")


def test_a_bad_report_path_is_refused_before_any_motion(tmp_path, capsys):
    target = tmp_path / "report.md"
    target.write_text("an existing file")
    db = tmp_path / "r.sqlite"
    code, summary = _run_json(capsys, ["calibrate", "--simulated", "--db", str(db), "--report", str(target)])
    assert code == summary["exit_code"] == 2 and summary["outcome"] == "CONFIG_ERROR"
    assert "that is a file" in summary["failure"]["message"]
    assert not db.exists()  # refused before a run was created, so before anything moved


@pytest.mark.slow  # an end-to-end session: the slow tier (README), run by CI
def test_no_upload_with_report_writes_the_report(seed1_not_uploaded):
    """calibrate --simulated --seed 1 --no-upload --json --report: the suite's run (tests/conftest.py)."""
    (line,) = seed1_not_uploaded.out.strip().splitlines()  # exactly one JSON object
    code, summary = seed1_not_uploaded.code, json.loads(line)
    assert code == 11 and summary["outcome"] == "NOT_UPLOADED"
    assert summary["upload_skipped"] is True and "after" not in summary
    text = (seed1_not_uploaded.report / "report.md").read_text(encoding="utf-8")
    assert "skipped (--no-upload)" in text
