"""``station identify --model …`` (issue 30): the model chosen by the data, on the command line."""

from __future__ import annotations

import json

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


@pytest.fixture(scope="module")
def bent_file(tmp_path_factory):
    """60 tracker positions of an arm whose shoulder and elbow bend under gravity."""
    rng = np.random.default_rng(21)
    true = perturbed(ARM, rng, StudyInputs())
    folder = tmp_path_factory.mktemp("model")
    for name, n in (("bent.csv", 60), ("held.csv", 40)):  # the fit's data and held-out data
        q = spread_joints(ARM, n, rng)
        basis = term_basis(ARM, q, TermSpec(("compliance",)))
        pts = apply_terms(ARM, q, true, basis, np.array([3e-6, 4e-6]))[:, :3, 3]
        d = MeasurementSet("position", q, pts, np.array([0.015] * 3))
        write_csv(folder / name, HEADER, np.column_stack([np.degrees(q), add_noise(d, pts, rng)]))
    return folder / "bent.csv"


def run(capsys, *argv):
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def test_identify_model_auto_json_keeps_compliance_with_units(bent_file, capsys):
    rc, out, err = run(capsys, "identify", bent_file, "--robot", "irb2600", "--model", "auto", "--json")
    assert rc == 0, err
    em = json.loads(out)["error_model"]
    assert em["chosen"] == ["compliance"]
    assert em["table"][0]["model"] == "geometric" and em["table"][0]["cv_rms_um"] > 0
    kept = [r for r in em["table"] if r["kept"] and r["terms"]]
    assert kept and kept[-1]["change_pct"] < -30 and kept[-1]["p_value"] < 0.01
    assert {t["name"] for t in em["terms"]} == {"compliance.q2", "compliance.q3"}
    assert all(t["unit"] and t["sigma"] > 0 for t in em["terms"])
    assert em["units"]["cv_rms_um"] == "µm"
    assert {i["family"] for i in em["identifiability"]} == {"compliance"}


def test_identify_text_forced_model_and_default(bent_file, capsys):
    rc, out, _ = run(capsys, "identify", bent_file, "--robot", "irb2600", "--model", "compliance+drift")
    assert rc == 0
    assert "model forced: geometric + compliance + drift" in out
    assert "compliance.q2" in out and "drift.x" in out and "identifiability compliance: rank 2 of 2" in out
    rc, out, _ = run(capsys, "identify", bent_file, "--robot", "irb2600")
    assert rc == 0 and "model:" not in out  # the geometric fit alone, as before


def test_identify_unknown_term_is_refused(bent_file, capsys):
    rc, _, err = run(capsys, "identify", bent_file, "--robot", "irb2600", "--model", "thermal")
    assert rc == 2 and "unknown error term 'thermal'" in err
    rc, _, err = run(capsys, "identify", bent_file, "--robot", "irb2600", "--model", "auto", "--loss", "huber")
    assert rc == 2 and "--model geometric" in err


def test_identified_terms_travel_in_the_robot_file(bent_file, tmp_path, capsys):
    """identify --output keeps the terms in [error_terms]; predict applies them; MDH says what it loses."""
    from station.core.kinematics.forward import forward
    from station.core.terms.error_model import prediction_basis
    from station.io.robot.files import load_robot
    from station.io.robot.terms import read_error_terms

    out = tmp_path / "bent.toml"
    rc, _, err = run(capsys, "identify", bent_file, "--robot", "irb2600", "--model", "auto", "-o", out)
    assert rc == 0, err
    terms = read_error_terms(out)
    assert terms is not None and terms.families == ("compliance",)
    assert terms.names == ("compliance.q2", "compliance.q3") and all(s > 0 for s in terms.sigma)
    model = load_robot(out)  # the schema knows [error_terms]
    q = spread_joints(ARM, 5, np.random.default_rng(3))
    joints = tmp_path / "j.csv"
    write_csv(joints, [f"q{i} [deg]" for i in range(1, 7)], np.degrees(q))
    rc, text, err = run(capsys, "predict", out, joints, "--json")
    assert rc == 0, err
    pred = np.array(json.loads(text)["poses_mm_rad"])[:, :3]
    basis, _ = prediction_basis(model, q, terms.families, terms.names)
    moved = forward(model, q + basis.joint_delta(np.array(terms.values)))[:, :3, 3]
    np.testing.assert_allclose(pred, moved, atol=1e-9)
    assert np.max(np.linalg.norm(pred - forward(model, q)[:, :3, 3], axis=1)) > 0.05  # the terms matter here
    rc, text, _ = run(capsys, "export-model", out, "--format", "mdh", "-o", tmp_path / "bent.mdh.csv", "--json")
    assert rc == 0
    assert any("not written in MDH" in n and "geometric fit of the same data" in n and "µm RMS" in n
               for n in json.loads(text)["notes"])
    assert terms.geometric_params is not None and terms.effect_on_fit_um is not None and terms.effect_on_fit_um > 5
    rc, _, _ = run(capsys, "export-model", out, "--format", "urdf-new", "-o", tmp_path / "bent.urdf")
    assert rc == 0
    urdf = load_robot(tmp_path / "bent.urdf")  # URDF holds any geometry: here the geometric fit, exactly
    np.testing.assert_allclose(forward(urdf, q)[:, :3, 3], forward(model, q, np.array(terms.geometric_params))[:, :3, 3],
                               atol=1e-6)
    rc, _, _ = run(capsys, "export-model", out, "--format", "toml", "-o", tmp_path / "again.toml")
    assert rc == 0 and read_error_terms(tmp_path / "again.toml") == terms


def test_backlash_and_drift_from_the_file_columns(tmp_path, capsys):
    """A file with approach1 … approach6 [sign] and time [min]: auto finds the lost motion of joints 2
    and 3 (arriving from either side) and leaves the drift out, which the data do not show."""
    from station.core.terms.error_model import TermRows

    rng = np.random.default_rng(5)
    true = perturbed(ARM, rng, StudyInputs())
    q = spread_joints(ARM, 60, rng)
    signs = rng.choice([-1.0, 1.0], size=q.shape)
    basis = term_basis(ARM, q, TermSpec(("backlash",)), TermRows(approach=signs))
    x = np.zeros(basis.size)
    x[[basis.names.index("backlash.q2"), basis.names.index("backlash.q3")]] = [2e-4, 3e-4]  # 41″, 62″
    pts = apply_terms(ARM, q, true, basis, x)[:, :3, 3]
    d = MeasurementSet("position", q, pts, np.array([0.015] * 3))
    f = tmp_path / "lost.csv"
    header = HEADER + [f"approach{j} [sign]" for j in range(1, 7)] + ["time [min]"]
    write_csv(f, header, np.column_stack([np.degrees(q), add_noise(d, pts, rng), signs, np.arange(60) * 0.5]))
    rc, out, err = run(capsys, "identify", f, "--robot", "irb2600", "--model", "auto", "--json")
    assert rc == 0, err
    em = json.loads(out)["error_model"]
    assert em["chosen"] == ["backlash"]
    vals = {t["name"]: t for t in em["terms"]}
    for name, v in (("backlash.q2", 2e-4), ("backlash.q3", 3e-4)):
        assert abs(vals[name]["value"] - v) < 4 * vals[name]["sigma"]
    assert any(r["terms"] == ["drift"] and not r["kept"] for r in em["table"])
    signs[0, 0] = 0.5
    write_csv(f, header, np.column_stack([np.degrees(q), pts, signs, np.arange(60) * 0.5]))
    rc, _, err = run(capsys, "identify", f, "--robot", "irb2600", "--model", "auto")
    assert rc == 2 and "+1 or -1" in err


def test_compensate_lands_a_robot_with_error_terms_on_its_targets(tmp_path, capsys):
    """A robot file with [error_terms]: the commands, solved by the controller's nominal IK, put the
    robot, which stands at q + Δq(q), on the wanted poses to a micrometre."""
    import csv
    import math

    from station.core.kinematics.forward import forward
    from station.core.kinematics.ik import ArmConfig, solve_ik
    from station.core.kinematics.model import robot_to_toml
    from station.core.kinematics.transforms import matrix_to_pose, pose_error, pose_to_matrix
    from station.core.terms.error_model import prediction_basis
    from station.io.robot.terms import error_terms_toml

    rng = np.random.default_rng(9)
    ident = perturbed(ARM, rng, StudyInputs())
    ident[:6] = 0.0
    fams, names = ("compliance", "cyclic.q2"), ("compliance.q2", "compliance.q3", "cyclic.q2.cos1", "cyclic.q2.sin1")
    values = (2e-6, 3e-6, 1e-4, -6e-5)
    model_file = tmp_path / "m.toml"
    model_file.write_text(robot_to_toml(ARM, ident, angle_unit="rad")
                          + error_terms_toml(fams, names, values, (0.0,) * 4, ("",) * 4))
    q = spread_joints(ARM, 12, rng)
    q[:, 4] = np.sign(q[:, 4]) * np.maximum(np.abs(q[:, 4]), 0.3)

    def stands(qq):
        return qq + prediction_basis(ARM, qq, fams, names)[0].joint_delta(np.array(values))

    P = forward(ARM, stands(q), ident, setup=False)  # where the user wants the tool
    lines = ["x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg"]
    lines += [",".join([f"{v:.9f}" for v in p[:3]] + [f"{math.degrees(v):.12f}" for v in p[3:]])
              for p in matrix_to_pose(P)]
    (tmp_path / "t.csv").write_text("\n".join(lines) + "\n")
    rc, out, err = run(capsys, "compensate", model_file, tmp_path / "t.csv", "-o", tmp_path / "o.csv", "--json")
    assert rc == 0, err
    summary = json.loads(out)
    assert summary["error_terms"] == list(names) and summary["max_residual_um"] < 1e-3
    with open(tmp_path / "o.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    C = pose_to_matrix(np.array([[float(r["x_mm"]), float(r["y_mm"]), float(r["z_mm"]),
                                  math.radians(float(r["roll_deg"])), math.radians(float(r["pitch_deg"])),
                                  math.radians(float(r["yaw_deg"]))] for r in rows]))
    cfg = [ArmConfig(*(int(r[k] or 0) for k in ("shoulder", "elbow", "wrist"))) for r in rows]
    ctl = solve_ik(ARM, C, ARM.nominal, configuration=cfg)  # the controller keeps its nominal model
    assert np.all(ctl.has_joints)
    e = pose_error(forward(ARM, stands(ctl.joints), ident, setup=False), P)
    assert np.linalg.norm(e[:, :3], axis=1).max() < 1e-3  # ≤ 1 µm
    # without the terms the same commands would miss by what the terms move
    e_geo = pose_error(forward(ARM, ctl.joints, ident, setup=False), P)
    assert np.linalg.norm(e_geo[:, :3], axis=1).max() > 0.05


def test_link_masses_from_the_robot_file_give_compliance_in_rad_per_newton_metre(tmp_path, capsys):
    """[gravity] in the robot file: the compliance term's torques come from its masses (N·m), the
    fitted compliances are the true ones, and the identified file keeps the table."""
    from station.core.kinematics.model import robot_to_toml
    from station.core.terms.error_model import GravityModel
    from station.io.robot.terms import gravity_toml, read_error_terms, read_gravity

    gm = GravityModel(masses=(0.0, 90.0, 40.0, 0.0, 0.0, 0.0),
                      com=((0.0, 0.0, 0.0), (0.0, -350.0, 0.0), (400.0, -60.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                           (0.0, 0.0, 0.0)), payload_kg=10.0, payload_com=(0.0, 0.0, 50.0))
    robot = tmp_path / "arm.toml"
    robot.write_text(robot_to_toml(ARM, angle_unit="rad") + gravity_toml(gm))
    assert read_gravity(robot, 6) == gm
    rng = np.random.default_rng(12)
    true = perturbed(ARM, rng, StudyInputs())
    q = spread_joints(ARM, 60, rng)
    basis = term_basis(ARM, q, TermSpec(("compliance",), gm))
    assert basis.names == ("compliance.q2", "compliance.q3") and basis.units[0] == "rad/(N·m)"
    x = np.array([5e-7, 8e-7])  # rad/(N·m): stiffness 2·10⁶ and 1.25·10⁶ N·m/rad
    pts = apply_terms(ARM, q, true, basis, x)[:, :3, 3]
    d = MeasurementSet("position", q, pts, np.array([0.015] * 3))
    f = tmp_path / "heavy.csv"
    write_csv(f, HEADER, np.column_stack([np.degrees(q), add_noise(d, pts, rng)]))
    out = tmp_path / "identified.toml"
    rc, text, err = run(capsys, "identify", f, "--robot", robot, "--model", "compliance", "--json", "-o", out)
    assert rc == 0, err
    terms = {t["name"]: t for t in json.loads(text)["error_model"]["terms"]}
    for name, v in zip(("compliance.q2", "compliance.q3"), x):
        assert terms[name]["unit"] == "rad/(N·m)" and abs(terms[name]["value"] - v) < 4 * terms[name]["sigma"]
    assert read_gravity(out, 6) == gm and read_error_terms(out) is not None
    robot.write_text(robot_to_toml(ARM, angle_unit="rad") + "\n[gravity]\nmasses_kg = [1, 2]\n")
    rc, _, err = run(capsys, "identify", f, "--robot", robot, "--model", "compliance")
    assert rc == 2 and "one mass" in err


def test_validate_applies_the_terms_of_the_model_file(bent_file, tmp_path, capsys):
    """Held-out data of the bending arm: the model with its terms meets them at the noise; the same
    geometry without them misses by what the arm bends."""
    with_terms, geometric = tmp_path / "auto.toml", tmp_path / "geo.toml"
    assert run(capsys, "identify", bent_file, "--robot", "irb2600", "--model", "auto", "-o", with_terms)[0] == 0
    assert run(capsys, "identify", bent_file, "--robot", "irb2600", "-o", geometric)[0] == 0
    held = bent_file.with_name("held.csv")
    rc, out, err = run(capsys, "validate", with_terms, held, "--robot", "irb2600", "--json")
    assert rc == 0, err
    auto = json.loads(out)
    assert any("error terms of the model applied: compliance.q2, compliance.q3" in n for n in auto["notes"])
    rc, out, _ = run(capsys, "validate", geometric, held, "--robot", "irb2600", "--json")
    geo = json.loads(out)
    assert auto["model_errors"]["rms_position_um"] < 40.0  # 15 µm per coordinate: 26 µm
    assert auto["model_errors"]["rms_position_um"] < 0.5 * geo["model_errors"]["rms_position_um"]


def test_the_written_model_reproduces_the_fit_with_an_unknown_marker(tmp_path, capsys):
    """A marker 150 mm off the flange (--tool unknown): the terms' torques are taken at the identified
    geometry, so the written model with its terms meets its own data as the fit did."""
    rng = np.random.default_rng(31)
    true = perturbed(ARM, rng, StudyInputs())
    true[-6:-3] += [60.0, -40.0, 130.0]  # the marker, far from the robot file's tool point
    q = spread_joints(ARM, 60, rng)
    basis = term_basis(ARM, q, TermSpec(("compliance",)), params=true)
    pts = apply_terms(ARM, q, true, basis, np.array([3e-5, 4e-5]))[:, :3, 3]  # a heavy arm's sag
    d = MeasurementSet("position", q, pts, np.array([0.015] * 3))
    f = tmp_path / "marker.csv"
    write_csv(f, HEADER, np.column_stack([np.degrees(q), add_noise(d, pts, rng)]))
    out = tmp_path / "m.toml"
    rc, _, err = run(capsys, "identify", f, "--robot", "irb2600", "--tool", "unknown", "--model", "compliance",
                     "-o", out)
    assert rc == 0, err
    rc, text, err = run(capsys, "validate", out, f, "--robot", "irb2600", "--json")
    assert rc == 0, err
    assert json.loads(text)["model_errors"]["rms_position_um"] < 1.1 * np.sqrt(3) * 15.0  # at the noise, as the fit


def test_payload_per_row_loads_the_compliance_term(tmp_path, capsys):
    """A payload [kg] column: rows carrying 0, 25 or 50 kg bend the arm by as much more; the fit takes
    each row's payload into its torques and recovers the compliances (without the column it cannot)."""
    from station.core.kinematics.model import robot_to_toml
    from station.core.terms.error_model import GravityModel, TermRows
    from station.io.robot.terms import gravity_toml

    gm = GravityModel(masses=(0.0, 90.0, 40.0, 0.0, 0.0, 0.0), payload_com=(0.0, 0.0, 80.0))
    robot = tmp_path / "arm.toml"
    robot.write_text(robot_to_toml(ARM, angle_unit="rad") + gravity_toml(gm))
    rng = np.random.default_rng(14)
    true = perturbed(ARM, rng, StudyInputs())
    q = spread_joints(ARM, 60, rng)
    payload = rng.choice([0.0, 25.0, 50.0], size=60)
    basis = term_basis(ARM, q, TermSpec(("compliance",), gm), TermRows(payload_kg=payload))
    x = np.array([5e-7, 8e-7])
    pts = apply_terms(ARM, q, true, basis, x)[:, :3, 3]
    d = MeasurementSet("position", q, pts, np.array([0.015] * 3))
    f = tmp_path / "loads.csv"
    write_csv(f, HEADER + ["payload [kg]"], np.column_stack([np.degrees(q), add_noise(d, pts, rng), payload]))
    rc, text, err = run(capsys, "identify", f, "--robot", robot, "--model", "compliance", "--json")
    assert rc == 0, err
    em = json.loads(text)["error_model"]
    terms = {t["name"]: t for t in em["terms"]}
    for name, v in zip(("compliance.q2", "compliance.q3"), x):
        assert abs(terms[name]["value"] - v) < 4 * terms[name]["sigma"]
    with_column = em["table"][-1]["cv_rms_um"]
    write_csv(f, HEADER, np.column_stack([np.degrees(q), d.measured]))  # the same rows, payload unknown
    rc, text, _ = run(capsys, "identify", f, "--robot", robot, "--model", "compliance", "--json")
    assert rc == 0 and json.loads(text)["error_model"]["table"][-1]["cv_rms_um"] > 1.5 * with_column


def test_gear_ratios_make_the_harmonics_cycle_with_the_motor(tmp_path, capsys):
    """[gears] ratios: the error of joint 2 cycles three times per joint turn; the fit finds it there
    (a harmonic of the joint angle would not), and the written model predicts with it."""
    from station.core.kinematics.forward import forward
    from station.core.kinematics.model import robot_to_toml
    from station.io.robot.terms import gears_toml, read_gear_ratios

    ratios = (1.0, 3.0, 1.0, 1.0, 1.0, 1.0)
    robot = tmp_path / "geared.toml"
    robot.write_text(robot_to_toml(ARM, angle_unit="rad") + gears_toml(ratios))
    assert read_gear_ratios(robot, 6) == ratios
    rng = np.random.default_rng(17)
    true = perturbed(ARM, rng, StudyInputs())
    q = spread_joints(ARM, 80, rng)
    basis = term_basis(ARM, q, TermSpec(("cyclic.q2",), ratios=ratios))
    x = np.array([2e-4, -1e-4])
    pts = apply_terms(ARM, q, true, basis, x)[:, :3, 3]
    d = MeasurementSet("position", q, pts, np.array([0.015] * 3))
    f = tmp_path / "geared.csv"
    write_csv(f, HEADER, np.column_stack([np.degrees(q), add_noise(d, pts, rng)]))
    out = tmp_path / "id.toml"
    rc, text, err = run(capsys, "identify", f, "--robot", robot, "--model", "auto", "--json", "-o", out)
    assert rc == 0, err
    em = json.loads(text)["error_model"]
    assert em["chosen"] == ["cyclic.q2"]
    terms = {t["name"]: t["value"] for t in em["terms"]}
    np.testing.assert_allclose([terms["cyclic.q2.cos1"], terms["cyclic.q2.sin1"]], x, atol=2e-5)
    assert read_gear_ratios(out, 6) == ratios
    joints = tmp_path / "j.csv"
    write_csv(joints, [f"q{i} [deg]" for i in range(1, 7)], np.degrees(q[:4]))
    rc, text, _ = run(capsys, "predict", out, joints, "--json")
    pred = np.array(json.loads(text)["poses_mm_rad"])[:, :3]
    assert rc == 0 and np.max(np.linalg.norm(pred - pts[:4], axis=1)) < 0.1  # near the truth, terms included
    assert np.max(np.linalg.norm(forward(ARM, q[:4], true)[:, :3, 3] - pts[:4], axis=1)) > 0.1


def test_study_with_terms_sets_the_linear_sigma_beside_the_monte_carlo_scatter(capsys):
    """Issue 30, "linear σ and Monte Carlo cover the new parameters": ``station study --model`` fits
    the geometry and the terms together on synthetic poses and compares each term's linear σ with
    the scatter over noisy copies (100 sets: the sample σ itself scatters by ~7 %)."""
    assert main(["study", "--robot", "sr800", "--model", "cyclic", "--sets", "100", "--json"]) == 0
    study = json.loads(capsys.readouterr().out)["studies"][0]
    figs = study["figures"]
    assert figs["terms"] == ["cyclic.q1.cos1", "cyclic.q1.sin1", "cyclic.q2.cos1", "cyclic.q2.sin1",
                             "cyclic.q4.cos1", "cyclic.q4.sin1"]  # the quill is prismatic: no harmonic
    lo, hi = figs["ratio_mc_linear_terms"]
    assert 0.75 < lo <= hi < 1.3 and figs["bias_within_4_sigma"] and figs["monte_carlo_failed"] == 0
    assert main(["study", "--robot", "sr800", "--model", "drift"]) == 2
    assert "describe a measurement run" in capsys.readouterr().err
