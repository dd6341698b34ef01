"""Scripts route every outcome (issue 29, part 3): a hint that is never empty, every ``--json``
object with ``outcome``, ``exit_code`` (and ``db`` where one was given), a missing ``--db`` file a
database error naming it, names never truncated in ``runs``, and progress lines with the elapsed
time and the time left. Fast: no simulated cell (tests/ui/test_scripts.py runs one, SIGTERM
included)."""

from __future__ import annotations

import json

import pytest

from station.cell.pipeline.outcomes import failure_summary, hint_for
from station.cell.records.reading.run_list import RunInfo
from station.cell.records.run_records import RunDatabaseError
from station.cell.run.facts import events as ev
from station.errors import ConfigError, IdentificationError, Outcome, RunAborted, StationError, UnreachableError
from station.ui.cli.main import main
from station.ui.cli.process.progress_clock import ProgressClock, clock_text


class _Drifted(StationError):
    outcome = Outcome.DRIFTED


@pytest.mark.parametrize("exc", [ConfigError("bad key"), RunDatabaseError("no such table"), IdentificationError("rank"),
                                 UnreachableError("out of reach"), RunAborted("stopped"), _Drifted("moved"),
                                 ValueError("a bug")])
@pytest.mark.parametrize("run_id", [None, 3])
def test_the_hint_is_never_empty(exc, run_id, tmp_path):
    assert hint_for(exc, run_id).strip()
    summary = failure_summary(exc, run_id=run_id, log_dir=tmp_path)
    assert summary.failure is not None and summary.failure.hint.strip()
    if run_id is None:
        assert "--resume" not in summary.failure.hint  # nothing to resume


def test_a_missing_db_is_a_database_error_naming_the_path(tmp_path, capsys):
    missing = tmp_path / "nope.sqlite"
    for argv in (["runs"], ["report", "1"], ["export", str(tmp_path / "out.csv")]):
        assert main([*argv, "--db", str(missing)]) == 5, argv
        assert f"no run database at {missing}" in capsys.readouterr().err
        assert not missing.exists()  # not created by looking
    assert main(["runs", "--db", str(missing), "--json"]) == 5
    obj = json.loads(capsys.readouterr().out)
    assert (obj["outcome"], obj["exit_code"], obj["db"]) == ("DATABASE_ERROR", 5, str(missing))
    assert obj["failure"]["hint"]


def test_every_json_object_has_outcome_exit_code_and_the_db(tmp_path, capsys):
    assert main(["runs", "--db", "x.sqlite", "--bogus", "--json"]) == 2  # a usage error
    obj = json.loads(capsys.readouterr().out)
    assert (obj["outcome"], obj["exit_code"], obj["db"]) == ("CONFIG_ERROR", 2, "x.sqlite") and obj["failure"]["hint"]
    assert main(["analyze", "--robot", "sr800", "--poses", "40", "--json"]) == 0  # success carries them too
    obj = json.loads(capsys.readouterr().out)
    assert (obj["outcome"], obj["exit_code"]) == ("SUCCESS", 0)
    db = tmp_path / "runs.sqlite"
    from station.cell.records.rundb import RunDB

    with RunDB(db):
        pass
    assert main(["runs", "--db", str(db), "--json"]) == 0
    obj = json.loads(capsys.readouterr().out)
    assert (obj["outcome"], obj["exit_code"], obj["runs"]) == ("SUCCESS", 0, [])


def test_runs_never_truncates_names(tmp_path, capsys, monkeypatch):
    db = tmp_path / "runs.sqlite"
    from station.cell.records.rundb import RunDB

    with RunDB(db):
        pass
    info = RunInfo(1, "2026-12-01T10:00:00Z", "the assembly line's second cell", "myscara650", "verified", 305, 305,
                   "SUCCESS", 800.0, 10.0, 80.0)
    monkeypatch.setattr("station.ui.cli.commands_cell.list_runs", lambda _db: [info])
    assert main(["runs", "--db", str(db)]) == 0
    out = capsys.readouterr().out
    assert "myscara650" in out and "the assembly line's second cell" in out


def test_progress_lines_carry_elapsed_time_and_time_left():
    t = [100.0]
    clock = ProgressClock(lambda run: 600.0, now=lambda: t[0])  # the plan's estimate: 10 min for 300 steps
    clock.started(ev.RunStarted(run_id=1, n_steps=300))
    t[0] = 160.0
    assert clock.text(100, 300) == "01:00 elapsed, ≈ 06:40 left (plan estimate)"
    t = [0.0]
    by_rate = ProgressClock(None, now=lambda: t[0])  # no estimate (instant simulated motion): the rate so far
    by_rate.started(ev.RunStarted(run_id=1, n_steps=300, resumed_from=100))
    assert by_rate.text(100, 300) == "00:00 elapsed"
    t[0] = 20.0
    assert by_rate.text(110, 300) == "00:20 elapsed, ≈ 06:20 left (rate so far)"
    assert clock_text(3725) == "1:02:05"


@pytest.mark.parametrize("verb", ["calibrate", "recheck"])
def test_a_signal_is_reported_as_a_signal_with_the_real_resume_command(verb, tmp_path, monkeypatch):
    from argparse import Namespace
    from types import SimpleNamespace

    import station.cell.session.calibrate as session
    from station.ui.cli import commands_cell

    stored = {}
    monkeypatch.setattr(commands_cell, "current_stop_signals", lambda: SimpleNamespace(requested=True, name="SIGTERM"))
    monkeypatch.setattr(session, "store_failure", lambda db, run, record: stored.update(record))
    args = Namespace(config=None, simulated=True, seed=4, robot=None, time_scale=0.0, db=str(tmp_path / "my runs.sqlite"))
    aborted = failure_summary(RunAborted("run aborted by the operator at a safe point"), run_id=7, log_dir=tmp_path)
    got = commands_cell.as_stopped(aborted, args, verb=verb)
    assert got.failure is not None and got.failure.message.startswith("stopped by SIGTERM at a safe point")
    assert f"'station {verb} --simulated --seed 4 --db '{tmp_path}/my runs.sqlite' --resume 7'" in got.failure.hint
    assert stored["failure"]["message"] == got.failure.message  # the stored summary says the same
    assert (stored.get("kind") == "recheck") is (verb == "recheck")
