"""The station as a process among others (issue 19): closed pipes, stop signals at any moment,
``--json`` answering usage errors, and command-line values refused before anything starts.

Every test runs ``python -m station.ui.cli.main`` as a subprocess on the built-in simulated cell at
time scale 0, and checks the exit code, the one JSON object on stdout and the run database.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from station.cell.records.reading.run_list import committed_steps
from station.cell.records.rundb import RunDB
from station.core.kinematics.poses import spread_joints
from station.core.kinematics.transforms import matrix_to_pose
from station.core.measurement.measurements import synthetic_set
from station.io.datafile import write_csv
from station.io.robot.files import load_robot

ROOT = Path(__file__).resolve().parents[2]
ENV = dict(os.environ, PYTHONPATH=str(ROOT))
STATION = [sys.executable, "-m", "station.ui.cli.main"]
SHORT = ["calibrate", "--simulated", "--no-upload", "--json"]  # NOT_UPLOADED (11) when it completes
ABORTED, CONFIG_ERROR, NOT_UPLOADED = 6, 2, 11
# a hang guard, not a speed target: a whole simulated session as a subprocess takes ~35 s near idle
# but 120 s and more beside two CPU hogs on 2 cores (issue 42: the three full-run tests here failed
# at 120.0 s), so each wait stops just short of pytest's own 600 s guard (pyproject's timeout)
HANG_S = 540


def _popen(args, cwd: Path, **kw) -> subprocess.Popen:
    kw.setdefault("stdout", subprocess.PIPE)
    kw.setdefault("stderr", subprocess.PIPE)
    return subprocess.Popen([*STATION, *map(str, args)], cwd=cwd, env=ENV, text=True, **kw)


def _one_json(out: str) -> dict:
    lines = [ln for ln in out.splitlines() if ln.strip()]
    assert len(lines) == 1, f"expected exactly one JSON object on stdout, got {out!r}"
    obj: dict = json.loads(lines[0])
    return obj


def _status(db: Path, run_id: int) -> str:
    with RunDB(db) as rdb:
        return rdb.run(run_id).status


def _no_internal_error(cwd: Path, err: str) -> None:
    assert "Traceback" not in err and "internal error" not in err and "BrokenPipe" not in err, err
    assert not list(cwd.glob("station-error-*.log")), "an internal-error log was written"


def _handlers_installed(pid: int) -> bool:
    """The process catches SIGTERM now (Linux: SigCgt in /proc/PID/status)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("SigCgt:"):
                return bool(int(line.split()[1], 16) & (1 << (signal.SIGTERM - 1)))
    except OSError:
        pass
    return False


def _short(cell: Path) -> list:
    """``calibrate --simulated CELL --no-upload --json``: NOT_UPLOADED (11) when it completes."""
    return ["calibrate", "--simulated", cell, "--no-upload", "--json"]


# --- closed and broken pipes ---------------------------------------------------------------------

def test_stdout_and_stderr_into_head_the_run_completes_and_is_stored(tmp_path, short_cell):
    """``station calibrate --simulated --json 2>&1 | head -n 3``: the first lines reach head, the
    rest is dropped, and the run ends SUCCESS in the run database with exit code 0."""
    db = tmp_path / "runs.sqlite"
    script = (f"{' '.join(STATION)} calibrate --simulated {short_cell} --json --db {db} 2>&1 | head -n 3 > head.txt; "
              f"echo ${{PIPESTATUS[0]}} > rc.txt")
    subprocess.run(["bash", "-c", script], cwd=tmp_path, env=ENV, check=True, timeout=HANG_S)
    assert (tmp_path / "rc.txt").read_text().strip() == "0"
    assert len((tmp_path / "head.txt").read_text().splitlines()) == 3
    assert _status(db, 1) == "verified"
    runs = subprocess.run([*STATION, "runs", "--db", str(db), "--json"], cwd=tmp_path, env=ENV,
                          capture_output=True, text=True, timeout=HANG_S)
    assert runs.returncode == 0 and _one_json(runs.stdout)["runs"][0]["outcome"] == "SUCCESS"
    assert not list(tmp_path.glob("station-error-*.log"))


def test_closed_stdout_the_json_is_dropped_and_the_run_stands(tmp_path, short_cell):
    db = tmp_path / "runs.sqlite"
    p = _popen([*_short(short_cell), "--db", db], tmp_path)
    p.stdout.close()  # nobody reads the JSON: its write meets a broken pipe
    _, err = p.communicate(timeout=HANG_S)
    assert p.returncode == NOT_UPLOADED
    assert "run 1: NOT_UPLOADED" in err
    _no_internal_error(tmp_path, err)
    assert _status(db, 1) == "identified"


def test_closed_stderr_every_progress_line_is_dropped_and_the_run_completes(tmp_path, short_cell):
    db = tmp_path / "runs.sqlite"
    p = _popen([*_short(short_cell), "--db", db], tmp_path)
    p.stderr.close()  # the first progress line already meets a broken pipe
    out, _ = p.communicate(timeout=HANG_S)
    assert p.returncode == NOT_UPLOADED
    assert _one_json(out)["outcome"] == "NOT_UPLOADED"
    assert _status(db, 1) == "identified"
    assert not list(tmp_path.glob("station-error-*.log"))


def test_closed_stderr_in_the_signal_handler_still_aborts_cleanly(tmp_path):
    db = tmp_path / "runs.sqlite"
    p = _popen([*SHORT, "--db", db], tmp_path)
    p.stderr.close()
    _wait_for_run(db, 1, p)
    p.send_signal(signal.SIGTERM)  # the handler's "stopping at the next safe point" is lost
    out, _ = p.communicate(timeout=HANG_S)
    s = _one_json(out)
    assert p.returncode == ABORTED and s["outcome"] == "ABORTED"
    assert _status(db, s["run_id"]) == "aborted"


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("pipes")
    subprocess.run([*STATION, "init", str(d / "cell.toml")], cwd=d, env=ENV, check=True, capture_output=True)
    model = load_robot("sr800")
    q = spread_joints(model, 30, np.random.default_rng(1))
    pose = matrix_to_pose(synthetic_set(model, "pose", q, model.nominal).measured)
    qd = np.array(q)
    qd[:, [0, 1, 3]] = np.degrees(qd[:, [0, 1, 3]])
    pose[:, 3:] = np.degrees(pose[:, 3:])
    header = ["q1 [deg]", "q2 [deg]", "q3 [mm]", "q4 [deg]", "x [mm]", "y [mm]", "z [mm]",
              "roll [deg]", "pitch [deg]", "yaw [deg]"]
    write_csv(d / "poses.csv", header, np.column_stack([qd, pose]))
    with RunDB(d / "runs.sqlite"):  # an empty run database
        pass
    return d


@pytest.mark.parametrize("args", [
    ["plan", "cell.toml"], ["plan", "cell.toml", "--json"], ["runs", "--db", "runs.sqlite"], ["--help"],
    ["calibrate", "--help"], ["identify", "poses.csv"], ["identify", "poses.csv", "--json"],
], ids=" ".join)
def test_every_command_into_a_closed_pipe_exits_with_its_outcome(files, args):
    """``station … | head`` where head has already gone: exit 0, no traceback, no error log."""
    p = _popen(args, files)
    p.stdout.close()
    _, err = p.communicate(timeout=HANG_S)
    assert p.returncode == 0, err
    _no_internal_error(files, err)
    assert "Exception ignored" not in err, err  # the interpreter's final flush found /dev/null


# --- stop signals --------------------------------------------------------------------------------

def _committed_steps(db: Path) -> int:
    """Steps of the run committed to the database so far; 0 while it is being created."""
    return len(committed_steps(db))


def _wait_for_run(db: Path, steps: int = 1, proc: subprocess.Popen | None = None) -> None:
    """Until the run has ``steps`` measurements committed: the test syncs on the database, never
    on a clock (the poll interval only spares the CPU)."""
    while _committed_steps(db) < steps:
        if proc is not None and proc.poll() is not None:
            out, err = proc.communicate()
            raise AssertionError(f"the station ended (exit {proc.returncode}) before {steps} committed steps:\n"
                                 f"{out}\n{err[-3000:] if err else ''}")
        time.sleep(0.02)


def test_sigterm_from_the_first_moment_the_handlers_exist_is_aborted_with_one_json(tmp_path):
    db = tmp_path / "runs.sqlite"
    p = _popen([*SHORT, "--db", db], tmp_path)
    while not _handlers_installed(p.pid) and p.poll() is None:
        time.sleep(0.0005)
    p.send_signal(signal.SIGTERM)
    out, err = p.communicate(timeout=HANG_S)
    s = _one_json(out)
    assert p.returncode == ABORTED and s["outcome"] == "ABORTED" and s["exit_code"] == ABORTED, err
    assert s["run_id"] is None  # stopped before the session: nothing was opened or moved
    _no_internal_error(tmp_path, err)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=lambda s: s.name)
def test_a_signal_during_the_run_stops_at_a_safe_point(tmp_path, sig):
    db = tmp_path / "runs.sqlite"
    p = _popen([*SHORT, "--db", db], tmp_path)
    _wait_for_run(db, 1, p)
    p.send_signal(sig)
    out, err = p.communicate(timeout=HANG_S)
    s = _one_json(out)
    assert p.returncode == ABORTED and s["outcome"] == "ABORTED", err
    assert _status(db, s["run_id"]) == "aborted"
    _no_internal_error(tmp_path, err)


def test_a_second_sigterm_stops_at_once_marks_the_run_aborted_and_it_resumes(tmp_path, short_cell):
    db = tmp_path / "runs.sqlite"
    p = _popen([*_short(short_cell), "--db", db], tmp_path)
    _wait_for_run(db, 1, p)
    p.send_signal(signal.SIGTERM)
    p.send_signal(signal.SIGTERM)
    out, err = p.communicate(timeout=HANG_S)
    s = _one_json(out)
    assert p.returncode == ABORTED and s["outcome"] == "ABORTED", err
    assert _status(db, s["run_id"]) == "aborted"
    _no_internal_error(tmp_path, err)
    again = _popen([*_short(short_cell), "--db", db, "--resume", s["run_id"]], tmp_path)
    out, err = again.communicate(timeout=HANG_S)
    assert again.returncode == NOT_UPLOADED and _one_json(out)["run_id"] == s["run_id"], err
    assert _status(db, s["run_id"]) == "identified"


def test_sigterm_at_spread_moments_always_gives_one_outcome(tmp_path):
    """Two SIGTERMs, side by side, once 8 and 32 steps are committed to the run database (synced on
    the database, not on a clock). Each process answers exactly one JSON object whose exit code it
    exits with, each kill lands mid-run (ABORTED, the run marked so), and the run keeps every step
    it had committed. The moment the handlers exist and the first step have their own tests above;
    benchmarks/bench_signal_moments.py sweeps more moments (every process designs the cell's
    table before its first step, 7 s of CPU: five here cost the suite more than any other test of
    this file, issue 42)."""
    moments = (8, 32)  # committed steps before the signal

    def one(i_steps: tuple[int, int]) -> tuple[int, int, str, Path]:
        i, steps = i_steps
        d = tmp_path / f"p{i}"
        d.mkdir()
        db = d / "runs.sqlite"
        p = _popen([*SHORT, "--db", db], d)
        _wait_for_run(db, steps, p)
        p.send_signal(signal.SIGTERM)
        out, _ = p.communicate(timeout=HANG_S)
        return steps, p.returncode, out, d

    with ThreadPoolExecutor(len(moments)) as pool:
        results = list(pool.map(one, enumerate(moments)))
    for steps, rc, out, d in results:
        s = _one_json(out)
        assert rc == s["exit_code"], (steps, rc, s)
        assert not list(d.glob("station-error-*.log"))
        # landed mid-run: stopped at the next safe point, with what it had measured kept
        assert s["outcome"] == "ABORTED" and rc == ABORTED, (steps, s)
        assert _status(d / "runs.sqlite", s["run_id"]) == "aborted"
        assert _committed_steps(d / "runs.sqlite") >= steps


# --- --json answers usage errors; values refused -------------------------------------------------

@pytest.mark.parametrize("args,says", [
    (["calibrate", "--simulated", "--bogus", "--json"], "unrecognized arguments: --bogus"),
    (["calibrate", "--simulated", "--seed", "abc", "--json"], "'abc': give a seed as a whole number (0 … 4294967295)"),
    (["recheck", "--simulated", "--poses", "x", "--json"], "--poses"),
    (["--json"], "required"),
])
def test_a_usage_error_with_json_prints_one_config_error_object(tmp_path, args, says):
    p = _popen([*args, "--db", tmp_path / "runs.sqlite"] if args[0] != "--json" else args, tmp_path)
    out, err = p.communicate(timeout=HANG_S)
    s = _one_json(out)
    assert p.returncode == CONFIG_ERROR and s["outcome"] == "CONFIG_ERROR" and s["exit_code"] == CONFIG_ERROR
    assert says in s["failure"]["message"] and says in err
    assert not (tmp_path / "runs.sqlite").exists()  # refused before anything was opened


@pytest.mark.parametrize("value", ["nan", "-1", "inf", "fast"])
def test_time_scale_must_be_zero_or_a_positive_number(tmp_path, value):
    for command in ("calibrate", "recheck"):
        p = _popen([command, "--simulated", "--db", tmp_path / "runs.sqlite", f"--time-scale={value}"], tmp_path)
        out, err = p.communicate(timeout=HANG_S)
        assert p.returncode == CONFIG_ERROR and "--time-scale" in err and "positive number" in err, err
        assert out == "" and not (tmp_path / "runs.sqlite").exists()


def test_tui_with_a_missing_configuration_says_so_instead_of_opening(tmp_path):
    p = _popen(["tui", "missing.toml", "--db", tmp_path / "runs.sqlite"], tmp_path, stdin=subprocess.DEVNULL)
    out, err = p.communicate(timeout=HANG_S)
    assert p.returncode == CONFIG_ERROR and "no such configuration file: missing.toml" in err
    assert "\x1b[" not in out  # the full-screen UI never drew


def test_a_descriptor_closed_before_start_is_not_a_crash(tmp_path):
    """Found by benchmarks/fuzz_campaign.py: with fd 1 closed (>&-) Python starts with sys.stdout
    None, and the station exited 120 from its own stream wrapper."""
    import shutil as _shutil

    sh = _shutil.which("sh")
    assert sh is not None
    for redirect in (">&-", "2>&-", ">&- 2>&-"):
        r = subprocess.run([sh, "-c", f'exec "{sys.executable}" -m station.ui.cli.main --help {redirect}'],
                           cwd=tmp_path, capture_output=True, text=True, timeout=HANG_S)
        assert r.returncode == 0, (redirect, r.stderr)
        assert "Traceback" not in r.stderr and not list(tmp_path.glob("station-error-*.log"))
