"""``station validate MODEL DATA --calibration CAL`` registers with the model it scores with, error
terms included (issue 36, §4): the held-out RMS equals the model's own validation within 1 %.

Registered without the terms' joint corrections, an auto model of the FANUC tracker data missed its
held-out poses by 2 133 µm where it holds 526 µm. The real data are not kept here (no licence,
benchmarks/data/README.md): that test runs where ``STATION_BOBY_KLIMCHIK`` names a clone of
github.com/RABKKK/LaserTrackerPoseData4KinIdent."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from station.core.accuracy.studies import StudyInputs, perturbed
from station.core.kinematics.poses import spread_joints
from station.core.measurement.measurements import MeasurementSet, add_noise
from station.core.terms.error_model import TermSpec, apply_terms, term_basis
from station.io.datafile import write_csv
from station.io.robot.files import load_robot
from station.ui.cli.main import main

ARM = load_robot("irb2600")
HEADER = [f"q{i} [deg]" for i in range(1, 7)] + ["x [mm]", "y [mm]", "z [mm]"]
ROOT = Path(__file__).resolve().parents[2]
BOBY = os.environ.get("STATION_BOBY_KLIMCHIK")


def _rms(capsys, *argv) -> float:
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert rc == 0, err
    return float(json.loads(out)["model_errors"]["rms_position_um"])


def _same_with_and_without_calibration(capsys, model, held, calibration, *robot) -> tuple[float, float]:
    own = _rms(capsys, "validate", model, held, *robot, "--json")
    registered = _rms(capsys, "validate", model, held, "--calibration", calibration, *robot, "--json")
    return own, registered


def test_a_bending_arm_registers_with_its_terms(tmp_path, capsys):
    """A heavy arm's sag (compliance 3e-5 rad/(N·m)) seen by a tracker turned and metres away."""
    rng = np.random.default_rng(36)
    true = perturbed(ARM, rng, StudyInputs())
    true[:6] = [2500.0, -1200.0, 300.0, 0.01, -0.02, 0.4]  # the tracker's frame
    files = {}
    for name, n in (("cal.csv", 60), ("held.csv", 40)):
        q = spread_joints(ARM, n, rng)
        basis = term_basis(ARM, q, TermSpec(("compliance",)), params=true)
        pts = apply_terms(ARM, q, true, basis, np.array([3e-5, 4e-5]))[:, :3, 3]
        d = MeasurementSet("position", q, pts, np.array([0.015] * 3))
        files[name] = tmp_path / name
        write_csv(files[name], HEADER, np.column_stack([np.degrees(q), add_noise(d, pts, rng)]))
    model = tmp_path / "auto.toml"
    rc = main([str(a) for a in ("identify", files["cal.csv"], "--robot", "irb2600", "--model", "compliance",
                                "-o", model)])
    assert rc == 0, capsys.readouterr().err
    capsys.readouterr()
    own, registered = _same_with_and_without_calibration(capsys, model, files["held.csv"], files["cal.csv"])
    assert own < 40.0  # the noise, 15 µm per coordinate: the terms hold
    assert registered == pytest.approx(own, rel=0.01)


@pytest.mark.skipif(not BOBY, reason="real tracker data not kept here: set STATION_BOBY_KLIMCHIK to a clone")
def test_an_auto_model_of_real_tracker_data_validates_the_same_registered_or_not(tmp_path, capsys):
    """The FANUC's nest poses, every fourth held out: identify --model auto on the rest, then validate
    the held-out poses with the model's own set-up and registered on the calibration data."""
    a = np.loadtxt(Path(BOBY) / "N1N2N3Jval.csv")  # type: ignore[arg-type]
    rows = np.column_stack([a[:, 15:21], a[:, :9]])
    header = [f"q{i} [deg]" for i in range(1, 7)] + [f"{c}{k} [mm]" for k in (1, 2, 3) for c in "xyz"]
    held = np.arange(len(rows)) % 4 == 2
    cal, test = tmp_path / "cal.csv", tmp_path / "held.csv"
    write_csv(cal, header, rows[~held])
    write_csv(test, header, rows[held])
    model = tmp_path / "auto.toml"
    robot = ROOT / "benchmarks" / "data" / "fanuc_r2000ic_165f.dh.csv"
    rc = main([str(a) for a in ("identify", cal, "--robot", robot, "--tool", "unknown", "--model", "auto",
                                "-o", model)])
    assert rc == 0, capsys.readouterr().err
    out = capsys.readouterr().out
    assert "kept" in out and "[error_terms]" in model.read_text()  # the data keep a term: the case at issue
    own, registered = _same_with_and_without_calibration(capsys, model, test, cal)
    assert registered == pytest.approx(own, rel=0.01)
