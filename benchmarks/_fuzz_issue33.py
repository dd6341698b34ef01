"""The families of issue 33 for ``fuzz_campaign.py``: record-level damage of every measured field,
robot-file typos, URDF structure, float limits, overflowing integers and a full disk. Each input
is damage or an out-of-range value the station must refuse, so besides internal errors and hangs a
family counts *silent acceptances*: exit 0 where the input should have been refused.

Every input is seeded (``random.Random(seed)``): the same command tries the same inputs.
"""

from __future__ import annotations

import contextlib
import json
import os
import random
import shutil
import sqlite3
import tempfile
import time
from collections.abc import Callable, Iterator
from importlib import resources
from pathlib import Path

from _fuzz_surfaces import Family, _error_logs, _good_db, _in_process, _looks_internal, _Overrun

#: exit 0 where the input must be refused
SILENT = "silent acceptance"


def _one(fam: Family, argv: list[str], cwd: Path, what: str, refused: Callable[[int], bool]) -> None:
    """Run ``station ARGV`` in-process; count its exit, an internal error, a hang or a silent acceptance."""
    fam.tried += 1
    try:
        rc, text = _in_process(argv, cwd)
    except _Overrun:
        fam.hang(what)
        return
    fam.by_exit[rc] += 1
    logs = _error_logs(cwd)
    if _looks_internal(rc, text) or logs:
        fam.internal_error(f"{what}: exit {rc}: {text[-1200:]}")
        for log in logs:
            log.unlink()
    elif not refused(rc):
        fam.silent += 1
        fam.failures.append(f"{SILENT}: {fam.name}: {what}: exit {rc}: {text[-600:]}")


def _refused(rc: int) -> bool:
    return rc != 0


# ------------------------------------------------------------------ family: every measured field

_FIELD_VALUES: dict[str, list[str]] = {
    "kind": ["'bogus'", "''", "'IDENTIFICATION'", "'identification '", "'{other_kind}'"],
    "point_id": ["'ZZ'", "''", "'{other_point}'", "'C1.a '"],
    "joints_commanded": ["'[1e300,0,0,0]'", "'[NaN,0,0,0]'", "'[0,0,0]'", "'[0,0,0,0,0]'", "'\"x\"'",
                         "'[99,0,0,0]'", "'[0,0,-1e5,0]'", "'null'", "'[Infinity,0,0,0]'", "'[[0],[0],[0],[0]]'"],
    "joints_read": ["'[1e300,0,0,0]'", "'[0,0,0]'", "'[0,9,0,0]'", "'{}'", "'[\"a\",0,0,0]'", "'[-Infinity,0,0,0]'"],
    "readings_mm": ["'[1e308,0,0,0,0,0]'", "'[1,2]'", "'[]'", "'[Infinity,0,0,0,0,0]'", "'[-1001,0,0,0,0,0]'",
                    "'\"x\"'", "'[0,0,0,0,0,0,0]'"],
    "channel_status": ["'[\"ok\"]'", "'[\"garbage\",\"ok\",\"ok\",\"ok\",\"ok\",\"ok\"]'", "'5'", "'[1,2,3,4,5,6]'",
                       "'{\"a\": 1}'", "'[null,\"ok\",\"ok\",\"ok\",\"ok\",\"ok\"]'", "'[\"OK\",\"ok\",\"ok\",\"ok\",\"ok\",\"ok\"]'"],
    "pose": ["'[[2,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]'", "'[[NaN,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]'",
             "'[[1,0,0,1e300],[0,1,0,0],[0,0,1,0],[0,0,0,1]]'", "'[[1,0,0],[0,1,0],[0,0,1]]'", "'[[1]]'", "'\"x\"'",
             "'[[1,0,0,0],[0,1,0,0],[0,0,1,0],[1,0,0,1]]'"],
    "pose_residual_um": ["-1", "'abc'", "1e999", "-1e999"],
    "t_utc": ["'x'", "''", "'2026-02-30T00:00:00Z'", "'2026-01-01 00:00:00'", "'2026-01-01T00:00:00+01:00'", "5",
              "'2026-01-01T25:00:00Z'"],
    "raw_frames": ["'text, not bytes'", "5"],
    "step_index": ["100000"],
    "run_id": ["99"],
}


def _field_damages(good: Path, rng: random.Random, n: int) -> Iterator[tuple[str, str]]:
    """(name, SQL) of ``n`` damages: every field's every value first, then seeded random rows."""
    conn = sqlite3.connect(good)
    plan = json.loads(conn.execute("SELECT plan_json FROM runs WHERE id = 1").fetchone()[0])
    conn.close()
    points = sorted({s["point_id"] for s in plan})
    cases = [(f, v) for f, vs in _FIELD_VALUES.items() for v in vs]
    for i in range(n):
        field, value = cases[i] if i < len(cases) else rng.choice(cases)
        step = 3 if i < len(cases) else rng.randrange(len(plan))
        kind = plan[step]["kind"]
        value = value.replace("{other_kind}", "oracle" if kind != "oracle" else "identification").replace(
            "{other_point}", next(p for p in points if p != plan[step]["point_id"]))
        pre = "PRAGMA foreign_keys = OFF; " if field == "run_id" else ""
        yield (f"step {step} {field} = {value}",
               f"{pre}UPDATE measurements SET {field} = {value} WHERE run_id = 1 AND step_index = {step};")


_RESULTS = [
    ("recentring", "[1]"), ("recentring", '{"3": 5}'), ("recentring", '{"x": [0,0,0,0,0,0]}'),
    ("recentring", '{"999999": [0,0,0,0,0,0]}'), ("recentring", '{"3": [NaN,0,0,0,0,0]}'), ("recentring", '{"3": [1,2]}'),
]
_TOOLS = ["[1]", '{"name": "t1", "summary": [1]}', '{"name": "t1", "error": 5}', '"x"', "null",
          '{"name": "t1", "tool_params_identified": [1], "tool_params_nominal": [1], "summary": 3}',
          '{"name": "t1", "tool_params_identified": [NaN], "tool_params_nominal": [1]}']
_LOCKS = ["'abc'", "-1", "0", "1e3", "99999999999", "'12'"]
_LOCK_TABLE = ("CREATE TABLE IF NOT EXISTS run_locks (run_id INTEGER PRIMARY KEY, host TEXT NOT NULL, pid INTEGER NOT "
               "NULL, pid_start TEXT NOT NULL DEFAULT '', since_utc TEXT NOT NULL, token TEXT NOT NULL); ")


def record_fields(scale: int, seed: int = 33) -> Family:
    """Each measured field of a stored measurement damaged (``export``), the re-centring and tool
    results (``report``, ``export --tool``) and the lock row (``calibrate --resume``): exit 5."""
    fam = Family("record fields")
    t0 = time.perf_counter()
    rng = random.Random(seed)
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        good = _good_db(d)
        jobs: list[tuple[str, str, list[str]]] = []
        for name, sql in _field_damages(good, rng, 60 * scale):
            jobs.append((name, sql, ["export", "--db", "{db}", "--run", "1", "{case}/m.csv"]))
        for key, value in _RESULTS:
            jobs.append((f"result {key} = {value}", f"UPDATE results SET json = '{value}' WHERE key = '{key}';",
                         ["report", "1", "--db", "{db}", "-o", "{case}/rep"]))
        for value in _TOOLS:
            jobs.append((f"result tool:t1 = {value}", "INSERT INTO results(run_id, key, json, t_utc) VALUES "
                         f"(1, 'tool:t1', '{value}', '2026-01-01T00:00:00Z');",
                         ["export", "--db", "{db}", "--run", "1", "--tool", "t1", "{case}/t.json"]))
        for pid in _LOCKS:
            jobs.append((f"lock pid = {pid}", _LOCK_TABLE + f"INSERT INTO run_locks VALUES (1, 'pc', {pid}, '', "
                         "'2026-01-01T00:00:00Z', 't');",
                         ["calibrate", "--simulated", "--seed", "1", "--no-upload", "--resume", "1", "--db", "{db}"]))
        for i, (name, sql, argv) in enumerate(jobs):
            case = d / f"case{i}"
            case.mkdir()
            db = case / "runs.sqlite"
            shutil.copy(good, db)
            conn = sqlite3.connect(db)
            try:
                conn.executescript(sql)
            except sqlite3.IntegrityError:  # the schema's own constraint refused the damage: not an input
                conn.close()
                shutil.rmtree(case)
                continue
            conn.close()
            _one(fam, [a.format(db=db, case=case) for a in argv], case, f"[{name}] {argv[0]}",
                 lambda rc: rc == 5)
            shutil.rmtree(case)
    fam.elapsed_s = time.perf_counter() - t0
    return fam


# ------------------------------------------------------------------ family: robot-file typos

_ROBOT_KEYS = ["robot", "transform", "joint_map", "tool", "name", "description", "angle_unit", "length_unit",
               "prefer", "joint", "limits", "max_speed", "x", "y", "z", "roll", "pitch", "yaw", "sign", "offset",
               "coupled_to", "k", "unknown"]


def _typo(word: str, rng: random.Random) -> str:
    """A typo that is not itself a known name: a letter dropped, doubled, swapped or replaced."""
    while True:
        i = rng.randrange(len(word))
        op = rng.randrange(4)
        if op == 0 and len(word) > 1:
            out = word[:i] + word[i + 1:]
        elif op == 1:
            out = word[:i] + word[i] + word[i:]
        elif op == 2 and i + 1 < len(word):
            out = word[:i] + word[i + 1] + word[i] + word[i + 2:]
        else:
            out = word[:i] + rng.choice("abcdefghijklmnopqrstuvwxyz_") + word[i + 1:]
        if out and out not in _ROBOT_KEYS and out.isidentifier():
            return out


def _robot_with_typo(rng: random.Random) -> tuple[str, str]:
    text = resources.files("station.io.robots").joinpath("sr800.toml").read_text()
    text += '\n[joint_map.A2]\nsign = -1\noffset = 0.0\n\n[tool]\nunknown = false\n'
    lines = text.splitlines()
    spots = [(i, ln.split("=")[0].strip()) for i, ln in enumerate(lines)
             if "=" in ln and not ln.lstrip().startswith("#") and ln.split("=")[0].strip() in _ROBOT_KEYS]
    tables = [(i, ln) for i, ln in enumerate(lines) if ln.startswith("[") and not ln.startswith("[[")]
    if rng.random() < 0.25:
        i, ln = rng.choice(tables)
        name = ln.strip("[]").split(".")[0]
        bad = _typo(name, rng)
        lines[i] = ln.replace(name, bad, 1)
        return f"table [{name}] → [{bad}]", "\n".join(lines) + "\n"
    i, key = rng.choice(spots)
    bad = _typo(key, rng)
    lines[i] = lines[i].replace(key, bad, 1)
    return f"key {key} → {bad} (line {i + 1})", "\n".join(lines) + "\n"


def robot_typos(scale: int, seed: int = 33) -> Family:
    """A typo in one table or key name of a robot file: refused (exit 2), never a default."""
    fam = Family("robot typos")
    t0 = time.perf_counter()
    rng = random.Random(seed)
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        (d / "j.csv").write_text("q1 [deg],q2 [deg],q3 [mm],q4 [deg]\n10,20,-50,0\n")
        (d / "j2.csv").write_text("q1 [deg],q2 [deg]\n10,20\n")
        for i in range(130 * scale):
            what, text = _robot_with_typo(rng)
            f = d / f"r{i}.toml"
            f.write_text(text)
            argv = ["predict", str(f), str(d / "j.csv")] if i % 2 else ["analyze", "--robot", str(f), "--poses", "5"]
            _one(fam, argv, d, f"{what}: {argv[0]}", _refused)
            f.unlink()
        cols = ["type", "theta [deg]", "d [mm]", "a [mm]", "alpha [deg]", "lower [deg|mm]", "upper [deg|mm]",
                "sign", "offset [deg|mm]"]
        for i in range(10 * scale):  # the DH table's columns
            c = list(cols)
            k = rng.randrange(len(c))
            name = c[k].split(" ")[0]
            c[k] = c[k].replace(name, _typo(name, rng), 1)
            f = d / f"r{i}.dh.csv"
            f.write_text(",".join(c) + "\nrevolute,0,0,100,0,-90,90,1,0\nrevolute,0,0,100,0,-90,90,1,0\n")
            _one(fam, ["predict", str(f), str(d / "j2.csv")], d, f"DH column {cols[k]} → {c[k]}", _refused)
    fam.elapsed_s = time.perf_counter() - t0
    return fam


# ------------------------------------------------------------------ family: URDF structure

def _urdf(rng: random.Random) -> tuple[str, str]:
    n = rng.randrange(2, 6)
    links = [f"l{i}" for i in range(n + 1)]
    joints = [(f"j{i}", links[i], links[i + 1]) for i in range(n)]
    link_xml = [f'<link name="{x}"/>' for x in links]
    kind = rng.randrange(5)
    if kind == 0:
        what = f"link {links[-1]} declared twice"
        link_xml.insert(rng.randrange(len(link_xml)), f'<link name="{links[rng.randrange(len(links))]}"/>')
    elif kind == 1:
        k = rng.randrange(1, n) if n > 1 else 0
        joints[k] = (joints[rng.randrange(k + 1) if k else 0][0], joints[k][1], joints[k][2])
        what = "a joint name twice" if len({j[0] for j in joints}) < n else "renamed"
    elif kind == 2:
        k = rng.randrange(n)
        joints[k] = (joints[k][0], joints[k][1], "ghost")
        what = f"joint {joints[k][0]}'s child undeclared"
    elif kind == 3:
        k = rng.randrange(n)
        joints[k] = (joints[k][0], "nowhere", joints[k][2])
        what = f"joint {joints[k][0]}'s parent undeclared"
    else:
        del link_xml[rng.randrange(len(link_xml))]
        what = "a used link not declared"
    joint_xml = [f'<joint name="{j}" type="revolute"><parent link="{p}"/><child link="{c}"/>'
                 f'<origin xyz="0.1 0 0"/><axis xyz="0 0 1"/><limit lower="-1" upper="1"/></joint>'
                 for j, p, c in joints]
    body = link_xml + joint_xml
    rng.shuffle(body)
    return what, '<robot name="r">' + "".join(body) + "</robot>"


def urdf_structure(scale: int, seed: int = 33) -> Family:
    """URDFs with duplicate link or joint names, or joints whose links are not declared: refused."""
    fam = Family("URDF structure")
    t0 = time.perf_counter()
    rng = random.Random(seed)
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        for i in range(50 * scale):
            what, text = _urdf(rng)
            if what == "renamed":  # the draw left the names unique: not damage
                continue
            f = d / f"r{i}.urdf"
            f.write_text(text)
            _one(fam, ["analyze", "--robot", str(f), "--poses", "5"], d, what, _refused)
    fam.elapsed_s = time.perf_counter() - t0
    return fam


# ------------------------------------------------------------------ family: float limits

_HUGE = ["1e308", "-1e308", "1.7976931348623157e308", "1e300", "-1e300", "1e200", "1e20", "1e9", "-1e9", "4e5"]
_TINY = ["5e-324", "-0.0", "1e-320", "2.2250738585072014e-308", "0.0", "-5e-324"]
_POSE_ROW = ["10", "45", "-50", "0", "812.331", "402.118", "431.072", "0.0012", "-0.0031", "55.0004"]
_ROBOT_SPOTS = ["z = 800.0", "x = 445.0", "x = 355.0", "z = -240.0", "limits = [-130.0, 130.0]"]


def float_limits(scale: int, seed: int = 33) -> Family:
    """Values at and beyond the float limits in joint files, pose files and robot files: beyond
    physical plausibility refused (exit 2), tiny and signed zeros taken as values; never internal."""
    fam = Family("float limits")
    t0 = time.perf_counter()
    rng = random.Random(seed)
    sr800 = resources.files("station.io.robots").joinpath("sr800.toml").read_text()
    jh = "q1 [deg],q2 [deg],q3 [mm],q4 [deg]"
    ph = jh + ",x [mm],y [mm],z [mm],roll [deg],pitch [deg],yaw [deg]"
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        (d / "good.csv").write_text(ph + "\n" + (",".join(_POSE_ROW) + "\n") * 3)
        (d / "j.csv").write_text(jh + "\n10,20,-50,0\n")
        for i in range(120 * scale):
            huge = rng.random() < 0.7
            v = rng.choice(_HUGE if huge else _TINY)
            where = rng.randrange(4)
            if where == 0:  # a joint
                row = ["10", "20", "-50", "0"]
                row[rng.randrange(4)] = v
                f = d / f"j{i}.csv"
                f.write_text(jh + "\n" + ",".join(row) + "\n")
                argv = (["predict", "sr800", str(f)] if i % 2 else
                        ["analyze", "--robot", "sr800", "--joints", str(f)])
                what = f"joint {v}: {argv[0]}"
                refused = huge  # 4e5 deg is beyond 3600 deg; in q3, 4e5 mm is 400 m > 100 m
            elif where == 1:  # a measured value
                row = list(_POSE_ROW)
                k = rng.randrange(len(row))
                row[k] = v
                f = d / f"p{i}.csv"
                f.write_text(ph + "\n" + ",".join(_POSE_ROW) + "\n" + ",".join(row) + "\n")
                argv = ["validate", "sr800", str(f)] if i % 2 else ["validate", "sr800", str(d / "good.csv"),
                                                                  "--calibration", str(f)]
                what = f"pose column {k + 1} = {v}: {' '.join(argv[:1])}"
                refused = huge and (k < 4 or v not in ("1e9", "-1e9", "4e5"))  # positions: 1000 km bound
            else:  # a robot file's length, angle or limit
                spot = rng.choice(_ROBOT_SPOTS)
                new = spot.split("=")[0] + "= " + (f"[-130.0, {v}]" if spot.startswith("limits") else v)
                f = d / f"r{i}.toml"
                f.write_text(sr800.replace(spot, new, 1))
                argv = ["predict", str(f), str(d / "j.csv")]
                what = f"robot {new}: predict"
                refused = huge
            if refused:
                _one(fam, argv, d, what, _refused)
            else:
                _one(fam, argv, d, what, lambda rc: True)
            f.unlink()
    fam.elapsed_s = time.perf_counter() - t0
    return fam


# ------------------------------------------------------------------ family: overflowing integers

_INTS = ["9223372036854775808", "9223372036854775807", "18446744073709551616", "-9223372036854775809",
         "99999999999999999999", "1" + "0" * 400, "-1", "0", "1e3", "0x10", "4294967296", "-4294967296"]
_INT_OPTIONS: list[tuple[list[str], str]] = [
    (["report", "{v}", "--db", "{db}"], "run"), (["export", "--db", "{db}", "--run", "{v}", "{d}/m.csv"], "run"),
    (["runs", "--db", "{db}", "--unlock", "{v}"], "run"),
    (["calibrate", "--simulated", "--resume", "{v}", "--db", "{db}"], "run"),
    (["recheck", "--simulated", "--resume", "{v}", "--db", "{db}"], "run"),
    (["recheck", "--simulated", "--baseline", "{v}", "--db", "{db}"], "run"),
    (["calibrate", "--simulated", "--seed", "{v}", "--db", "{db}"], "seed"),
    (["recheck", "--simulated", "--seed", "{v}", "--db", "{db}"], "seed"),
    (["analyze", "--robot", "sr800", "--seed", "{v}", "--poses", "5"], "seed"),
    (["analyze", "--robot", "sr800", "--poses", "{v}"], "poses"),
    (["analyze", "--robot", "sr800", "--objective", "distance", "--distances", "{v}", "--poses", "5"], "count"),
    (["identify", "{d}/p.csv", "--objective", "distance", "--max-pairs", "{v}"], "count"),
    (["study", "--robot", "sr800", "--sets", "{v}", "--quick"], "count"),
    (["recheck", "--simulated", "--poses", "{v}", "--db", "{db}"], "recheck poses"),
]
_VALID = {"run": lambda n: 1 <= n < 2**63, "seed": lambda n: 0 <= n < 2**32, "poses": lambda n: 1 <= n <= 10_000,
          "count": lambda n: 1 <= n <= 10_000_000, "recheck poses": lambda n: 3 <= n <= 100}


def overflowing_integers(scale: int, seed: int = 33) -> Family:
    """Every integer option and argument with values beyond its range (above 2^63, negative,
    thousands of digits, not decimal): a usage error (exit 2), never OverflowError, never exit 0."""
    fam = Family("overflowing integers")
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        db = d / "runs.sqlite"
        (d / "p.csv").write_text("q1 [deg],q2 [deg],q3 [mm],q4 [deg],x [mm],y [mm],z [mm]\n10,45,-50,0,812,402,431\n")
        for _ in range(scale):
            for argv, kind in _INT_OPTIONS:
                for v in _INTS:
                    try:
                        n = int(v)
                    except ValueError:
                        n = None
                    if n is not None and _VALID[kind](n):
                        continue  # in range: not an overflowing input (it would run the command)
                    words = [a.format(v=v, db=db, d=d) for a in argv]
                    _one(fam, words, d, " ".join(words[:4]), _refused)
                    if db.exists():
                        db.unlink()
    fam.elapsed_s = time.perf_counter() - t0
    return fam


# ------------------------------------------------------------------ family: full disk

def full_disk(scale: int, seed: int = 33) -> Family:
    """Every command that writes a file the user names, onto a full disk (``/dev/full``, ENOSPC):
    refused with a message naming the file (exit 2 or 5), never an internal error, never exit 0."""
    fam = Family("full disk")
    t0 = time.perf_counter()
    if not os.path.exists("/dev/full"):
        return fam
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        good = _good_db(d)
        (d / "targets.csv").write_text("x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg\n600,100,400,0,0,30\n")
        _in_process(["export", "--db", str(good), "--run", "1", "--format", "identify", str(d / "p.csv")], d)
        full = "/dev/full"
        commands = [["export-model", "sr800", "--format", f, "-o", full] for f in ("toml", "urdf", "dh", "mdh")]
        commands += [["identify", str(d / "p.csv"), "--robot", "sr800", "-o", full],
                     ["export", "--db", str(good), "--run", "1", full],
                     ["export", "--db", str(good), "--run", "1", "--format", "identify", full],
                     ["compensate", "sr800", str(d / "targets.csv"), "-o", full],
                     ["init", full, "--force"],
                     ["report", "1", "--db", str(good), "-o", full]]
        for _ in range(scale):
            for argv in commands:
                _one(fam, argv, d, " ".join(argv[:3]), _refused)
        # a disk that fills up while the command writes: a file-size limit (EFBIG, SIGXFSZ ignored)
        for limit, argv in ((2_000, ["report", "1", "--db", str(good), "-o", str(d / "rep")]),
                            (64_000, ["report", "1", "--db", str(good), "-o", str(d / "rep")]),
                            (40_000, ["export", "--db", str(good), "--run", "1", str(d / "m.csv")]),
                            (200_000, ["calibrate", "--simulated", "--seed", "1", "--db", str(d / "new.sqlite")])):
            with _file_size_limit(limit):
                _one(fam, argv, d, f"{' '.join(argv[:2])} with files limited to {limit} bytes", _refused)
    fam.elapsed_s = time.perf_counter() - t0
    return fam


@contextlib.contextmanager
def _file_size_limit(n_bytes: int) -> Iterator[None]:
    """Writes beyond ``n_bytes`` per file fail with EFBIG, as on a disk that has just filled up."""
    import resource
    import signal

    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    old = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (n_bytes, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
        signal.signal(signal.SIGXFSZ, old)


FAMILIES = {"fields": record_fields, "typos": robot_typos, "urdf": urdf_structure, "floats": float_limits,
            "ints": overflowing_integers, "disk": full_disk}
