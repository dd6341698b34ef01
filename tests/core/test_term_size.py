"""A kept term's physical size with σ, judged against the robot's class (issue 38,
station/core/terms/term_size.py): the class from the robot file's reach, the joint stiffness a
compliance with masses implies, and a gear error no robot reducer has refused as implausible."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from simulators.joint_errors import JointErrors
from simulators.six_axis_cell import six_axis_truth
from simulators.truth_kinematics import true_forward
from station.core.identification.identify import identify
from station.core.kinematics.poses import spread_joints
from station.core.measurement.measurements import MeasurementSet, add_noise
from station.core.terms.error_model import GravityModel, TermSpec
from station.core.terms.selection import select_model
from station.core.terms.term_size import GEAR_MAX_RAD, robot_class
from station.io.robot.formats import read_dh_file

ROOT = Path(__file__).resolve().parents[2]
ARCSEC = np.radians(1 / 3600)


def test_the_class_follows_the_robot_files_reach():
    fanuc, _ = read_dh_file(ROOT / "benchmarks" / "data" / "fanuc_r2000ic_165f.dh.csv")
    ur10e, _ = read_dh_file(ROOT / "benchmarks" / "data" / "ur10e.dh.csv")
    assert robot_class(fanuc).name == "heavy" and 2600 < robot_class(fanuc).reach_mm < 3200
    assert robot_class(ur10e, 12.5).name == "medium" and robot_class(ur10e, 12.5).payload_kg == 12.5
    assert robot_class(ur10e).payload_kg is None


def _data(errs: JointErrors, seed: int = 4, n: int = 80):
    truth = six_axis_truth(seed)
    model, p = truth.model, truth.params
    kinds = [t.joint for t in model.transforms]
    rng = np.random.default_rng(seed)
    q = spread_joints(model, n, rng)
    pts = true_forward(kinds, p, q + errs.delta(model, p, q))[:, :3, 3]
    d = MeasurementSet("position", q, pts, np.array([0.015] * 3))
    return model, d.with_measured(add_noise(d, pts, rng))


def test_a_compliance_with_the_files_masses_says_its_joint_stiffness_and_is_plausible():
    errs = JointErrors(compliance=(0.0, 4e-7, 6e-7, 0.0, 0.0, 0.0), masses=((2, 60.0), (4, 25.0)), payload_kg=5.0)
    model, data = _data(errs)
    spec = TermSpec(gravity=GravityModel(masses=(0.0, 0.0, 60.0, 0.0, 25.0, 0.0), payload_kg=5.0))
    sel = select_model(model, data, spec=spec, geometric=identify(model, data), force=("compliance",))
    sizes = {z.joint: z for z in sel.sizes}
    assert set(sizes) >= {2, 3} and all(z.kind == "gravity sag" and z.plausible for z in sizes.values())
    for j, c in ((2, 4e-7), (3, 6e-7)):
        k, sk = sizes[j].stiffness  # type: ignore[misc]
        assert abs(k - 1 / c) < 4 * sk + 0.05 / c  # the simulated stiffness, within its σ
        assert sizes[j].sigma_rad > 0 and sizes[j].tool_mm > 0
    d = sel.to_dict()
    assert d["robot_class"]["class"] == "medium" and d["term_sizes"][0]["plausible"] is True
    assert d["term_sizes"][0]["units"]["largest_turn_arcsec"] == "″"
    assert "gravity sag: up to" in sel.summary


def test_a_gear_error_no_reducer_has_is_implausible():
    big = 10 * 60 * ARCSEC  # 10 arcmin once per turn of joint 2: three times the 3 arcmin limit and more
    model, data = _data(JointErrors(cyclic=((0.0, 0.0), (big, 0.0), (0.0, 0.0), (0.0, 0.0), (0.0, 0.0), (0.0, 0.0))))
    sel = select_model(model, data, geometric=identify(model, data), force=("cyclic.q2",))
    (z,) = sel.sizes
    assert z.kind == "cyclic" and z.joint == 2 and abs(z.turn_rad) > GEAR_MAX_RAD and not z.plausible
    assert "IMPLAUSIBLE" in sel.summary
    small = 20 * ARCSEC
    model, data = _data(JointErrors(cyclic=((0.0, 0.0), (small, 0.0), (0.0, 0.0), (0.0, 0.0), (0.0, 0.0), (0.0, 0.0))))
    sel = select_model(model, data, geometric=identify(model, data), force=("cyclic.q2",))
    assert all(z.plausible for z in sel.sizes) and "IMPLAUSIBLE" not in sel.summary


def test_identify_json_gives_the_class_and_the_sizes_with_units(tmp_path, capsys):
    import json

    from station.core.terms.error_model import apply_terms, term_basis
    from station.io.datafile import write_csv
    from station.io.robot.files import load_robot
    from station.ui.cli.main import main

    arm = load_robot("irb2600")
    rng = np.random.default_rng(38)
    q = spread_joints(arm, 60, rng)
    basis = term_basis(arm, q, TermSpec(("compliance",)))
    pts = apply_terms(arm, q, arm.nominal, basis, np.array([3e-5, 4e-5]))[:, :3, 3]
    d = MeasurementSet("position", q, pts, np.array([0.015] * 3))
    f = tmp_path / "cal.csv"
    write_csv(f, [f"q{i} [deg]" for i in range(1, 7)] + ["x [mm]", "y [mm]", "z [mm]"],
              np.column_stack([np.degrees(q), add_noise(d, pts, rng)]))
    assert main(["identify", str(f), "--robot", "irb2600", "--model", "compliance", "--json"]) == 0
    em = json.loads(capsys.readouterr().out)["error_model"]
    assert em["robot_class"]["class"] == "medium" and em["robot_class"]["units"]["reach_mm"] == "mm"
    sizes = {z["joint"]: z for z in em["term_sizes"]}
    assert set(sizes) == {2, 3} and all(z["kind"] == "gravity sag" and z["plausible"] for z in sizes.values())
    assert all(z["sigma_arcsec"] > 0 and z["units"]["tool_mm"] == "mm" for z in sizes.values())
    assert "sizes (medium arm" in em["summary"]
