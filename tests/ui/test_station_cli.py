"""Station commands: configuration template and validation, check, export, reversal, selection."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from simulators import start_simulated_cell
from simulators.reference_cell import cell_config_text as simulated_config_text
from station.cell.config.cell_config import parse_text
from station.cell.config.template import TEMPLATE
from station.cell.plan.measurement_plan import build_plan
from station.errors import ConfigError
from station.ui.cli.main import main

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def sim():
    s = start_simulated_cell(seed=2)
    yield s
    s.stop()


def test_init_writes_a_template_that_validates(tmp_path, capsys):
    path = tmp_path / "cell.toml"
    assert main(["init", str(path)]) == 0
    cfg = parse_text(path.read_text())
    assert cfg.model.name == "sr800" and len(cfg.point_ids) == 9  # three cubes at three heights
    assert main(["plan", str(path)]) == 0  # enough poses to plan as written
    capsys.readouterr()
    assert main(["init", str(path)]) == 2  # never overwrites without --force
    assert "exists" in capsys.readouterr().err


@pytest.mark.parametrize("old,new,key", [
    ('word_order = "big"', 'word_order = "middle"', "devices.word_order"),
    ("speed = 0.5", "speed = 1.5", "plan.speed"),
    ('controller = "192.168.0.10:502"', 'controller = "192.168.0.10"', "devices.controller"),
    ('objective = "pose"', 'objective = "angles"', "identification.objective"),
    ("[cell]", "[cell]\ncolour = 1", "cell"),
    ("samples = 4 ", "samples = \"four\" ", "plan.samples"),
    ("joints = [[-125.0, 125.0],", "joints = [[125.0, -125.0],", "limits.joints"),
])
def test_bad_configuration_names_the_key(old, new, key):
    assert old in TEMPLATE
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        parse_text(TEMPLATE.replace(old, new, 1))


def test_broken_toml_is_a_config_error_not_a_traceback(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text("[robot\nmodel = 1")
    assert main(["check", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "not valid TOML" in err and "Traceback" not in err


def test_check_connects_to_every_device(sim, tmp_path, capsys):
    cfg = tmp_path / "sim.toml"
    cfg.write_text(simulated_config_text(sim, 2))
    # the parked head touches nothing: its plungers rest at their stops (over range), not a fault
    assert main(["check", str(cfg)]) == 0
    out = capsys.readouterr().out
    assert "probe head" in out and "controller" in out and "FAILED" not in out
    # a controller nobody listens on is reported, and the exit code says device fault
    cfg.write_text(simulated_config_text(sim, 2).replace(f":{sim.controller_port}", ":1"))
    assert main(["check", str(cfg)]) == 7
    assert "FAILED" in capsys.readouterr().out


@pytest.mark.slow  # an end-to-end session: the slow tier (README), run by CI
def test_calibrate_json_summary_export_and_reversal(sim, tmp_path, capsys):
    text = simulated_config_text(sim, 2).replace("repeats = 4", "repeats = 1\nboth_directions = true")
    cfg = tmp_path / "sim.toml"
    cfg.write_text(text)
    db = tmp_path / "runs.sqlite"
    code = main(["calibrate", str(cfg), "--db", str(db), "--no-upload", "--json"])
    out, err = capsys.readouterr()
    summary = json.loads(out.strip().splitlines()[-1])
    assert code == 11 and summary["outcome"] == "NOT_UPLOADED" and "[measure]" in err
    # the reversal error: approach from both sides, about the simulated 0.1 mm backlash
    rev = summary["reversal"]
    assert rev["n"] > 10 and 30.0 < rev["rms_um"] < 250.0
    assert main(["export", "--db", str(db), str(tmp_path / "m.csv")]) == 0
    rows = list(csv.reader(open(tmp_path / "m.csv")))
    from station.cell.records.rundb import RunDB

    with RunDB(db) as d:
        n = len(d.measurements(summary["run_id"]))
    assert len(rows) - 1 == n  # one row per stored measurement
    # units in the header; joints and orientations in degrees, as everywhere else (issue 29)
    assert any("[mm]" in h for h in rows[0]) and any("[deg]" in h for h in rows[0])
    assert not any("rad" in h for h in rows[0])


def test_calibrate_without_config_is_a_usage_error(capsys):
    assert main(["calibrate"]) == 2
    assert "--simulated" in capsys.readouterr().err


def test_d_optimal_selection_keeps_the_most_informative_steps(sim):
    text = simulated_config_text(sim, 2)
    full = build_plan(parse_text(text))
    sel = build_plan(parse_text(text.replace("repeats = 4", "repeats = 1\nselect = 12")))
    assert len(sel.identification) == 12
    from station.core.identification.identifiability import analyze
    from station.core.identification.identify import identify  # noqa: F401  (the core is what ranks them)
    from station.core.measurement.measurements import synthetic_set

    cfg = parse_text(text)
    q = np.array([s.q for s in sel.identification])
    a = analyze(cfg.model, synthetic_set(cfg.model, "pose", q, cfg.model.nominal))
    assert a.rank == 20  # 12 chosen poses still identify the complete model
    assert len(full.identification) > len(sel.identification)


def test_simulated_calibration_console_script_exit_code(tmp_path, short_cell):
    # the built-in cell with one visit per identification pose and one verification cycle: the
    # process's exit code and its one JSON object are the same on the shorter run (issue 42)
    p = subprocess.run([sys.executable, "-m", "station.ui.cli.main", "calibrate", "--simulated", str(short_cell),
                        "--seed", "2", "--no-upload", "--db", str(tmp_path / "r.sqlite"), "--json"],
                       cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert p.returncode == 11, p.stderr  # its own outcome: a script tells it from a correction
    assert json.loads(p.stdout)["outcome"] == "NOT_UPLOADED"
    assert "Traceback" not in p.stderr
