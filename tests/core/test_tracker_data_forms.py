"""Real measured data as a tracker user brings it (issue 18 §3), on data made here with the
project's six-axis and SCARA models: repeated wrist angles (q6 and q6 + 360°), a distance-fitted
model validated, an unknown marker offset, a cp1252 export with extra columns and unit-bracket
headers in capitals, a nest of three reflectors, outliers under a robust loss; every --json
carries outcome and exit_code, no case exits 1."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from station.core.identification.registration import rigid_residual_mm
from station.core.kinematics.forward import forward
from station.core.kinematics.model import robot_to_toml
from station.core.kinematics.poses import spread_joints
from station.core.kinematics.tool_frame import fit_marker_offset
from station.core.kinematics.transforms import matrix_to_pose
from station.core.measurement.measurements import synthetic_set
from station.core.units import DEG
from station.errors import ConfigError
from station.io.datafile import read_measurement_file, read_table
from station.io.robot.files import load_robot
from station.ui.cli.main import main

IRB = load_robot("irb2600")
SR800 = load_robot("sr800")
TRACKER = np.array([2100.0, -1500.0, 600.0, 3 * DEG, -2 * DEG, 120 * DEG])  # robot base in the tracker frame
MARKER = np.array([62.0, -40.0, 75.0])  # a reflector on an adapter, unknown to the robot file [mm]


def _truth(model=IRB, seed=3, marker=None):
    rng = np.random.default_rng(seed)
    p = model.nominal + rng.standard_normal(model.n_params) * np.where(model.is_angle(), 3e-4, 0.2)
    p[:6] = TRACKER
    if marker is not None:
        p[-6:-3] += marker
    return p


def _joints(n, seed, model=IRB):
    q = spread_joints(model, n, np.random.default_rng(seed))
    if model.n_joints == 6:
        q[:, 4] = np.sign(q[:, 4]) * np.maximum(np.abs(q[:, 4]), 0.3)  # away from the wrist singularity
    return q


def _positions(q, true, seed, model=IRB, sigma=0.015):
    return synthetic_set(model, "position", q, true, sigma=np.full(3, sigma), rng=np.random.default_rng(seed)).measured


def _header(model=IRB):
    return [f"q{j + 1} [{'deg' if t == 'revolute' else 'mm'}]" for j, t in enumerate(model.joint_types)]


def _deg(q, model=IRB):
    out = np.array(q)
    rev = [j for j, t in enumerate(model.joint_types) if t == "revolute"]
    out[:, rev] = np.degrees(out[:, rev])
    return out


def _write(path: Path, header, rows, encoding="utf-8", comment="# tracker export") -> Path:
    lines = [comment, ",".join(header)] + [",".join(str(v) if isinstance(v, str) else repr(float(v)) for v in r)
                                           for r in rows]
    path.write_bytes(("\n".join(lines) + "\n").encode(encoding))
    return path


def _position_file(path, q, pos, model=IRB):
    return _write(path, _header(model) + ["x [mm]", "y [mm]", "z [mm]"], np.column_stack([_deg(q, model), pos]))


def run(capsys, *argv):
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def run_json(capsys, *argv):
    rc, out, err = run(capsys, *argv, "--json")
    d = json.loads(out)  # one JSON object, success or failure
    assert d["exit_code"] == rc and "outcome" in d, d
    assert rc != 1, err
    return rc, d, err


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    """Calibration and held-out position files of the six-axis robot in a tracker frame."""
    d = tmp_path_factory.mktemp("tracker")
    true = _truth()
    q_cal, q_val = _joints(40, 1), _joints(30, 2)
    cal = _position_file(d / "cal.csv", q_cal, _positions(q_cal, true, 11))
    val = _position_file(d / "val.csv", q_val, _positions(q_val, true, 12))
    return d, true, q_cal, q_val, cal, val


# --- repeated wrist angles -------------------------------------------------------------------

def test_distance_objective_drops_pairs_of_q6_and_q6_plus_360_instead_of_crashing(capsys, cell, tmp_path):
    d, true, q_cal, _, _, _ = cell
    q = np.vstack([q_cal, q_cal[:6] + np.array([0, 0, 0, 0, 0, 2 * np.pi])])  # wrist sweeps past a full turn
    f = _position_file(tmp_path / "wrist.csv", q, _positions(q, true, 21))
    rc, rep, err = run_json(capsys, "identify", f, "--robot", "irb2600", "--objective", "distance", "--pairs", "all")
    assert rc == 0, err
    assert rep["outcome"] == "SUCCESS"
    assert [1, 41] in rep["dropped_pairs"] and len(rep["dropped_pairs"]) == 6
    assert any("6 of 1035 distances dropped" in n for n in rep["notes"]), rep["notes"]
    assert rep["pairs"]["count"] == 1035 - 6
    assert rep["rms_normalized"] < 2.0


# --- validate: set-up known, registered on the calibration data, or refused --------------------

def test_validate_refuses_a_distance_fitted_model_without_its_set_up(capsys, cell):
    d, true, _, _, cal, val = cell
    model = d / "dist.toml"
    rc, _, err = run(capsys, "identify", cal, "--robot", "irb2600", "--objective", "distance", "-o", model)
    assert rc == 0, err
    rc, rep, err = run_json(capsys, "validate", model, val)
    assert rc == 2 and rep["outcome"] == "CONFIG_ERROR"
    assert "set-up is unknown" in err and "--calibration" in err and "0.0×" not in err
    rc, rep, err = run_json(capsys, "validate", model, val, "--calibration", cal)
    assert rc == 0 and rep["outcome"] == "SUCCESS", err
    assert rep["setup"].startswith("registered on")
    assert rep["model_errors"]["rms_position_um"] < 60
    assert rep["improvement"] > 5


def test_validate_registers_nominal_on_the_calibration_data_not_on_the_held_out_rows(capsys, cell):
    d, true, _, q_val, cal, val = cell
    model = d / "pos.toml"
    rc, _, err = run(capsys, "identify", cal, "--robot", "irb2600", "-o", model)
    assert rc == 0, err
    rc, own, err = run_json(capsys, "validate", model, val)  # a position fit carries its set-up
    assert rc == 0, err
    rc, reg, err = run_json(capsys, "validate", model, val, "--calibration", cal)
    assert rc == 0, err
    held_out_fit_um = rigid_residual_mm(IRB, q_val, read_measurement_file(val, IRB).measured) * 1e3
    for r in (own, reg):
        assert r["model_errors"]["rms_position_um"] < 60
        # registered on the held-out rows themselves it would read exactly the best alignment's figure
        assert r["nominal_errors"]["rms_position_um"] > held_out_fit_um + 1.0
    assert own["model_errors"]["rms_position_um"] == pytest.approx(reg["model_errors"]["rms_position_um"], rel=0.2)


# --- an unknown marker offset -----------------------------------------------------------------

def test_marker_offset_is_told_from_a_unit_error_and_fitted_with_tool_unknown(capsys, tmp_path):
    true = _truth(marker=MARKER)
    q_cal, q_val = _joints(40, 5), _joints(30, 6)
    cal = _position_file(tmp_path / "mocap.csv", q_cal, _positions(q_cal, true, 31))
    rc, rep, err = run_json(capsys, "identify", cal, "--robot", "irb2600")
    assert rc == 2, err
    assert "--tool unknown" in err and "not a unit error" in err and "no unit explains" not in err
    out = tmp_path / "m.toml"
    rc, rep, err = run_json(capsys, "identify", cal, "--robot", "irb2600", "--tool", "unknown", "-o", out)
    assert rc == 0 and rep["outcome"] == "SUCCESS", err
    np.testing.assert_allclose(np.array(rep["registration"]["tool_offset_mm"]) - IRB.nominal[-6:-3], MARKER, atol=2.0)
    ident = load_robot(out)
    err_mm = forward(IRB, q_val, ident.nominal)[:, :3, 3] - forward(IRB, q_val, true)[:, :3, 3]
    assert np.sqrt(np.mean(np.sum(err_mm**2, axis=1))) < 0.05


def test_marker_fit_on_a_scara_holds_the_height_it_cannot_see():
    true = _truth(SR800, marker=np.array([30.0, -20.0, 15.0]))
    q = spread_joints(SR800, 40, np.random.default_rng(8))
    fit = fit_marker_offset(SR800, q, _positions(q, true, 9, model=SR800))
    assert fit.undetermined == 1  # a SCARA's tool turns about z only: its height merges with the tracker's
    np.testing.assert_allclose(fit.shift_mm[:2], [30.0, -20.0], atol=1.5)
    assert fit.shift_mm[2] == pytest.approx(0.0, abs=1e-6)


def test_a_refusal_that_misses_names_sigma_and_its_option(capsys, cell, tmp_path):
    _, true, q_cal, _, _, _ = cell
    pos = _positions(q_cal, true, 41)
    swapped = q_cal[:, [0, 2, 1, 3, 4, 5]]  # joints 2 and 3 exchanged in the export
    f = _position_file(tmp_path / "swapped.csv", swapped, pos)
    rc, rep, err = run_json(capsys, "identify", f, "--robot", "irb2600")
    assert rc == 3 and "miss the nominal model by" in err, err
    assert "30 × 15 µm" in err and "--sigma-position" in err


# --- the file as an instrument exports it ------------------------------------------------------

def test_cp1252_export_with_capital_bracket_headers_and_extra_columns(capsys, cell, tmp_path):
    _, true, q_cal, _, cal, _ = cell
    pos = read_measurement_file(cal, IRB).measured
    header = ([f"Q{j} [DEG]" for j in range(1, 7)] + ["Point ID", "X [mm]", "Y [m]", "Z (mm)", "Temp [°C]"])
    rows = [[*_deg(q_cal)[i], f"P{i + 1}", pos[i, 0], pos[i, 1] / 1000.0, pos[i, 2], "21.5 °C"]
            for i in range(len(q_cal))]
    f = _write(tmp_path / "export.csv", header, rows, encoding="cp1252", comment="# Messung Prüfstand, 15 µm")
    assert b"\xb0C" in f.read_bytes()  # ° as one byte: not UTF-8
    rc, rep, err = run_json(capsys, "identify", f, "--robot", "irb2600")
    assert rc == 0, err
    notes = " ".join(rep["notes"])
    assert "read as cp1252" in notes and "'Point ID'" in notes and "'Temp [°C]'" in notes
    rc, ref, err = run_json(capsys, "identify", cal, "--robot", "irb2600")
    assert rc == 0, err
    for name, p in ref["parameters"].items():
        assert rep["parameters"][name]["value_mm" if "value_mm" in p else "value_rad"] == pytest.approx(
            p["value_mm" if "value_mm" in p else "value_rad"], abs=1e-6)


def test_utf16_and_semicolon_exports_are_read(tmp_path):
    text = "q1 [deg];q2 [deg];x [mm]\n1,5;2;3,25\n"
    (tmp_path / "a.csv").write_bytes(text.encode("utf-16"))
    t = read_table(tmp_path / "a.csv")
    assert t.columns["q1"][0] == pytest.approx(1.5 * DEG) and t.columns["x"][0] == pytest.approx(3.25)
    assert any("UTF-16" in n for n in t.notes)
    (tmp_path / "b.csv").write_bytes(b"q1 [deg],x [mm]\n1,\x002\n")
    with pytest.raises(ConfigError, match="NUL bytes"):
        read_table(tmp_path / "b.csv")


def test_a_known_column_still_needs_its_unit(tmp_path):
    (tmp_path / "u.csv").write_text("Q1,x [mm]\n1,2\n")
    with pytest.raises(ConfigError, match="column 'Q1' has no unit"):
        read_table(tmp_path / "u.csv")


# --- a nest of three reflectors --------------------------------------------------------------

# reflectors in the tool frame; three different sides, so that two reflectors read into each
# other's columns change the sides (an equilateral nest would only mirror the frame)
NEST = np.array([[50.0, 0.0, 0.0], [-20.0, 35.0, 0.0], [-25.0, -30.0, 0.0]])


def _nest_rows(q, true, seed):
    rng = np.random.default_rng(seed)
    T = forward(IRB, q, true)
    P = np.einsum("nij,kj->nki", T[:, :3, :3], NEST) + T[:, None, :3, 3]
    return P + rng.normal(0, 0.01, P.shape)


def test_three_reflectors_of_a_nest_are_one_pose(capsys, tmp_path):
    true = _truth()
    q = _joints(40, 7)
    P = _nest_rows(q, true, 3)
    header = _header() + [f"{c}{k} [mm]" for k in (1, 2, 3) for c in "xyz"]
    f = _write(tmp_path / "nest.csv", header, np.column_stack([_deg(q), P.reshape(len(q), 9)]))
    mf = read_measurement_file(f, IRB)
    assert mf.kind == "pose" and mf.measured.shape == (40, 4, 4)
    np.testing.assert_allclose(mf.measured[:, :3, 3], P.mean(axis=1))
    rc, rep, err = run_json(capsys, "identify", f, "--robot", "irb2600", "--sigma-position", 10, "--sigma-angle", 60)
    assert rc == 0 and rep["objective"] == "pose", err
    assert rep["rms_normalized"] < 3.0
    bad = P.copy()
    bad[17, [0, 1]] = bad[17, [1, 0]]  # two reflectors read into each other's columns on one row
    g = _write(tmp_path / "nest_bad.csv", header, np.column_stack([_deg(q), bad.reshape(len(q), 9)]))
    rc, rep, err = run_json(capsys, "identify", g, "--robot", "irb2600")
    assert rc == 2 and "line 20" in err and "reflectors" in err, err


# --- outliers under a robust loss -------------------------------------------------------------

def test_huber_loss_resists_outliers_and_lists_the_rows_it_down_weighted(capsys, cell, tmp_path):
    _, true, q_cal, q_val, _, _ = cell
    pos = np.array(_positions(q_cal, true, 51))
    bad_rows = [4, 17, 29]
    pos[bad_rows] += np.array([1.5, -1.0, 2.0])  # the tracker caught another reflector
    f = _position_file(tmp_path / "outliers.csv", q_cal, pos)
    held = {}
    for loss in ("linear", "huber"):
        out = tmp_path / f"{loss}.toml"
        rc, rep, err = run_json(capsys, "identify", f, "--robot", "irb2600", "--loss", loss, "-o", out)
        assert rc == 0, err
        e = forward(IRB, q_val, load_robot(out).nominal)[:, :3, 3] - forward(IRB, q_val, true)[:, :3, 3]
        held[loss] = float(np.sqrt(np.mean(np.sum(e**2, axis=1))))
        if loss == "huber":
            worst = {r["rows"][0] for r in rep["down_weighted"] if r["weight"] < 0.1}
            assert worst == {i + 1 for i in bad_rows}, rep["down_weighted"]
            assert rep["loss"] == "huber"
    assert held["huber"] < 0.3 * held["linear"], held
    assert held["huber"] < 0.05


# --- --json carries outcome and exit_code -----------------------------------------------------

def test_predict_and_compensate_json_carry_outcome(capsys, cell, tmp_path):
    d, true, q_cal, _, _, _ = cell
    j = _write(tmp_path / "j.csv", _header(), _deg(q_cal[:5]))
    rc, rep, err = run_json(capsys, "predict", "irb2600", j)
    assert rc == 0 and rep["outcome"] == "SUCCESS" and len(rep["poses_mm_rad"]) == 5
    (tmp_path / "model.toml").write_text(robot_to_toml(IRB, true, angle_unit="rad"))
    P = forward(IRB, _joints(3, 9), true, setup=False)
    poses = matrix_to_pose(P)
    t = tmp_path / "t.csv"
    t.write_text("x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg\n" + "\n".join(
        ",".join([f"{v:.9f}" for v in p[:3]] + [f"{math.degrees(v):.12f}" for v in p[3:]]) for p in poses) + "\n")
    rc, rep, err = run_json(capsys, "compensate", tmp_path / "model.toml", t, "-o", tmp_path / "o.csv",
                            "--robot", "irb2600")
    assert rc == 0 and rep["outcome"] == "SUCCESS", err
