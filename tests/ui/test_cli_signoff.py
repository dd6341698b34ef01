"""The engineer at a terminal (issue 20, CLI): results on stdout and progress on stderr, no empty
phase headers, AP/RP as ISO 9283 names them, a readable ``station check`` that exits 7 on an
invalid wired probe, the plan's implausible-σ warning, an export ``station identify`` reads,
reports per database, the tool table's bound, no NaN from export-model, joints in deg / mm and
"too close" naming the joint, side and margin."""

from __future__ import annotations

import json
import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from drivers.controller_status import ControllerStatus
from drivers.probe_protocol import ChannelStatus, DeviceInfo
from simulators import start_simulated_cell
from simulators.reference_cell import cell_config_text
from station.cell.limits.joint_text import joint_values, nearest_limit
from station.cell.limits.motion_guard import MotionGuard
from station.cell.pipeline.outcomes import classify
from station.cell.run.device_check import ProbeChannelsInvalid, controller_lines, probe_lines, wired_channels_invalid
from station.errors import Outcome, UnreachableError
from station.ui.cli.commands_cell import plan_warnings, report_dir
from station.ui.cli.main import main


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory, seed1_run):
    """One simulated calibration of the built-in cell from the command line, its streams apart (the
    suite's seed-1 run, tests/conftest.py; the database copied, since the tests export beside it)."""
    tmp = tmp_path_factory.mktemp("signoff")
    run = seed1_run.copy_to(tmp, db_name="cell-a.sqlite")
    return SimpleNamespace(code=run.code, out=run.out, err=run.err, db=run.db, tmp=tmp)


def test_the_summary_goes_to_stdout_and_the_progress_to_stderr(calibrated):
    assert calibrated.code == 0
    out, err = calibrated.out, calibrated.err
    assert "SUCCESS (exit code 0)" in out and "improvement ×" in out
    assert "[measure]" in err and "[measure]" not in out and "SUCCESS (exit code" not in err
    # no empty phase header: every "[phase]" line says what the phase does
    headers = [ln for ln in err.splitlines() if re.match(r"^\[\w+\]", ln)]
    assert headers and all(re.match(r"^\[\w+\] \S", ln) for ln in headers), headers
    assert any(ln.startswith("[identify] identifying") for ln in headers)
    # AP / RP as ISO 9283 defines them, the worst pose's, no "≤" that reads as a bound
    assert "AP≤" not in out and "RP≤" not in out
    assert "AP µm, worst pose" in out and "RP µm, worst pose" in out and "ISO 9283" in out
    after = next(ln for ln in out.splitlines() if ln.strip().startswith("after "))
    assert len(re.findall(r"\d+\.\d", after)) == 4  # RMS, max, AP, RP


def test_json_keeps_stdout_for_the_one_object(seed1_not_uploaded):
    """calibrate --simulated --no-upload --json (and --report): the suite's run, tests/conftest.py."""
    code, out, err = seed1_not_uploaded.code, seed1_not_uploaded.out, seed1_not_uploaded.err
    assert code == 11
    doc = json.loads(out)  # the whole of stdout is one JSON object
    assert doc["outcome"] == "NOT_UPLOADED" and "NOT_UPLOADED (exit code 11)" in err


def test_export_writes_a_pose_file_that_identify_reads(calibrated, capsys):
    db, tmp = str(calibrated.db), calibrated.tmp
    assert main(["export", "--db", db, str(tmp / "record.csv")]) == 0
    assert "--format identify" in capsys.readouterr().out  # the record says how to get the pose file
    pose_file = tmp / "poses.csv"
    assert main(["export", "--db", db, "--format", "identify", str(pose_file)]) == 0
    said = capsys.readouterr().out
    assert f"station identify {pose_file} --robot sr800" in said
    header = next(ln for ln in pose_file.read_text().splitlines() if not ln.startswith("#"))
    assert header.startswith("q1 [deg],q2 [deg],q3 [mm],q4 [deg],x [mm]")
    assert main(["identify", str(pose_file)]) == 0
    # the run's own identification again: a residual at the probes' noise level (µm, not mm)
    residual = re.search(r"RMS position residual (\d+\.\d) µm", capsys.readouterr().out)
    assert residual and float(residual.group(1)) < 30.0


def test_reports_are_named_after_their_database(tmp_path):
    a, b = report_dir(tmp_path / "cell-a.sqlite", 3), report_dir(tmp_path / "cell-b.sqlite", 3)
    assert a == tmp_path / "report-cell-a-run-3" and b == tmp_path / "report-cell-b-run-3" and a != b
    from station.ui.report.paths import report_dir as tui_report_dir

    assert tui_report_dir(tmp_path / "cell-a.sqlite", 3) == a  # one rule for the CLI and the UI


def test_export_model_never_writes_nan():
    from station.io.export import model_files as robot_export
    from station.io.robot.files import load_robot

    model = load_robot("sr800")
    p = np.array(model.nominal, dtype=float)
    p[6 * 2 + 3] += 3e-9  # a tilt between axes 1 and 2 below what doubles resolve
    res = robot_export.export_model(model, "mdh", p)
    text = " ".join(res.notes)
    assert "nan" not in text.lower() and "written as parallel" in text and "0.000619″" in text
    assert "nan" not in res.text.lower()


# --- station check -------------------------------------------------------------------------

HEAD = SimpleNamespace(probe_ids=("T1", "T2", "X1"), probe_channels=(1, 2, 4))


def test_the_check_table_names_each_wired_probe_and_leaves_the_unwired_channel_out():
    statuses = [ChannelStatus.OK, ChannelStatus.INVALID, ChannelStatus.INVALID, ChannelStatus.UNDER_RANGE]
    lines = probe_lines("/dev/ttyUSB0", DeviceInfo("DL-RS1A", "1.2", 4), statuses, HEAD)
    text = "\n".join(lines)
    assert "DeviceInfo(" not in text and "ChannelStatus." not in text
    assert lines[0] == "probe head /dev/ttyUSB0: DL-RS1A, firmware 1.2, 4 channels; 3 probes wired"
    assert re.search(r"T2 +2 +invalid", text) and re.search(r"X1 +4 +under range", text)
    assert "channel 3: not wired" in text
    err = wired_channels_invalid(statuses, HEAD)  # channel 3 is invalid too, but nothing is wired there
    assert isinstance(err, ProbeChannelsInvalid) and "T2 (channel 2)" in str(err) and "channel 3" not in str(err)
    assert classify(err) is Outcome.DEVICE_FAULT and err.exit_code == 7
    ok = [ChannelStatus.OK, ChannelStatus.OK, ChannelStatus.INVALID, ChannelStatus.OVER_RANGE]
    assert wired_channels_invalid(ok, HEAD) is None  # a free plunger out of range is no fault


def test_the_controller_reads_in_words_and_its_joints_in_deg_and_mm():
    st = ControllerStatus(ack_seq=0, done_seq=0, error_seq=0, error_code=0, bits=5, error_joint=0, error_bound=0)
    lines = controller_lines("127.0.0.1:502", st, [0.0, np.pi / 2, -6.0, 0.0],
                             ("revolute", "revolute", "prismatic", "revolute"), 2, 128)
    text = "\n".join(lines)
    assert "ControllerStatus(" not in text and "1.5708" not in text
    assert "ready" in lines[0] and "no error" in lines[0]
    assert "joints: 0.00°, 90.00°, -6.0 mm, 0.00°" in text and "register map 2 at base 128" in text


def test_station_check_exits_7_when_a_wired_probe_reads_invalid(tmp_path, capsys):
    srv = start_simulated_cell(seed=2)
    try:
        cfg = tmp_path / "sim.toml"
        cfg.write_text(cell_config_text(srv, 2))
        # parked in the air, the plungers rest at their stops: over range, no fault
        assert main(["check", str(cfg)]) == 0
        assert "read invalid" not in capsys.readouterr().out
        srv.probe_server.faults.force_status(1, ChannelStatus.INVALID)  # a wired channel's sensor fails
        code = main(["check", str(cfg)])
    finally:
        srv.stop()
    out = capsys.readouterr().out
    assert code == 7
    assert "FAILED: 1 of the head's" in out and "wired probes read invalid: " in out
    # words for people: no Python type name, no repr (issue 33)
    assert "ProbeChannelsInvalid" not in out and "DeviceInfo(" not in out and "ControllerStatus(" not in out
    assert re.search(r"joints: -?\d+\.\d\d°", out)


# --- plan, limits, joint units ----------------------------------------------------------------

def test_the_plan_warns_of_an_implausible_predicted_accuracy():
    cfg = SimpleNamespace(identification=SimpleNamespace(sigma_position_um=15.0), point_ids=("C1.a", "C1.b", "C1.c"))
    every = tuple(SimpleNamespace(step=SimpleNamespace(point_id=pid)) for pid in cfg.point_ids)  # each point measured
    bad = SimpleNamespace(sigma_position_um=(386130.6, 386130.6, 386130.6), condition=298233.2, steps=every)
    (w,) = plan_warnings(bad, cfg)
    assert "386130.6 µm" in w and "sigma_position_um = 15 µm" in w and "[body]" in w and "3 measuring points" in w
    fine = SimpleNamespace(sigma_position_um=(9.0, 10.0, 12.0), condition=30.0, steps=every)
    assert plan_warnings(fine, cfg) == []


def test_the_scara600_plan_has_no_warning_and_names_the_tightest_joint(capsys):
    assert main(["plan", str(Path(__file__).resolve().parents[2] / "examples/scara600/cell.toml")]) == 0
    out = capsys.readouterr().out
    assert "warning" not in out
    assert re.search(r"smallest margin to a soft limit: \d+\.\d\d(°| mm) \(joint \d\)", out)


def test_too_close_names_the_joint_side_and_margin():
    kinds = ("revolute", "revolute", "prismatic")
    lim = np.array([[-np.pi / 2, np.pi / 2], [-np.pi, np.pi], [-200.0, 0.0]])
    q = np.array([0.0, np.pi - np.radians(1.0), -100.0])
    near = nearest_limit(q, lim, kinds, required=np.radians([3.0, 3.0, 0.0]))
    text = near.describe(np.radians(3.0))
    assert text == "joint 2 is 1.00° inside its upper soft limit 180.00° (the plan keeps at least 3.00°)"
    assert nearest_limit([np.nan, 0, 0], lim, kinds) is None
    assert joint_values(q, kinds) == "0.00°, 179.00°, -100.0 mm"


def test_the_motion_guard_speaks_in_the_robot_files_units():
    guard = MotionGuard(np.array([[-np.pi / 2, np.pi / 2], [-200.0, 0.0]]), joint_types=("revolute", "prismatic"))
    with pytest.raises(UnreachableError, match=r"joint 1 = 95\.00° is 5\.00° beyond its upper soft limit 90\.00°"):
        guard.check_joints([np.radians(95.0), -10.0], "step 1")
    with pytest.raises(UnreachableError, match=r"joint 2 = -210\.0 mm is 10\.0 mm beyond its lower soft limit"):
        guard.check_joints([0.0, -210.0], "step 1")
