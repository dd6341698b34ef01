"""A run that fails after measuring names the setting to change, and a fix that only judges the
stored readings again is resumed (issue 37 §4).

The cell: examples/scara600 copied, its seven-probe head's probes 4 µm noisy (the head file says
so, the simulator reads that noisy), and ``[plan] max_residual_um = 0.8`` as if copied from a
quieter head. Every step is measured; 28 of 120 identification readings are refused by their plane
residual alone, the run ends exit 3 and its message names ``[plan] max_residual_um`` with the value
that makes enough valid. That value, written into the file, is a change a resume accepts (before:
"[plan] changed since", refused); the resume judges the stored readings again and ends SUCCESS."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import pytest

from station.cell.config.cell_config import parse_text
from station.cell.records.fingerprint import JUDGED_APART, check_same_cell, current_like, fingerprint
from station.errors import ConfigError, Outcome
from station.ui.cli.main import main

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "scara600"


def _cell(tmp_path: Path, bound: float = 0.8) -> Path:
    for name in ("cell.toml", "head.toml", "robot.toml", "body.csv"):
        shutil.copy(EXAMPLE / name, tmp_path / name)
    head = tmp_path / "head.toml"
    head.write_text(re.sub(r"(?m)^reading_sigma_um = 0\.5", "reading_sigma_um = 4.0", head.read_text()))
    cfg = tmp_path / "cell.toml"
    text = cfg.read_text()
    # one verification cycle: the refusal and the resume's outcome are what is compared, and five
    # cycles of the verification cost the resume most of its CPU (issue 42)
    text = re.sub(r"(?m)^verification_cycles = 5$",
                  f"verification_cycles = 1\nmax_residual_um = {bound:g}\nmax_spread_um = 50.0", text, count=1)
    text = re.sub(r"(?m)^seed = 1$", "seed = 1\nprobe_noise_um = 4.0", text, count=1)
    assert "max_residual_um" in text and "probe_noise_um" in text
    cfg.write_text(text)
    return cfg


def test_a_changed_residual_bound_is_post_processing_and_other_plan_keys_are_not(tmp_path):
    cfg_path = _cell(tmp_path)
    text = cfg_path.read_text()
    stored = fingerprint(parse_text(text, str(cfg_path)))
    looser = parse_text(text.replace("max_residual_um = 0.8", "max_residual_um = 1.5"), str(cfg_path))
    assert check_same_cell(stored, current_like(stored, looser), 1) == ("[plan] max_residual_um",)
    more = parse_text(text.replace("repeats = 4", "repeats = 5"), str(cfg_path))
    with pytest.raises(ConfigError, match=r"\[plan\] changed since"):
        check_same_cell(stored, current_like(stored, more), 1)
    # a fingerprint stored before the bound had its own entry compares as it was made: [plan] whole
    old = fingerprint(parse_text(text, str(cfg_path)), judged_apart=False)
    assert JUDGED_APART[0] not in old
    assert check_same_cell(old, current_like(old, parse_text(text, str(cfg_path))), 1) == ()
    with pytest.raises(ConfigError, match=r"\[plan\] changed since"):
        check_same_cell(old, current_like(old, looser), 1)


@pytest.mark.slow
@pytest.mark.timeout(600)  # a hang guard: two simulated runs of 270 steps, minutes on a loaded 2-core machine
def test_a_failure_after_measuring_names_the_setting_and_its_fix_resumes_to_success(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    cfg = _cell(tmp_path)
    args = ["calibrate", "--simulated", "cell.toml", "--db", "runs.sqlite", "--json"]
    assert main(args) == Outcome.IDENTIFICATION_FAILED
    failed = json.loads(capsys.readouterr().out)
    message = failed["failure"]["message"]
    assert re.search(r"only \d+ of 120 identification poses are valid", message), message
    found = re.search(r"set \[plan\] max_residual_um = ([0-9.]+) \((\d+) valid with it\)", message)
    assert found, message
    bound, valid = float(found.group(1)), int(found.group(2))
    assert 0.8 < bound <= 1000.0 and valid >= 96
    assert "--resume" in message

    cfg.write_text(cfg.read_text().replace("max_residual_um = 0.8", f"max_residual_um = {bound:g}"))
    assert main([*args, "--resume", "1"]) == 0
    done = json.loads(capsys.readouterr().out)
    assert done["outcome"] == "SUCCESS"
    assert done["run_id"] == 1
