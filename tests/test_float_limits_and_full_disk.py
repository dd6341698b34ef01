"""Issue 33, inputs: data at the float limits, joints beyond physical plausibility, a header-only
joints file and a full disk are each refused with a typed error (exit 2) and a message that says
what to change — never an internal error, never exit 0 with poses of z = 1e308 or "RMS inf µm"."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from station.ui.cli.main import main

JOINTS = "q1 [deg],q2 [deg],q3 [mm],q4 [deg]\n"
POSES = "q1 [deg],q2 [deg],q3 [mm],q4 [deg],x [mm],y [mm],z [mm],roll [deg],pitch [deg],yaw [deg]\n"
GOOD_POSE = "10,45,-50,0,812.331,402.118,431.072,0.0012,-0.0031,55.0004\n"


def _run(capsys, *argv: object) -> tuple[int, str]:
    capsys.readouterr()
    rc = main([str(a) for a in argv])
    out = capsys.readouterr()
    text = out.out + out.err
    assert "Traceback" not in text and "internal error" not in text, text
    return rc, text


@pytest.mark.parametrize("row, what", [
    ("1e308,0,0,0", "q1 = 1e308 deg is beyond physical plausibility (at most ±3600 deg"),
    ("0,0,1e300,0", "q3 = 1e300 mm is beyond physical plausibility (at most ±100000 mm = 100 m)"),
    ("0,-1e308,0,0", "q2 = -1e308 deg"),
    ("0,0,0,1.7976931348623157e308", "q4 = 1.7976931348623157e308 deg"),
])
def test_absurd_joints_are_refused_by_predict_and_analyze(tmp_path, capsys, row, what):
    f = tmp_path / "j.csv"
    f.write_text(JOINTS + row + "\n")
    for argv in (("predict", "sr800", f), ("analyze", "--robot", "sr800", "--joints", f)):
        rc, text = _run(capsys, *argv)
        assert rc == 2 and what in text and "line 2" in text, (argv, text)


def test_joints_at_the_small_float_limits_are_values_like_any(tmp_path, capsys):
    f = tmp_path / "j.csv"
    f.write_text(JOINTS + "5e-324,-0.0,-1e-320,2.2250738585072014e-308\n")
    rc, text = _run(capsys, "predict", "sr800", f)
    assert rc == 0 and "nan" not in text.lower() and "inf" not in text.lower(), text


def test_a_header_only_joints_file_is_refused(tmp_path, capsys):
    f = tmp_path / "j.csv"
    f.write_text(JOINTS)
    for argv in (("predict", "sr800", f), ("analyze", "--robot", "sr800", "--joints", f)):
        rc, text = _run(capsys, *argv)
        assert rc == 2 and "a header but no rows" in text, (argv, text)


@pytest.mark.parametrize("calibration", [False, True])
def test_validate_on_data_of_1e308_is_refused(tmp_path, capsys, calibration):
    """Was ``LinAlgError`` (internal error), and with --calibration "RMS inf µm", exit 0."""
    bad = tmp_path / "bad.csv"
    bad.write_text(POSES + GOOD_POSE + "10,45,-50,0,1e308,1e308,1e308,0,0,55\n")
    good = tmp_path / "good.csv"
    good.write_text(POSES + GOOD_POSE * 3)
    argv = ("validate", "sr800", good, "--calibration", bad) if calibration else ("validate", "sr800", bad)
    rc, text = _run(capsys, *argv)
    assert rc == 2 and "x = 1e308 mm is beyond physical plausibility" in text, text


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs /dev/full (Linux)")
@pytest.mark.parametrize("fmt", ["toml", "urdf-new", "dh"])
def test_export_model_to_a_full_disk_is_refused(capsys, fmt):
    """Was ``OSError: [Errno 28] No space left on device`` (internal error)."""
    rc, text = _run(capsys, "export-model", "sr800", "--format", fmt, "-o", "/dev/full")
    assert rc == 2 and "/dev/full: cannot write it (No space left on device)" in text, text
    assert "free space" in text


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs /dev/full (Linux)")
def test_a_full_disk_anywhere_is_not_a_bug(monkeypatch, capsys):
    """The last line of defence (main): ENOSPC without a file name is the operator's, exit 2."""
    import station.ui.cli.commands_core as core

    def full(args):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(core, "cmd_predict", full)
    rc, text = _run(capsys, "predict", "sr800", "x.csv")
    assert rc == 2 and "No space left on device; free space on the disk" in text, text


def test_export_model_to_a_missing_folder_names_it(tmp_path, capsys):
    out = tmp_path / "no" / "such" / "m.toml"
    rc, text = _run(capsys, "export-model", "sr800", "--format", "toml", "-o", out)
    assert rc == 2 and str(out) in text, text
    assert not Path(out).exists()
