"""A converged fit is plausible or refused (issue 36, §3): distinct joint values modulo a turn, the
identified robot against its file's geometry in the same gauge, and the refusal's words.

The real tracker data (FANUC R-2000iC/165F, Boby & Klimchik, 36 nest poses) carry no licence and
are not kept here (benchmarks/data/README.md): the tests on them run where
``STATION_BOBY_KLIMCHIK`` names a clone of github.com/RABKKK/LaserTrackerPoseData4KinIdent."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from station.core.identification.identify import identify
from station.core.identification.plausibility import (
    few_angle_joints,
    joint_angle_counts,
    plausibility,
    require_plausible,
)
from station.core.kinematics.forward import forward
from station.core.kinematics.poses import spread_joints
from station.core.kinematics.transforms import matrix_to_pose, pose_to_matrix
from station.core.measurement.measurements import MeasurementSet, synthetic_set
from station.errors import IdentificationError
from station.io.datafile import read_measurement_file
from station.io.robot.formats import read_dh_file

ROOT = Path(__file__).resolve().parents[2]
ARM6 = Path(__file__).parent / "data" / "arm6_fixture.dh.csv"
FANUC = ROOT / "benchmarks" / "data" / "fanuc_r2000ic_165f.dh.csv"
BOBY = os.environ.get("STATION_BOBY_KLIMCHIK")
NEST_HEADER = ("q1 [deg],q2 [deg],q3 [deg],q4 [deg],q5 [deg],q6 [deg],x1 [mm],y1 [mm],z1 [mm],x2 [mm],y2 [mm],"
               "z2 [mm],x3 [mm],y3 [mm],z3 [mm]")


def test_a_revolute_joint_counts_its_angles_modulo_a_turn():
    model, _ = read_dh_file(ARM6)
    q = np.zeros((7, model.n_joints))
    q[:, 3] = np.radians([-360.0, 0.0, 360.0, 0.0, -360.0, 720.0, 0.0])  # one angle
    q[:, 0] = np.radians([0.0, 359.95, 10.0, 10.02, 20.0, 20.0, 0.0])  # 0 and 359.95 meet across the wrap
    q[:, 1] = np.radians([0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
    counts = joint_angle_counts(model, q)
    assert counts[3] == 1 and counts[0] == 3 and counts[1] == 7 and counts[2] == 1
    assert (4, 1) in few_angle_joints(model, q) and (1, 3) not in few_angle_joints(model, q)


def _placed(model, rng, shift_mm=(1393.0, -3660.0, 700.0), yaw_deg=22.0):
    """A robot with errors of a real arm's size, seen by an instrument metres away and turned."""
    true = np.array(model.nominal, dtype=float)
    true[6:-6] += rng.normal(0.0, 0.3, true[6:-6].shape) * np.tile([1, 1, 1, 1e-3, 1e-3, 1e-3], model.n_params // 6 - 2)
    T = pose_to_matrix(np.array([*shift_mm, 0.01, -0.02, np.radians(yaw_deg)])) @ pose_to_matrix(true[:6])
    true[:6] = matrix_to_pose(T)
    return true


def test_a_good_fit_far_from_the_instrument_is_plausible():
    """Set-up metres away and turned 22°: the parameters that carry it move by metres, the robot
    does not; the comparison in the same gauge sees only the robot's own sub-millimetre errors."""
    model, _ = read_dh_file(ARM6)
    rng = np.random.default_rng(36)
    true = _placed(model, rng)
    q = spread_joints(model, 40, rng)
    data = synthetic_set(model, "pose", q, true, rng=rng)
    res = identify(model, data)
    moved = np.abs(res.estimates - model.nominal[res.chosen_index])
    assert moved.max() > 100.0  # something carries the set-up by metres: a direct comparison would refuse it
    p = plausibility(model, data, res.params, res.chosen, res.uncertainty.sigma)
    assert p.ok and p.compared and p.workspace_mm < 2.0
    assert max(abs(d) for n, (d, lim) in p.deviations.items() if n[-1] in "xyz") < 2.0


def test_a_link_moved_by_centimetres_is_refused_with_its_name_value_and_sigma():
    model, _ = read_dh_file(ARM6)
    rng = np.random.default_rng(7)
    true = _placed(model, rng)
    q = spread_joints(model, 40, rng)
    data = synthetic_set(model, "pose", q, true, rng=rng)
    res = identify(model, data)
    wrong = res.params.copy()
    name = next(n for n in res.chosen if n.startswith("A3.") and n[-1] in "xy")
    wrong[model.param_index(name)] += 45.0  # a link 45 mm longer while σ says micrometres
    p = plausibility(model, data, wrong, res.chosen, res.uncertainty.sigma)
    assert not p.ok and p.implausible[0].name == name
    assert p.implausible[0].deviation == pytest.approx(45.0, abs=1.0)
    assert p.workspace_mm > 10.0
    with pytest.raises(IdentificationError) as e:
        require_plausible(model, data, wrong, res.chosen, res.uncertainty.sigma)
    msg = str(e.value)
    k = res.chosen.index(name)
    assert name in msg and f"{wrong[model.param_index(name)]:.3f} mm" in msg
    assert f"σ {res.uncertainty.sigma[k] * 1e3:.3g} µm" in msg and "Likely cause" in msg
    assert e.value.exit_code == 3


def _fanuc(tmp: Path):
    """The FANUC's nest positions read as ``station identify`` reads them (the data file of
    ``benchmarks/bench_real_data.py``: the minimal set's choice among near-equal columns follows
    the last digit, so the test takes the same digits as the command)."""
    model, jmap = read_dh_file(FANUC)
    a = np.loadtxt(Path(BOBY) / "N1N2N3Jval.csv")  # type: ignore[arg-type]
    f = tmp / "fanuc_nest.csv"
    np.savetxt(f, np.column_stack([a[:, 15:21], a[:, :9]]), delimiter=",", header=NEST_HEADER, comments="",
               fmt="%.10g")
    mf = read_measurement_file(f, model)
    data = MeasurementSet("position", jmap.to_model(mf.joints), mf.measured[:, :3, 3], np.array([0.015] * 3))
    return model, data, a[:, 18]


#: the minimal set the station chose on the FANUC's poses with joint 4 at one angle before the set-up
#: joined every minimal set (issue 36, commits 2c9dee4 and 1cee999): A1.pitch, A2.z and A2.yaw where
#: the set-up's R.z, R.pitch and R.yaw stand now. With it the fit converges to another branch
OLD_CHOSEN = ("R.x", "R.y", "R.roll", "A1.pitch", "A2.x", "A2.z", "A2.roll", "A2.yaw", "A3.x", "A3.y", "A3.roll",
              "A3.pitch", "A4.x", "A4.roll", "A5.z", "A5.yaw", "A6.x", "A6.y", "A6.z", "A6.roll", "A6.yaw", "K.x", "K.y")


def _held_out_mm(model, data, rows, params) -> float:
    miss = forward(model, data.joints[rows], params)[:, :3, 3] - data.measured[rows]
    return float(np.sqrt(np.mean(np.sum(miss**2, axis=1))))


@pytest.mark.skipif(not BOBY, reason="real tracker data not kept here: set STATION_BOBY_KLIMCHIK to a clone")
def test_real_tracker_data_with_joint_4_at_one_angle_is_refused_naming_the_cause(tmp_path):
    """The FANUC's nest positions without its joint-4 sweep (−360°, 0°, +360° only). Fitted with the
    minimal set chosen before the set-up joined every set, a geometric fit converges with σ of tens of
    µm and misses the other poses by ~200 mm: it is refused, naming joint 4. The station's own choice
    now (set-up first) stays on the robot's branch: 3 mm from its file over the joint ranges, as with
    every joint measured, and ~2 mm off at joint-4 angles the data never visited (the axis the data
    cannot place, left at the file's): plausible, and flagged (identify's note says the model holds
    where joint 4 stood only). The same robot with every joint measured, or with joint 4 at two
    angles beside the wrap, is plausible."""
    model, data, q4 = _fanuc(tmp_path)
    one = np.nonzero(~np.isin(np.abs(q4), (72.0, 216.0)))[0]
    held = np.setdiff1d(np.arange(len(q4)), one)
    assert few_angle_joints(model, data.joints[one]) == ((4, 1),)
    silent = identify(model, data.subset(one), tool_unknown=True, chosen=OLD_CHOSEN)
    assert silent.converged and silent.uncertainty.sigma.max() < 0.1  # σ says micrometres
    assert _held_out_mm(model, data, held, silent.params) > 50.0  # the silent model this test is about
    with pytest.raises(IdentificationError) as e:
        require_plausible(model, data.subset(one), silent.params, silent.chosen, silent.uncertainty.sigma)
    assert "joint 4 stands at 1 distinct angle modulo a turn" in str(e.value)
    own = identify(model, data.subset(one), tool_unknown=True)
    assert own.converged and own.chosen[:6] == ("R.x", "R.y", "R.z", "R.roll", "R.pitch", "R.yaw")
    p = plausibility(model, data.subset(one), own.params, own.chosen, own.uncertainty.sigma)
    assert p.ok and p.workspace_mm < 5.0 and p.few_angles == ((4, 1),)
    assert _held_out_mm(model, data, held, own.params) < 5.0
    for rows in (np.arange(len(q4)), np.nonzero(~np.isin(q4, (72.0, -72.0, -216.0)))[0]):
        ok = identify(model, data.subset(rows), tool_unknown=True)
        p = plausibility(model, data.subset(rows), ok.params, ok.chosen, ok.uncertainty.sigma)
        assert p.ok and p.workspace_mm < 5.0
