"""The surfaces of issue 19 for ``fuzz_campaign.py``: damaged run-database records, signals at
random moments, closed pipes. Each family returns a ``Family`` of counts; an internal error is
exit 1, a traceback or "internal error" in the output, or a station-error-*.log left behind."""

from __future__ import annotations

import contextlib
import io
import json
import os
import random
import shutil
import signal
import sqlite3
import subprocess
import sys
import tempfile
import time
import traceback
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
STATION = [sys.executable, "-m", "station.ui.cli.main"]
BUDGET_S = 60.0  # per command: a simulated calibration takes ~5 s on an idle machine


@dataclass
class Family:
    name: str
    tried: int = 0
    by_exit: Counter[int] = field(default_factory=Counter)
    internal: int = 0
    hangs: int = 0
    silent: int = 0  # exit 0 where the input must be refused (issue 33's families count it)
    failures: list[str] = field(default_factory=list)
    elapsed_s: float = 0.0

    def internal_error(self, what: str) -> None:
        self.internal += 1
        self.failures.append(f"internal error: {self.name}: {what}")

    def hang(self, what: str) -> None:
        self.hangs += 1
        self.failures.append(f"hang: {self.name}: {what}")


def _looks_internal(rc: int, text: str) -> bool:
    return rc == 1 or "Traceback" in text or "internal error" in text


def _error_logs(d: Path) -> list[Path]:
    return sorted(d.glob("station-error-*.log"))


def _good_db(d: Path) -> Path:
    """One finished simulated calibration without the upload (exit 11, NOT_UPLOADED)."""
    db = d / "good.sqlite"
    proc = subprocess.run([*STATION, "calibrate", "--simulated", "--seed", "1", "--no-upload", "--db", str(db)],
                          cwd=d, capture_output=True, text=True, timeout=BUDGET_S * 2)
    if proc.returncode != 11:
        raise RuntimeError(f"the seed run failed (exit {proc.returncode}): {proc.stderr[-2000:]}")
    return db


# ------------------------------------------------------------------ family 1: damaged records

_JOINTS = "json_set(plan_json, '$[0].joints', json('{}'))"
_TEXT = '"abc"'


def _record_damages(rng: random.Random, n_random: int) -> list[tuple[str, str | Callable[[Path], None]]]:
    """(name, SQL script or a function of the file): the fixed kinds, then seeded random JSON."""
    def sql(s: str) -> str:
        return s

    def truncate(frac: float) -> Callable[[Path], None]:
        def f(p: Path) -> None:
            data = p.read_bytes()
            p.write_bytes(data[: int(len(data) * frac)])
        return f

    def scribble(p: Path) -> None:
        data = bytearray(p.read_bytes())
        r = random.Random(len(data))
        for _ in range(64):
            i = r.randrange(100, len(data))
            data[i] = r.randrange(256)
        p.write_bytes(bytes(data))

    m1 = "UPDATE measurements SET {} WHERE run_id = 1 AND step_index = 0;"
    res = "UPDATE results SET json = '{}' WHERE key = '{}';"
    out: list[tuple[str, str | Callable[[Path], None]]] = [
        ("plan not JSON", sql("UPDATE runs SET plan_json = '{not json';")),
        ("plan '['", sql("UPDATE runs SET plan_json = '[';")),
        ("plan an object", sql("UPDATE runs SET plan_json = '{}';")),
        ("plan null", sql("UPDATE runs SET plan_json = 'null';")),
        ("plan empty list", sql("UPDATE runs SET plan_json = '[]';")),
        ("plan of numbers", sql("UPDATE runs SET plan_json = '[1, 2, 3]';")),
        ("plan step without joints", sql("UPDATE runs SET plan_json = json_remove(plan_json, '$[0].joints');")),
        ("plan step of 5 joints", sql(f"UPDATE runs SET plan_json = {_JOINTS.format('[0,0,0,0,0]')};")),
        ("plan step of 3 joints", sql(f"UPDATE runs SET plan_json = {_JOINTS.format('[0,0,0]')};")),
        ("plan joints text", sql(f"UPDATE runs SET plan_json = {_JOINTS.format(_TEXT)};")),
        ("plan joint NaN", sql("UPDATE runs SET plan_json = replace(plan_json, '\"joints\":[-1.34', "
                               "'\"joints\":[NaN');")),
        ("plan joint huge", sql(f"UPDATE runs SET plan_json = {_JOINTS.format('[1e308,1e308,1e308,1e308]')};")),
        ("plan index text", sql("UPDATE runs SET plan_json = json_set(plan_json, '$[0].index', 'x');")),
        ("plan kind unknown", sql("UPDATE runs SET plan_json = json_set(plan_json, '$[0].kind', 'bogus');")),
        ("plan truncated", sql("UPDATE runs SET plan_json = substr(plan_json, 1, length(plan_json) / 2);")),
        ("config not TOML", sql("UPDATE runs SET config_toml = '[[[ not toml';")),
        ("config empty", sql("UPDATE runs SET config_toml = '';")),
        ("seed not a number", sql("UPDATE runs SET seed = 'abc';")),
        ("created_utc garbage", sql("UPDATE runs SET created_utc = 'yesterday';")),
        ("joints_commanded not JSON", sql(m1.format("joints_commanded = '{bad'"))),
        ("joints_commanded 5 long", sql(m1.format("joints_commanded = '[0,0,0,0,0]'"))),
        ("joints_commanded NaN", sql(m1.format("joints_commanded = '[NaN, 0, 0, 0]'"))),
        ("joints_commanded huge", sql(m1.format("joints_commanded = '[1e308, 1e308, 0, 0]'"))),
        ("joints_commanded a string", sql(m1.format("joints_commanded = '\"x\"'"))),
        ("joints_read wrong length", sql(m1.format("joints_read = '[1]'"))),
        ("readings not JSON", sql(m1.format("readings_mm = '['"))),
        ("readings 2 long", sql(m1.format("readings_mm = '[1, 2]'"))),
        ("readings null", sql(m1.format("readings_mm = NULL"))),
        ("readings text values", sql(m1.format("readings_mm = '[\"a\",\"b\",\"c\",\"d\",\"e\",\"f\"]'"))),
        ("readings huge", sql(m1.format("readings_mm = '[1e308,1e308,1e308,1e308,1e308,1e308]'"))),
        ("channel_status a number", sql(m1.format("channel_status = '5'"))),
        ("pose 1x1", sql(m1.format("pose = '[[1]]'"))),
        ("pose NaN", sql(m1.format("pose = '[[NaN,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]'"))),
        ("pose not JSON", sql(m1.format("pose = '[[1,'"))),
        ("pose_residual text", sql(m1.format("pose_residual_um = 'abc'"))),
        ("step_index beyond the plan", sql(m1.format("step_index = 100000"))),
        ("measurement kind unknown", sql(m1.format("kind = 'bogus'"))),
        ("all ok rows deleted", sql("DELETE FROM measurements WHERE step_index > 3;")),
        ("summary '['", sql(res.format("[", "summary"))),
        ("summary a list", sql(res.format("[1, 2]", "summary"))),
        ("summary empty object", sql(res.format("{}", "summary"))),
        ("summary NaN", sql(res.format("NaN", "summary"))),
        ("summary wrong types", sql(res.format('{"outcome": 5, "exit_code": "x", "run_id": []}', "summary"))),
        ("summary deleted", sql("DELETE FROM results WHERE key = 'summary';")),
        ("identification not JSON", sql(res.format("{bad", "identification"))),
        ("identification 2 params", sql(res.format('{"params": [1, 2]}', "identification"))),
        ("identification NaN params", sql("UPDATE results SET json = json_set(json, '$.params', "
                                          "json('[1e999, 1e999]')) WHERE key = 'identification';")),
        ("fingerprint a list", sql(res.format("[]", "fingerprint"))),
        ("devices null", sql(res.format("null", "devices"))),
        ("measurements without columns", sql("DROP TABLE measurements; CREATE TABLE measurements"
                                             "(run_id INTEGER, step_index INTEGER, kind TEXT);")),
        ("measurements dropped", sql("DROP TABLE measurements;")),
        ("results dropped", sql("DROP TABLE results;")),
        ("runs without the note column", sql("ALTER TABLE runs DROP COLUMN note;")),
        ("schema version 999", sql("UPDATE schema_version SET version = 999;")),
        ("schema version gone", sql("DELETE FROM schema_version;")),
        ("file truncated to half", truncate(0.5)),
        ("file truncated to 100 bytes", truncate(100 / 1e9)),
        ("file empty", truncate(0.0)),
        ("file scribbled", scribble),
    ]
    garbage = ["[", "{", "null", "true", "-1", "1e999", "\"\"", "[[]]", "{\"a\": NaN}", "[1, [2, [3]]]"]
    columns = [("runs", "plan_json", ""), ("measurements", "joints_commanded", " WHERE step_index = 1"),
               ("measurements", "readings_mm", " WHERE step_index = 2"),
               ("measurements", "pose", " WHERE step_index = 3"), ("results", "json", " WHERE key = 'summary'"),
               ("results", "json", " WHERE key = 'identification'")]
    for _ in range(n_random):
        table, col, where = rng.choice(columns)
        value = rng.choice(garbage)
        if rng.random() < 0.3:
            value = "".join(rng.choice("[]{},:\"0123456789.eE-NaInfy ") for _ in range(rng.randrange(1, 24)))
        esc = value.replace("'", "''")
        out.append((f"{table}.{col}{where} = {value!r}", sql(f"UPDATE {table} SET {col} = '{esc}'{where};")))
    return out


class _Overrun(BaseException):
    """Raised by SIGALRM past the budget: a BaseException, so the station's handlers pass it on."""


def _in_process(argv: list[str], cwd: Path) -> tuple[int, str]:
    from station.ui.cli.main import main

    out, err = io.StringIO(), io.StringIO()
    here = os.getcwd()

    def overrun(*_: object) -> None:
        raise _Overrun

    old = signal.signal(signal.SIGALRM, overrun)
    signal.setitimer(signal.ITIMER_REAL, BUDGET_S)
    try:
        os.chdir(cwd)
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                rc = main(argv)
            except SystemExit as exc:  # argparse
                rc = exc.code if isinstance(exc.code, int) else 2
            except Exception:  # escaped main: the worst internal error
                err.write(traceback.format_exc())
                rc = 1
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
        os.chdir(here)
    return rc, out.getvalue() + err.getvalue()


def damaged_records(scale: int, seed: int = 19) -> Family:
    fam = Family("records")
    t0 = time.perf_counter()
    rng = random.Random(seed)
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        good = _good_db(d)
        for i, (name, damage) in enumerate(_record_damages(rng, n_random=4 * scale)):
            case = d / f"case{i}"
            case.mkdir()
            db = case / "runs.sqlite"
            shutil.copy(good, db)
            if isinstance(damage, str):
                conn = sqlite3.connect(db)
                try:
                    conn.executescript(damage)
                finally:
                    conn.close()
            else:
                damage(db)
            # resume last: it writes to the copy
            for argv in (["runs", "--db", str(db)], ["runs", "--db", str(db), "--json"],
                         ["report", "1", "--db", str(db), "-o", str(case / "rep")],
                         ["export", "--db", str(db), "--run", "1", str(case / "m.csv")],
                         ["calibrate", "--simulated", "--seed", "1", "--no-upload", "--resume", "1",
                          "--db", str(db)]):
                fam.tried += 1
                what = f"[{name}] station {' '.join(argv)}"
                try:
                    rc, text = _in_process(argv, case)
                except _Overrun:
                    fam.hang(what)
                    continue
                fam.by_exit[rc] += 1
                logs = _error_logs(case)
                if _looks_internal(rc, text) or logs:
                    fam.internal_error(f"{what}: exit {rc}: {text[-1500:]}"
                                       + "".join(f"\n  {p.name}: {p.read_text()[-1500:]}" for p in logs))
                    for log in logs:
                        log.unlink()
            shutil.rmtree(case)
    fam.elapsed_s = time.perf_counter() - t0
    return fam


# ------------------------------------------------------------------ family 2: signals

def _runs_json(db: Path, cwd: Path) -> tuple[int, list[dict]]:
    proc = subprocess.run([*STATION, "runs", "--db", str(db), "--json"], cwd=cwd, capture_output=True,
                          text=True, timeout=BUDGET_S)
    try:
        return proc.returncode, list(json.loads(proc.stdout).get("runs", []))
    except (ValueError, AttributeError):
        return proc.returncode, []


def signals(scale: int, seed: int = 19) -> Family:
    fam = Family("signals")
    t0 = time.perf_counter()
    rng = random.Random(seed)
    n = 2 * scale  # each is a simulated calibration (~5 s)
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(n):
            case = Path(tmp) / f"sig{i}"
            case.mkdir()
            db = case / "runs.sqlite"
            delay = rng.uniform(0.0, 5.0)
            second = rng.random() < 0.4
            gap = rng.uniform(0.0, 0.5)
            what = f"SIGTERM after {delay:.2f} s{f' and again {gap:.2f} s later' if second else ''}"
            fam.tried += 1
            proc = subprocess.Popen([*STATION, "calibrate", "--simulated", "--seed", "1", "--no-upload",
                                     "--json", "--db", str(db)], cwd=case, stdout=subprocess.PIPE,
                                    stderr=subprocess.PIPE, text=True)
            time.sleep(delay)
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
                if second:
                    time.sleep(gap)
                    if proc.poll() is None:
                        proc.send_signal(signal.SIGTERM)
            try:
                out, err = proc.communicate(timeout=BUDGET_S)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.communicate()
                fam.hang(what)
                continue
            rc = proc.returncode
            fam.by_exit[rc] += 1
            problems = []
            if rc not in (6, 11):
                problems.append(f"exit {rc} (6, or 11 when it finished first)")
            try:
                obj = json.loads(out)
                if not isinstance(obj, dict):
                    problems.append("stdout is JSON but not one object")
            except ValueError:
                problems.append(f"stdout is not exactly one JSON object: {out[:300]!r}")
            rc_runs, runs = _runs_json(db, case) if db.exists() else (0, [])
            if rc_runs not in (0,):
                problems.append(f"station runs --json exit {rc_runs}")
            if any(r.get("status") == "measuring" for r in runs):
                problems.append("the run is left 'measuring'")
            logs = _error_logs(case)
            if _looks_internal(rc, err) or logs or problems:
                fam.internal_error(f"{what}: {'; '.join(problems)}: {err[-1500:]}"
                                   + "".join(f"\n  {p.name}: {p.read_text()[-1000:]}" for p in logs))
    fam.elapsed_s = time.perf_counter() - t0
    return fam


# ------------------------------------------------------------------ family 3: closed pipes

def _reader_closing_after(n_bytes: int, *argv: str, cwd: Path, stream: str) -> tuple[int, str]:
    """Run argv with `stream` into a pipe read for n_bytes and then closed; the other into a file."""
    other = cwd / "other.txt"
    with open(other, "w") as fh:
        kw = {"stdout": subprocess.PIPE, "stderr": fh} if stream == "stdout" else {"stdout": fh,
                                                                                   "stderr": subprocess.PIPE}
        proc = subprocess.Popen(list(argv), cwd=cwd, **kw)  # type: ignore[call-overload]
        pipe = proc.stdout if stream == "stdout" else proc.stderr
        assert pipe is not None
        got = 0
        while got < n_bytes:
            chunk = pipe.read1(max(1, n_bytes - got))
            if not chunk:
                break
            got += len(chunk)
        pipe.close()
        try:
            rc = proc.wait(timeout=BUDGET_S)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
            return -999, ""
    return rc, other.read_text(errors="replace") if stream == "stdout" else ""


def _closed(mode: str, argv: list[str], cwd: Path) -> tuple[int, str]:
    """mode: 'stdout', 'stderr' or 'both' closed (the fd is not open in the child)."""
    redir = {"stdout": ">&-", "stderr": "2>&-", "both": ">&- 2>&-"}[mode]
    err_file = cwd / "err.txt"
    cmd = " ".join(_q(a) for a in argv) + f" {redir}"
    if mode == "stdout":
        cmd += f" 2>{_q(str(err_file))}"
    try:
        proc = subprocess.run(["sh", "-c", f"exec {cmd}"], cwd=cwd, timeout=BUDGET_S,
                              stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired:
        return -999, ""
    return proc.returncode, err_file.read_text(errors="replace") if err_file.exists() else ""


def _q(s: str) -> str:
    return "'" + s.replace("'", "'\\''") + "'"


def closed_pipes(scale: int, seed: int = 19) -> Family:
    fam = Family("pipes")
    t0 = time.perf_counter()
    rng = random.Random(seed)
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        good = _good_db(d)
        cfg = d / "cell.toml"
        subprocess.run([*STATION, "init", str(cfg)], cwd=d, capture_output=True, timeout=BUDGET_S, check=True)
        cheap = [["runs", "--db", "{db}"], ["runs", "--db", "{db}", "--json"], ["plan", str(cfg)],
                 ["plan", str(cfg), "--json"], ["export", "--db", "{db}", "--run", "1", "{case}/m.csv"],
                 ["analyze", "--help"], ["calibrate", "--bogus", "--json"]]
        run = ["calibrate", "--simulated", "--seed", "1", "--no-upload", "--db", "{db}"]
        cases: list[tuple[list[str], str, int]] = []  # argv, mode, bytes before the reader closes
        for argv in cheap:
            cases.append((argv, rng.choice(["stdout", "stderr", "both"]), 0))
            cases.append((argv, "pipe-stdout", rng.choice([0, 1, 10, 200])))
        for mode in ("stdout", "stderr", "both"):
            cases.append((run, mode, 0))
        for _ in range(max(1, scale - 1)):
            cases.append((run, rng.choice(["pipe-stdout", "pipe-stderr"]), rng.choice([1, 100, 1000])))
            cases.append((run + ["--json"], "pipe-stdout", rng.choice([1, 50])))
        for i, (template, mode, n_bytes) in enumerate(cases):
            case = d / f"pipe{i}"
            case.mkdir()
            db = case / "runs.sqlite"
            shutil.copy(good, db)
            argv = [a.format(db=db, case=case) for a in template]
            base = subprocess.run([*STATION, *argv], cwd=case, capture_output=True, timeout=BUDGET_S)
            shutil.copy(good, db)  # the baseline's run is not the one under test
            for p in case.glob("*.csv"):
                p.unlink()
            fam.tried += 1
            what = f"station {' '.join(argv)} with {mode}{f' after {n_bytes} B' if mode.startswith('pipe') else ''}"
            if mode.startswith("pipe"):
                rc, text = _reader_closing_after(n_bytes, *STATION, *argv, cwd=case, stream=mode[5:])
            else:
                rc, text = _closed(mode, [*STATION, *argv], case)
            if rc == -999:
                fam.hang(what)
                continue
            fam.by_exit[rc] += 1
            logs = _error_logs(case)
            problems = [] if rc == base.returncode else [f"exit {rc}, {base.returncode} with open streams"]
            if _looks_internal(rc, text) or logs or problems:
                fam.internal_error(f"{what}: {'; '.join(problems)}: {text[-1500:]}"
                                   + "".join(f"\n  {p.name}: {p.read_text()[-1000:]}" for p in logs))
            shutil.rmtree(case)
    fam.elapsed_s = time.perf_counter() - t0
    return fam


FAMILIES = {"records": damaged_records, "signals": signals, "pipes": closed_pipes}
