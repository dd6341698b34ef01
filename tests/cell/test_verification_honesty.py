"""Verification measures what the robot does (issue 18, section 1).

A touch whose probes come near their stroke end is re-centred: the robot is moved onto the corner
and read again. The reading then shows where the robot was moved to; the re-centring's move must
be counted in the verification error, the same way before, after and with the oracle, or a robot
far off reads as accurate (the issue's "before" of 24 µm for a robot off by > 430 µm).

The example cell examples/scara_arc (a 550 mm SCARA, an 8-probe head read within 0.5 mm of
mid-stroke, twelve cubes on an arc) re-centres its "before" touches: its reported "before" is compared with the
simulator's truth, pose by pose.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from station.cell.config.cell_config import load_config
from station.cell.pipeline.results import reference_params, verification_errors
from station.cell.plan.measurement_plan import head_targets_world, joints_for
from station.cell.plan.steps import StepKind
from station.cell.records.reading.stored_config import stored_plan
from station.cell.records.rundb import RunDB
from station.cell.records.summary import ErrorStats, RecentringStats, RunSummary
from station.cell.run.recentring import RESULT_KEY, RecentringLog, head_as_commanded, stored_recentring
from station.cell.run.runner import (
    Checkpoint,
    MoveCartesian,
    MoveJoints,
    ReadJoints,
    ReadProbes,
    RecentReadings,
    Settle,
    approach_and_read,
    head_of,
)
from station.core.kinematics.forward import forward
from station.core.kinematics.transforms import invert, matrix_to_pose, pose_to_matrix
from station.core.probe.geometry import readings_from_pose
from station.errors import Outcome
from station.ui.cli.main import main

ARC = Path(__file__).resolve().parents[2] / "examples" / "scara_arc" / "cell.toml"


# --- one touch, on a robot with a known error ---------------------------------------------

def _touch(cfg, point: int, error_world_mm: np.ndarray, cartesian: bool):
    """Run one reading of ``approach_and_read`` against a robot that puts the head
    ``error_world_mm`` off wherever it is commanded (exact probe readings)."""
    geom = head_of(cfg)
    R = pose_to_matrix(cfg.model.nominal[:6])
    corner = cfg.body_points[point]
    target = head_targets_world(cfg)[point]
    q = joints_for(cfg, target, 1)[0]
    T_base = invert(R) @ target
    proc = approach_and_read(cfg, q, 1, cartesian=(matrix_to_pose(T_base), 1) if cartesian else None)
    commanded = {"T": forward(cfg.model, q[None], setup=False)[0]}
    shift = np.eye(4)
    shift[:3, 3] = error_world_mm
    value = None
    n_channels = int(geom.probe_channels.max())
    try:
        while True:
            msg = proc.send(value)
            value = None
            if isinstance(msg, MoveJoints) and msg.q is not None:
                commanded["T"] = forward(cfg.model, np.asarray(msg.q)[None], setup=False)[0]
            elif isinstance(msg, MoveCartesian):
                commanded["T"] = pose_to_matrix(msg.pose)
            elif isinstance(msg, ReadProbes):
                head = shift @ R @ commanded["T"]
                s = readings_from_pose(geom, invert(head) @ corner)
                v = np.zeros(n_channels)
                v[geom.probe_channels - 1] = s / geom.probe_scales
                value = SimpleNamespace(raw=b"", values_mm=v, status=["ok"] * n_channels)
            elif isinstance(msg, ReadJoints):
                value = q
            elif isinstance(msg, RecentReadings):
                value = ()
            else:
                assert isinstance(msg, (Checkpoint, MoveJoints, Settle)), msg
    except StopIteration as stop:
        return stop.value, corner, target


@pytest.mark.parametrize("cartesian", [True, False])
def test_a_re_centred_touch_keeps_the_robots_error(cartesian):
    cfg = load_config(ARC)
    e = np.array([1.2, -1.1, 0.3])  # beyond the 0.5 mm the cell reads without re-centring
    reading, corner, target = _touch(cfg, 5, e, cartesian)
    assert reading.ok and reading.recentring is not None
    assert "re-centred" in reading.message
    measured = corner @ invert(reading.pose)
    # read where it was moved to, the robot looks on target; moved back, it shows its error
    assert np.linalg.norm(measured[:3, 3] - target[:3, 3]) < 0.05
    honest = head_as_commanded(measured, reading.recentring)
    np.testing.assert_allclose(honest[:3, 3] - target[:3, 3], e, atol=2e-3)


def test_a_touch_within_the_stroke_is_not_re_centred():
    reading, corner, target = _touch(load_config(ARC), 5, np.array([0.05, 0.0, 0.0]), True)
    assert reading.ok and reading.recentring is None and "re-centred" not in reading.message
    np.testing.assert_allclose((corner @ invert(reading.pose))[:3, 3] - target[:3, 3], [0.05, 0, 0], atol=1e-6)


def test_the_displacement_is_stored_before_its_measurement_and_replaced_with_it(tmp_path):
    with RunDB(tmp_path / "runs.sqlite") as db:
        run = db.create_run("x = 1", [{"kind": "identification"}] * 3)
        log = RecentringLog(db, run)
        log.record(0, None)
        assert db.load_result(run, RESULT_KEY, default=None) is None  # nothing re-centred: nothing written
        log.record(1, np.array([0.5, 0, 0, 0, 0, 0.001]))
        log.record(2, np.array([0.1, 0.2, 0, 0, 0, 0]))
        RecentringLog(db, run).record(2, None)  # step 2 measured again, without re-centring
        moved = stored_recentring(db, run)
        assert set(moved) == {1} and moved[1][0] == pytest.approx(0.5)


def test_summary_says_how_many_readings_were_re_centred_and_explains_rp():
    rc = (RecentringStats("identification", 216, 30, 2100.0, 1900.0),
          RecentringStats("verification_before", 120, 120, 1640.0, 1620.0),
          RecentringStats("verification_after", 120, 0))
    rng = np.random.default_rng(0)
    before = ErrorStats.from_errors({(f"P{i}", 1): 0.5 + rng.normal(0, 0.005, (5, 3)) for i in range(24)})
    after = ErrorStats.from_errors({(f"P{i}", 1): rng.normal(0, 0.005, (5, 3)) for i in range(24)})
    assert before.cycles == 5 and before.n_poses == 24 and before.rp_mean_um > 0
    s = RunSummary(Outcome.SUCCESS, before=before, after=after, recentring=rc)
    text = s.recentring_text()
    assert "before 120 of 120 (up to 1640 µm)" in text and "after 0 of 120" in text
    assert "identification 30 of 216" in text and "counted in the error" in text
    assert RunSummary.from_json(json.loads(json.dumps(s.to_json()))) == s
    assert "cannot be told from the scatter" in s.rp_text() and "5 cycles at each of 24 poses" in s.rp_text()
    # a robot that really repeats worse after the correction is not explained away
    worse = ErrorStats.from_errors({(f"P{i}", 1): rng.normal(0, 0.02, (5, 3)) for i in range(24)})
    assert "repeated worse" in s.replace(after=worse).rp_text()
    assert RunSummary(Outcome.SUCCESS).recentring_text() is None


# --- the example arc cell against the simulator's truth -------------------------------------

def _truth_before_um(cfg, db: RunDB, run: int, truth) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per verification-before measurement: the reported error, the truth's error for the
    commanded target, and the error as read without the re-centring's move [µm] (each (n, 3))."""
    steps = stored_plan(db, run)
    R_id = np.asarray(db.load_result(run, "identification")["params"])[:6]
    records = db.measurements(run, kind=StepKind.VERIFY_BEFORE.value)
    reported = verification_errors(cfg, steps, records, stored_recentring(db, run))
    as_read = verification_errors(cfg, steps, records)
    heads = head_targets_world(cfg)
    p_true = reference_params(cfg, truth)  # the true robot as the station approaches it
    rep, tru, raw = [], [], []
    for key, e in reported.items():
        st = next(s for s in steps if s.kind is StepKind.VERIFY_BEFORE and (s.point_id, s.elbow) == key)
        q = joints_for(cfg, heads[st.point], st.elbow, R_id)[0]  # what the controller runs, no table
        t = forward(cfg.model, q[None], params=p_true, setup=True)[0][:3, 3] - heads[st.point][:3, 3]
        rep.append(e)
        tru.append(np.broadcast_to(t, e.shape))
        raw.append(as_read[key])
    return (np.concatenate(rep) * 1e3, np.concatenate(tru) * 1e3, np.concatenate(raw) * 1e3)


def _rougher_arc_cell(tmp_path: Path) -> Path:
    """examples/scara_arc with a robot 4× as far from its file as the example simulates: since the
    set-up carries what the body cannot tell from it (issue 36), "before" is the robot's own error
    (174 µm on seed 2, inside the ±0.5 mm the head reads), so nothing was re-centred there; a
    rougher robot puts "before" beyond the window again (748 µm, every reading re-centred)."""
    for f in ARC.parent.iterdir():
        if f.is_file():
            shutil.copy(f, tmp_path / f.name)
    cell = tmp_path / ARC.name
    text = cell.read_text()
    assert "\nseed = 1\n" in text
    text = text.replace("\nseed = 1\n", "\nseed = 1\nlength_sigma_um = 160.0\nangle_sigma_arcsec = 600.0\n", 1)
    # one visit per identification pose and two verification cycles (the example: 3 and 5): what is
    # judged is each "before" reading against the truth, which one cycle shows as well as five
    # (the suite's time, issue 42; the accuracy of the full plan is benchmarks/bench_table_design.py's)
    assert "\nrepeats = 3\n" in text and "\nverification_cycles = 5\n" in text
    cell.write_text(text.replace("\nrepeats = 3\n", "\nrepeats = 1\n", 1)
                    .replace("\nverification_cycles = 5\n", "\nverification_cycles = 2\n", 1))
    return cell


@pytest.mark.slow
# Seed 2: every "before" reading is re-centred there (the old calculation read 9.7 µm for 1627 µm).
# One seed keeps the suite short.
@pytest.mark.parametrize("seed", [2])
@pytest.mark.slow  # an end-to-end session: the slow tier (README), run by CI
def test_the_arc_cell_rehearses_with_an_honest_before(seed, tmp_path, capsys):
    from simulators.from_config import simulated_cell_for

    arc = _rougher_arc_cell(tmp_path)
    db_path = tmp_path / "runs.sqlite"
    code = main(["calibrate", "--simulated", str(arc), "--json", "--seed", str(seed), "--db", str(db_path)])
    out = json.loads(capsys.readouterr().out)
    assert code == 0, out.get("failure")
    assert out["robot"] == "scara550"
    assert out["gain"] >= 20.0 and 0.7 <= out["after_vs_oracle"] <= 1.2, out["after_vs_oracle"]
    assert out["after"]["rms_um"] < 30.0, out["after"]  # µm
    kinds = {r["kind"]: r for r in out["recentring"]}
    assert kinds["verification_before"]["n_recentred"] > 0  # the case of the issue: "before" re-centred

    cfg = load_config(arc)
    with RunDB(db_path) as db:
        reported, truth, as_read = _truth_before_um(cfg, db, out["run_id"], simulated_cell_for(cfg, seed).truth)
    half_stroke_um = float(np.min(head_of(cfg).strokes)) / 2 * 1e3
    err = np.linalg.norm(truth, axis=1)
    # at most poses the robot is off by more than the cell reads without re-centring
    assert np.median(err) > half_stroke_um - cfg.plan.recenter_margin_mm * 1e3
    # "before" within the measurement noise of the truth (joint repeatability, probe noise, body σ) …
    diff = np.linalg.norm(reported - truth, axis=1)
    assert np.sqrt(np.mean(diff**2)) < 15.0 and diff.max() < 40.0
    assert out["before"]["rms_um"] == pytest.approx(np.sqrt(np.mean(err**2)), rel=0.02)
    # … where the re-centred readings as taken would have hidden most of it
    moved = np.linalg.norm(reported - as_read, axis=1) > 1.0
    assert moved.sum() == kinds["verification_before"]["n_recentred"]
    rms = lambda a: float(np.sqrt(np.mean(np.sum(a**2, axis=1))))  # noqa: E731
    assert rms(as_read[moved]) < 0.2 * rms(reported[moved])
