"""The ``station`` command line for the numerical core: analyze, identify, predict, errors."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from station.core.kinematics.forward import forward
from station.core.kinematics.poses import spread_joints
from station.core.kinematics.transforms import matrix_to_pose
from station.core.measurement.measurements import synthetic_set
from station.io.datafile import write_csv
from station.io.robot.files import load_robot
from station.ui.cli.main import main

SR800 = load_robot("sr800")
ROOT = Path(__file__).resolve().parents[2]
JOINT_HEADER = ["q1 [deg]", "q2 [deg]", "q3 [mm]", "q4 [deg]"]
POSE_HEADER = JOINT_HEADER + ["x [mm]", "y [mm]", "z [mm]", "roll [deg]", "pitch [deg]", "yaw [deg]"]


def _deg_joints(q):
    out = np.array(q)
    out[:, [0, 1, 3]] = np.degrees(out[:, [0, 1, 3]])
    return out


def _true_params(seed=3):
    rng = np.random.default_rng(seed)
    p = SR800.nominal + rng.standard_normal(36) * np.where(SR800.is_angle(), 5e-4, 0.1)
    p[:6] = [150.0, -80.0, 12.0, 0.0, 0.0, 0.3]  # set-up: body frame shifted and turned
    return p


@pytest.fixture(scope="module")
def pose_file(tmp_path_factory):
    """A pose file in degrees with 5 µm / 5″ noise, and its joints-only companion."""
    d = tmp_path_factory.mktemp("cli")
    rng = np.random.default_rng(4)
    q = spread_joints(SR800, 30, rng)
    sig = np.array([0.005] * 3 + [5 * np.pi / 180 / 3600] * 3)
    data = synthetic_set(SR800, "pose", q, _true_params(), sigma=sig, rng=rng)
    pose = matrix_to_pose(data.measured)
    pose[:, 3:] = np.degrees(pose[:, 3:])
    f = d / "poses.csv"
    write_csv(f, POSE_HEADER, np.column_stack([_deg_joints(q), pose]))
    f.write_text("# synthetic SR 800, 5 µm noise\n" + f.read_text())
    j = d / "joints.csv"
    write_csv(j, JOINT_HEADER, _deg_joints(q))
    return f, j, q, data


def run(capsys, *argv):
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


# --- analyze --------------------------------------------------------------------------------------

def test_analyze_text(capsys):
    rc, out, err = run(capsys, "analyze")
    assert rc == 0 and err == ""
    assert "identifiable parameters (rank): 20" in out
    assert "4R+2P+6 = 20" in out
    assert "A1.x ≡ +1·R.x" in out


def test_analyze_json(capsys):
    rc, out, _ = run(capsys, "analyze", "--json")
    assert rc == 0
    d = json.loads(out)
    assert d["rank"] == 20 and d["n_parameters"] == 36 and len(d["chosen"]) == 20
    rc, out, _ = run(capsys, "analyze", "--kind", "distance", "--json")
    assert json.loads(out)["rank"] == 11
    rc, out, _ = run(capsys, "analyze", "--kind", "distance", "--planar", "--json")
    assert json.loads(out)["rank"] == 5
    rc, out, _ = run(capsys, "analyze", "--kind", "distance", "--exclude", "A4.roll,A4.pitch", "--json")
    d = json.loads(out)
    assert d["rank"] == 9 and set(d["held"]) == {"A4.roll", "A4.pitch"}


def test_analyze_with_joint_file(capsys, pose_file):
    _, joints, _, _ = pose_file
    rc, out, _ = run(capsys, "analyze", "--joints", joints, "--json")
    d = json.loads(out)
    assert rc == 0 and d["poses"] == 30 and d["rank"] == 20


# --- identify -> robot file -> predict ---------------------------------------------------------------

def test_identify_writes_model_that_predict_reproduces(capsys, pose_file, tmp_path):
    f, joints, q, data = pose_file
    out_file = tmp_path / "identified.toml"
    rc, out, err = run(capsys, "identify", f, "-o", out_file, "--sigma-position", 5,
                       "--sigma-angle", 5, "--json")
    assert rc == 0, err
    d = json.loads(out)
    assert d["converged"] is True
    assert 0.6 < d["rms_normalized"] < 1.4  # noise of the stated σ
    assert len(d["parameters"]) == 20 and d["outliers"] == []
    # the file holds exactly the fitted parameters
    model = load_robot(out_file)
    for name, v in d["parameters"].items():
        value = v["value_rad"] if "value_rad" in v else v["value_mm"]
        assert model.nominal[model.param_index(name)] == pytest.approx(value, abs=1e-12)
    # its poses agree with the measurements to the noise level
    T = forward(model, q)
    assert np.abs(T[:, :3, 3] - data.measured[:, :3, 3]).max() < 0.03
    # predict with the file reproduces the model's poses (6 decimals mm, 8 decimals deg)
    rc, out, err = run(capsys, "predict", out_file, joints)
    assert rc == 0, err
    lines = out.strip().splitlines()
    assert lines[0] == "x [mm],y [mm],z [mm],roll [deg],pitch [deg],yaw [deg]"
    pred = np.array([[float(v) for v in line.split(",")] for line in lines[1:]])
    ref = matrix_to_pose(T)
    ref[:, 3:] = np.degrees(ref[:, 3:])
    np.testing.assert_allclose(pred, ref, atol=2e-6)
    # json and base frame
    rc, out, _ = run(capsys, "predict", out_file, joints, "--base", "--json")
    d = json.loads(out)
    assert d["frame"] == "base"
    np.testing.assert_allclose(d["poses_mm_rad"], matrix_to_pose(forward(model, q, setup=False)), atol=1e-9)


def test_identify_text_and_objectives(capsys, pose_file):
    f, _, _, _ = pose_file
    rc, out, _ = run(capsys, "identify", f, "--sigma-position", 5, "--sigma-angle", 5)
    assert rc == 0
    assert "identified 20 of 36 parameters of sr800 from 30 pose measurements" in out and "converged" in out
    # it says what was fitted: registration, unit check, condition, left-out parameters, outliers
    for text in ("registration:", "unit check: consistent", "condition of the fitted set",
                 "left out (16)", "A4.z ≡ +1·R.z", "suspected outliers: none"):
        assert text in out, text
    rc, out, _ = run(capsys, "identify", f, "--objective", "position", "--json")
    assert rc == 0 and len(json.loads(out)["parameters"]) == 17
    rc, out, _ = run(capsys, "identify", f, "--objective", "distance", "--json")
    d = json.loads(out)
    assert rc == 0 and len(d["parameters"]) == 11 and d["n_measurements"] == 30 * 29 // 2
    assert d["pairs"] == {"strategy": "cap", "count": 435, "points": 30}
    rc, out, _ = run(capsys, "identify", f, "--objective", "distance", "--pairs", "independent", "--json")
    assert rc == 0 and json.loads(out)["n_measurements"] == 15


def test_identify_json_keys_carry_units(capsys, pose_file):
    f, _, _, _ = pose_file
    rc, out, _ = run(capsys, "identify", f, "--json")
    d = json.loads(out)
    assert rc == 0 and "units" in d
    for v in d["parameters"].values():
        assert set(v) in ({"value_mm", "sigma_um"}, {"value_rad", "value_deg", "sigma_arcsec"})
    assert {x["name"] for x in d["left_out"]} | set(d["parameters"]) == set(load_robot("sr800").param_names)
    assert d["registration"]["similarity_scale"] == pytest.approx(1.0, abs=0.01)
    assert d["unit_check"].startswith("consistent") and d["condition"] > 1
    assert d["suspected_outlier_rows"] == []


@pytest.mark.parametrize("unit,factor", [("m", 1e-3), ("inch", 1 / 25.4), ("µm", 1e3)])
def test_identify_refuses_wrong_length_unit(capsys, pose_file, tmp_path, unit, factor):
    f, _, _, _ = pose_file
    lines = f.read_text().splitlines()
    out_lines = []
    for line in lines:
        if line.startswith("#") or line.startswith("q1"):
            out_lines.append(line)
            continue
        v = line.split(",")
        v[4:7] = [repr(float(x) * factor) for x in v[4:7]]
        out_lines.append(",".join(v))
    g = _write(tmp_path, "wrong_unit.csv", "\n".join(out_lines) + "\n")
    rc, _, err = run(capsys, "identify", g)
    assert rc == 2 and f"look like {unit}, not mm" in err, err


def test_validate_and_export_model(capsys, pose_file, tmp_path):
    f, joints, q, data = pose_file
    model_file = tmp_path / "id.toml"
    rc, _, err = run(capsys, "identify", f, "-o", model_file)
    assert rc == 0, err
    rc, out, err = run(capsys, "validate", model_file, f, "--json")
    assert rc == 0, err
    d = json.loads(out)
    assert d["model_errors"]["rms_position_um"] < 30 and len(d["per_row"]) == 30
    assert d["nominal_errors"]["rms_position_um"] > 5 * d["model_errors"]["rms_position_um"]
    rc, out, _ = run(capsys, "validate", model_file, f)
    assert rc == 0 and "improvement" in out and "worst rows" in out
    for fmt, suffix in (("mdh", ".mdh.csv"), ("urdf-new", ".urdf"), ("dh", ".dh.csv"), ("toml", ".toml")):
        target = tmp_path / f"exported{suffix}"
        rc, out, err = run(capsys, "export-model", model_file, "--format", fmt, "-o", target, "--json")
        assert rc == 0, err
        e = json.loads(out)
        assert e["max_position_difference_um"] >= 0 and target.exists()
        if fmt in ("urdf-new", "toml"):
            assert e["exact"] is True
        else:  # tilted parallel axes: DH states what it loses
            assert e["exact"] or any("cannot hold" in n for n in e["notes"])


def test_bom_is_read(capsys, pose_file, tmp_path):
    f, _, _, _ = pose_file
    g = tmp_path / "bom.csv"
    g.write_bytes(b"\xef\xbb\xbf" + f.read_bytes())
    rc, out, err = run(capsys, "identify", g, "--json")
    assert rc == 0, err


def test_identify_flags_outlier(capsys, pose_file, tmp_path):
    f, _, _, _ = pose_file
    lines = f.read_text().splitlines()
    row = lines[12].split(",")  # comment, header, then data row 11 (1-based)
    row[4] = repr(float(row[4]) + 1.0)
    lines[12] = ",".join(row)
    g = tmp_path / "outlier.csv"
    g.write_text("\n".join(lines) + "\n")
    rc, out, _ = run(capsys, "identify", g, "--sigma-position", 5, "--sigma-angle", 5)
    assert rc == 0
    assert "suspected outliers (rows): 11" in out


# --- bad input -----------------------------------------------------------------------------------------

def _write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


GOOD_ROW = "10,20,-50,5,800,300,400,0,0,30"


@pytest.mark.parametrize("case,argv_fn,pattern", [
    ("unknown parameter", lambda f, t: ["identify", f, "--prefer", "A9.x"], "unknown parameter 'A9.x'"),
    ("malformed csv", lambda f, t: ["identify", _write(t, "m.csv", ",".join(POSE_HEADER) + "\n" + GOOD_ROW + "\n1,2,3\n")],
     "line 3: 3 values but 10 columns"),
    ("missing unit", lambda f, t: ["identify", _write(t, "u.csv", "q1,q2 [deg],q3 [mm],q4 [deg],x [mm],y [mm],z [mm]\n1,2,3,4,5,6,7\n")],
     "column 'q1' has no unit"),
    ("wrong joint count", lambda f, t: ["identify", _write(t, "j.csv", "q1 [deg],q2 [deg],q3 [mm],x [mm],y [mm],z [mm]\n1,2,3,5,6,7\n1,2,3,5,6,7\n")],
     "has 4 joints; expected columns q1, q2, q3, q4"),
    ("nan", lambda f, t: ["identify", _write(t, "n.csv", ",".join(POSE_HEADER) + "\n" + GOOD_ROW + "\n" + GOOD_ROW.replace("800", "nan") + "\n")],
     "line 3: x is nan"),
    ("not a number", lambda f, t: ["identify", _write(t, "s.csv", ",".join(POSE_HEADER) + "\n" + GOOD_ROW.replace("300", "3OO") + "\n")],
     "y = '3OO' is not a number"),
    ("wrong unit kind", lambda f, t: ["identify", _write(t, "k.csv", "q1 [deg],q2 [deg],q3 [deg],q4 [deg],x [mm],y [mm],z [mm]\n1,2,3,4,5,6,7\n")],
     "q3 is a prismatic joint and needs mm or m"),
    ("nonexistent file", lambda f, t: ["identify", t / "missing.csv"], "missing.csv: no such file"),
    ("unknown robot", lambda f, t: ["identify", f, "--robot", "sr900"], "'sr900' is neither a built-in robot"),
    ("unknown robot predict", lambda f, t: ["predict", "nope", f], "'nope' is neither a built-in robot"),
    ("position file, pose objective", lambda f, t: ["identify", _write(t, "p.csv", "q1 [deg],q2 [deg],q3 [mm],q4 [deg],x [mm],y [mm],z [mm]\n1,2,3,4,5,6,7\n1,2,3,4,5,6,7\n"), "--objective", "pose"],
     "holds positions only"),
    ("garbage data", lambda f, t: ["identify", _write(t, "g.csv", ",".join(POSE_HEADER) + "\n" + "\n".join(
        f"{i},{2 * i},-{i},{i},{(-1) ** i * 1000},{i * 37 % 500},{i},{i * 10},{-i},{i * 7}" for i in range(1, 31)) + "\n")],
     "joint order"),
])
def test_bad_inputs_exit_nonzero_without_traceback(capsys, pose_file, tmp_path, case, argv_fn, pattern):
    f, _, _, _ = pose_file
    rc, out, err = run(capsys, *argv_fn(f, tmp_path))
    assert rc != 0, case
    assert err.startswith("station: error: ")
    assert pattern in err, err
    assert "Traceback" not in err + out


def test_exit_codes_by_error_type(capsys, pose_file, tmp_path):
    from station.errors import ConfigError, IdentificationError

    f, _, _, _ = pose_file
    rc, _, _ = run(capsys, "identify", tmp_path / "missing.csv")
    assert rc == ConfigError.outcome == 2
    g = _write(tmp_path, "g.csv", ",".join(POSE_HEADER) + "\n" + "\n".join(
        f"{i},{2 * i},-{i},{i},{(-1) ** i * 1000},{i * 37 % 500},{i},{i * 10},{-i},{i * 7}" for i in range(1, 31)) + "\n")
    rc, _, _ = run(capsys, "identify", g)
    assert rc == IdentificationError.outcome == 3


def test_argparse_errors_exit_2(capsys):
    assert main(["identify"]) == 2  # main() returns a usage error's code (and JSON with --json)
    assert "the following arguments are required: data" in capsys.readouterr().err


def test_console_script_subprocess():
    r = subprocess.run([sys.executable, "-m", "station.ui.cli.main", "--help"], cwd=ROOT,
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0
    for cmd in ("analyze", "identify", "predict", "study"):
        assert cmd in r.stdout
    r = subprocess.run([sys.executable, "-m", "station.ui.cli.main", "analyze", "--robot", "nope"], cwd=ROOT,
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2
    assert "station: error:" in r.stderr and "Traceback" not in r.stderr


def test_reidentify_from_identified_file(capsys, pose_file, tmp_path):
    f, _, _, _ = pose_file
    out_file = tmp_path / "first.toml"
    rc, out, _ = run(capsys, "identify", f, "-o", out_file, "--sigma-position", 5, "--sigma-angle", 5, "--json")
    first = json.loads(out)
    rc, out, err = run(capsys, "identify", f, "--robot", out_file, "--sigma-position", 5,
                       "--sigma-angle", 5, "--json")
    assert rc == 0, err
    second = json.loads(out)
    assert second["rms_normalized"] == pytest.approx(first["rms_normalized"], rel=1e-3)
    worst = max(v.get("sigma_um", 0.0) for v in second["parameters"].values())
    assert worst < 10 * max(v.get("sigma_um", 0.0) for v in first["parameters"].values())
