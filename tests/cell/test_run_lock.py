"""One process per run: a run is locked while a process works on it, a second process is refused
before it connects to any device, a lock whose process is gone is taken over (issue 19)."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from station.cell.records.run_lock import RunLockedError
from station.cell.records.rundb import RunDB
from station.ui.cli.main import main

ROOT = Path(__file__).resolve().parents[2]
CONFIG = '[cell]\nname = "lock test"\n'
PLAN = [{"index": 0, "kind": "identification", "point": 0, "point_id": "P1", "elbow": 1, "joints": [0.0] * 4}]

HOLDER = """
import sys, time
from station.cell.records.rundb import RunDB
with RunDB(sys.argv[1]) as db, db.lock_run(1):
    print("locked", flush=True)
    time.sleep(120)
"""


@pytest.fixture
def db_path(tmp_path) -> Path:
    path = tmp_path / "runs.sqlite"
    with RunDB(path) as db:
        db.create_run(CONFIG, PLAN, seed=1)
    return path


@pytest.fixture
def holder(db_path):
    """Another station process that holds run 1's lock."""
    p = subprocess.Popen([sys.executable, "-c", HOLDER, str(db_path)], cwd=ROOT, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert p.stdout is not None and p.stdout.readline().strip() == "locked", p.stderr.read() if p.stderr else ""
    yield p
    if p.poll() is None:
        p.kill()
    p.wait(10)


@pytest.mark.parametrize("command", ["calibrate", "recheck"])
def test_second_process_is_refused_before_any_device(db_path, holder, capsys, command):
    rc = main([command, "--simulated", "--seed", "1", "--resume", "1", "--db", str(db_path)])
    text = "".join(capsys.readouterr())
    assert rc == 5, text
    assert f"run 1 is in use by process {holder.pid} on host {socket.gethostname()} (since 20" in text
    assert f"station runs --db {db_path} --unlock 1" in text
    assert "connecting the probe head" not in text  # refused before connecting: nothing could move
    with RunDB(db_path) as db:  # the holder's lock is untouched, no failure stored for its run
        lock = db.run_lock(1)
        assert lock is not None and lock.pid == holder.pid
        assert db.load_result(1, "summary", default=None) is None


def test_lock_of_a_killed_process_is_taken_over(db_path, holder):
    holder.send_signal(signal.SIGKILL)
    holder.wait(10)
    with RunDB(db_path) as db:
        assert db.run_lock(1).pid == holder.pid  # left behind by the kill
        with db.lock_run(1) as stale:
            assert stale is not None and stale.pid == holder.pid
            assert db.run_lock(1).pid == os.getpid()
        assert db.run_lock(1) is None
        assert any("stale run lock of process" in e.message and "taken over" in e.message for e in db.events(1))


def test_lock_released_after_an_exception(db_path):
    with RunDB(db_path) as db:
        with pytest.raises(RuntimeError), db.lock_run(1):
            assert db.run_lock(1).pid == os.getpid()
            raise RuntimeError("mid-run failure")
        assert db.run_lock(1) is None


def test_failed_resume_releases_its_lock(db_path, capsys):
    # a run without a fingerprint resumed on another cell: refused after the lock was taken
    rc = main(["calibrate", "--simulated", "--seed", "1", "--resume", "1", "--db", str(db_path)])
    assert rc not in (0, 1), capsys.readouterr()
    with RunDB(db_path) as db:
        assert db.run_lock(1) is None


def test_second_session_in_the_same_process_is_refused(db_path):
    with RunDB(db_path) as first, first.lock_run(1), RunDB(db_path) as second:
        with pytest.raises(RunLockedError, match=f"process {os.getpid()}") as err, second.lock_run(1):
            pass
        assert err.value.exit_code == 5


def test_new_run_is_locked_from_its_creation(tmp_path):
    path = tmp_path / "runs.sqlite"
    with RunDB(path, lock_new_runs=True) as db:
        run_id = db.create_run(CONFIG, PLAN)
        assert db.run_lock(run_id).pid == os.getpid()
        with RunDB(path) as other, pytest.raises(RunLockedError), other.lock_run(run_id):
            pass
    with RunDB(path) as db:
        assert db.run_lock(run_id) is None  # released on close


def test_lock_of_another_host_is_cleared_by_hand(db_path):
    with RunDB(db_path) as db:
        db._c().execute("INSERT INTO run_locks(run_id, host, pid, pid_start, since_utc, token) "
                        "VALUES (1, 'line-2-pc', 4242, '', '2026-01-01T00:00:00Z', 'x')")
        with pytest.raises(RunLockedError, match="process 4242 on host line-2-pc .*--unlock 1"), db.lock_run(1):
            pass
        assert db.unlock_run(1).host == "line-2-pc"
        with db.lock_run(1) as stale:
            assert stale is None
        assert any("cleared by hand" in e.message for e in db.events(1))


def test_station_runs_unlock_clears_another_hosts_lock(db_path, capsys):
    from station.ui.cli.main import main

    with RunDB(db_path) as db:
        db._c().execute("INSERT INTO run_locks(run_id, host, pid, pid_start, since_utc, token) "
                        "VALUES (1, 'line-2-pc', 4242, '', '2026-01-01T00:00:00Z', 'x')")
    assert main(["runs", "--db", str(db_path), "--unlock", "1"]) == 0
    assert "lock of process 4242 on host line-2-pc" in capsys.readouterr().out
    with RunDB(db_path) as db:
        assert db.run_lock(1) is None
    assert main(["runs", "--db", str(db_path), "--unlock", "1"]) == 0
    assert "was not locked" in capsys.readouterr().out
