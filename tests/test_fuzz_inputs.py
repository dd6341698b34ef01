"""Fuzz campaign over the files and arguments a user hands the station (issue 12): the cell
configuration (TOML text and structured mutations), robot files (TOML, DH/MDH CSV, URDF), data
files (``read_measurements`` and ``station identify``) and the CLI of the commands that read files
without devices (``analyze --robot``, ``predict``, ``export``).

Every input must end in a typed error (a :class:`StationError`, or a CLI exit code other than 1
with no traceback on stderr) or be accepted, within a time budget per input. The examples are
derandomized, so CI sees the same inputs every run. ``benchmarks/fuzz_campaign.py`` runs the same
targets with more examples and prints the counts.
"""

from __future__ import annotations

import contextlib
import copy
import io
import os
import signal
import tempfile
import tomllib
from collections.abc import Callable
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from station.cell.config.cell_config import parse_config, parse_text
from station.cell.config.template import TEMPLATE
from station.errors import StationError

#: seconds one input may take before it counts as a hang (a parse takes milliseconds; an
#: identification on a small file well under a second)
BUDGET_S = 10

# ------------------------------------------------------------------------------------ outcome

class Hang(Exception):
    pass


class Traceback_(AssertionError):
    """An input ended in an untyped exception or an internal error (exit code 1)."""


@contextlib.contextmanager
def time_budget(seconds: int = BUDGET_S):
    """Raise :class:`Hang` when the block runs longer than ``seconds`` (SIGALRM: interrupts a
    blocking open or read too)."""
    def on_alarm(signum, frame):
        raise Hang(f"no result after {seconds} s")

    old = signal.signal(signal.SIGALRM, on_alarm)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def call_typed(fn: Callable[[], Any]) -> str:
    """``"accepted"`` or ``"refused"`` (a StationError); anything else raises Traceback_/Hang."""
    try:
        with time_budget():
            fn()
    except StationError:
        return "refused"
    except Hang:
        raise
    except Exception as exc:  # noqa: BLE001 - this is what the campaign looks for
        raise Traceback_(f"{type(exc).__name__}: {exc}") from exc
    return "accepted"


def run_cli(argv: list[str], workdir: Path) -> str:
    """``station ARGV`` in ``workdir`` (internal-error logs land there): ``accepted`` (exit 0),
    ``refused`` (another documented exit code, no traceback); exit 1 or a traceback raises."""
    from station.ui.cli.main import main

    out, err = io.StringIO(), io.StringIO()
    cwd = os.getcwd()
    os.chdir(workdir)
    try:
        with time_budget(), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                rc = main(argv)
            except SystemExit as exc:  # argparse: a usage error
                rc = exc.code if isinstance(exc.code, int) else 2
    except Hang:
        raise
    except Exception as exc:  # noqa: BLE001
        raise Traceback_(f"station {argv}: {type(exc).__name__}: {exc}") from exc
    finally:
        os.chdir(cwd)
    text = err.getvalue()
    if rc == 1 or "Traceback" in text:
        raise Traceback_(f"station {argv} exited {rc}: {text.strip()[-400:]}")
    return "accepted" if rc == 0 else "refused"


# ------------------------------------------------------------------------------ value strategies

NASTY_LITERALS = [
    "nan", "-nan", "inf", "-inf", "0", "-0", "0.0", "-1", "1e308", "-1e308", "1e-320", "9223372036854775807",
    "-9223372036854775808", "true", "false", '""', '"x"', '"\\u0000"', '"../../etc/passwd"', '"/dev/zero"',
    "[]", "[[]]", "[1, 2]", "[nan, 125.0]", "[125.0, -125.0]", "[inf, 1]", '["a", "b"]', "{}", "{ a = 1 }",
    "1979-05-27T07:32:00Z", "0x10", "1_000", "[1, -1, 1]", "[-1]", "[2]", "5", "4.5", "1e9", "100000000",
]

toml_scalars = st.one_of(
    st.integers(min_value=-(2**63), max_value=2**63 - 1),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=20),
    st.booleans(),
)
toml_values = st.recursive(toml_scalars, lambda inner: st.one_of(
    st.lists(inner, max_size=6), st.dictionaries(st.text(max_size=8), inner, max_size=4)), max_leaves=12)

# ------------------------------------------------------------------------------ configuration

TEMPLATE_DATA = tomllib.loads(TEMPLATE)
_VALUE_LINES = [i for i, ln in enumerate(TEMPLATE.splitlines()) if " = " in ln and not ln.lstrip().startswith("#")]


@st.composite
def config_texts(draw) -> str:
    """The template with one line's value replaced, or a slice deleted, inserted or duplicated."""
    lines = TEMPLATE.splitlines()
    how = draw(st.sampled_from(["value", "value", "value", "delete", "insert", "duplicate", "truncate"]))
    if how == "value":
        i = draw(st.sampled_from(_VALUE_LINES))
        key = lines[i].split(" = ")[0]
        value = draw(st.one_of(st.sampled_from(NASTY_LITERALS), st.integers().map(str),
                               st.floats().map(lambda f: repr(f).replace("nan", "nan").replace("inf", "inf"))))
        lines[i] = f"{key} = {value}"
    elif how == "delete":
        i = draw(st.integers(0, len(lines) - 1))
        del lines[i:i + draw(st.integers(1, 4))]
    elif how == "insert":
        i = draw(st.integers(0, len(lines)))
        lines.insert(i, draw(st.one_of(st.sampled_from(["[plan]", "[[body]]", "x = 1", "[robot]\nmodel = 1",
                                                        "samples = 5", "]", "= =", '"""']),
                                       st.text(max_size=30))))
    elif how == "duplicate":
        i = draw(st.integers(0, len(lines) - 1))
        lines.insert(i, lines[i])
    else:
        return TEMPLATE[: draw(st.integers(0, len(TEMPLATE)))]
    return "\n".join(lines) + "\n"


@st.composite
def config_dicts(draw) -> dict:
    """The template's parsed data with one key set to an arbitrary TOML value, deleted, or one
    section replaced."""
    data = copy.deepcopy(TEMPLATE_DATA)
    section = draw(st.sampled_from(sorted(data) + ["simulation", "unknown"]))
    how = draw(st.sampled_from(["set", "set", "set", "delete", "section"]))
    if how == "section" or not isinstance(data.get(section), dict):
        data[section] = draw(toml_values)
        return data
    table = data[section]
    key = draw(st.sampled_from(sorted(table) + ["seed", "samples", "points", "joints", "colour"]))
    if how == "delete":
        table.pop(key, None)
    elif key == "points" and isinstance(table.get("points"), list) and draw(st.booleans()):
        k = draw(st.integers(0, len(table["points"]) - 1))
        table["points"][k] = dict(table["points"][k], **{draw(st.sampled_from(["id", "pose", "x"])): draw(toml_values)})
    else:
        table[key] = draw(toml_values)
    return data


# ------------------------------------------------------------------------------ robot files

SR800_TOML = resources.files("station.io.robots").joinpath("sr800.toml").read_text()
SR800_DATA = tomllib.loads(SR800_TOML)
DH_HEADER = ["type", "theta [deg]", "d [mm]", "a [mm]", "alpha [deg]", "lower [deg|mm]", "upper [deg|mm]"]
DH_ROWS = [["revolute", "0", "0", "445", "0", "-130", "130"], ["revolute", "0", "0", "355", "0", "-140", "140"],
           ["prismatic", "0", "0", "0", "180", "-195", "-5"], ["revolute", "0", "0", "0", "0", "-355", "355"]]
CELL_TOKENS = ["nan", "inf", "-inf", "", "x", "1e400", "-0", "revolute", "prismatic", "fixed", "1,2", '"', "[deg]",
               "0 0", "1e308", "-1e308", "\x00", "é"]

URDF_JOINTS = [("j1", "base", "l1", "revolute", "0 0 0.2", "0 0 1", "-2 2"),
               ("j2", "l1", "l2", "revolute", "0.4 0 0", "0 0 1", "-2 2"),
               ("j3", "l2", "l3", "prismatic", "0.3 0 0", "0 0 -1", "-0.2 0"),
               ("j4", "l3", "tool", "revolute", "0 0 0", "0 0 1", "-6 6")]


def urdf_text(joints=URDF_JOINTS, drop: str = "", attr: tuple[str, str] | None = None) -> str:
    links = "".join(f'<link name="{n}"/>' for n in ("base", "l1", "l2", "l3", "tool"))
    out = []
    for name, parent, child, kind, xyz, axis, lim in joints:
        lo, _, hi = lim.partition(" ")
        parts = {"parent": f'<parent link="{parent}"/>', "child": f'<child link="{child}"/>',
                 "origin": f'<origin xyz="{xyz}" rpy="0 0 0"/>', "axis": f'<axis xyz="{axis}"/>',
                 "limit": f'<limit lower="{lo}" upper="{hi}" effort="1" velocity="1"/>'}
        if drop in parts and name == "j2":
            del parts[drop]
        if attr and name == "j2":
            tag, value = attr
            if tag in parts:
                parts[tag] = parts[tag].split('="')[0] + f'="{value}"' + ("/>" if tag != "limit" else f' upper="{hi}"/>')
        out.append(f'<joint name="{name}" type="{kind}">' + "".join(parts.values()) + "</joint>")
    return f'<?xml version="1.0"?><robot name="arm">{links}{"".join(out)}</robot>'


@st.composite
def robot_files(draw) -> tuple[str, bytes]:
    """(file name, content): a TOML robot with one mutated field, a DH/MDH CSV with mutated
    cells or shape, a URDF with a dropped element or a bad attribute, or raw bytes."""
    kind = draw(st.sampled_from(["toml", "dh", "urdf", "raw"]))
    if kind == "toml":
        data = copy.deepcopy(SR800_DATA)
        if draw(st.booleans()):
            data["robot"][draw(st.sampled_from(["name", "prefer", "angle_unit", "length_unit", "x"]))] = draw(toml_values)
        else:
            k = draw(st.integers(0, len(data["transform"]) - 1))
            field = draw(st.sampled_from(["name", "joint", "limits", "x", "y", "z", "roll", "pitch", "yaw", "bogus"]))
            data["transform"][k][field] = draw(toml_values)
        import tomli_w

        try:
            text = tomli_w.dumps(data)
        except (TypeError, ValueError):  # a value TOML cannot hold: write the text by hand
            text = SR800_TOML.replace("[robot]", f"[robot]\nx = {draw(st.sampled_from(NASTY_LITERALS))}", 1)
        return "r.toml", text.encode()
    if kind == "dh":
        rows = [list(DH_HEADER)] + [list(r) for r in DH_ROWS]
        for _ in range(draw(st.integers(1, 3))):
            how = draw(st.sampled_from(["cell", "cell", "header", "drop_row", "drop_col", "add_col"]))
            if how == "cell" and len(rows) > 1:
                i, j = draw(st.integers(1, len(rows) - 1)), draw(st.integers(0, 6))
                if j < len(rows[i]):
                    rows[i][j] = draw(st.one_of(st.sampled_from(CELL_TOKENS), st.floats().map(repr)))
            elif how == "header":
                j = draw(st.integers(0, len(rows[0]) - 1))
                rows[0][j] = draw(st.sampled_from(["theta", "theta [furlong]", "d [m]", "lower [rad]", "type", "", "x [mm]"]))
            elif how == "drop_row" and len(rows) > 1:
                del rows[draw(st.integers(0, len(rows) - 1))]
            elif how == "drop_col":
                j = draw(st.integers(0, 6))
                for r in rows:
                    if j < len(r):
                        del r[j]
            else:
                rows[draw(st.integers(0, len(rows) - 1))].append("7")
        name = draw(st.sampled_from(["r.dh.csv", "r.mdh.csv"]))
        return name, ("\n".join(",".join(r) for r in rows) + "\n").encode("utf-8", "surrogatepass")
    if kind == "urdf":
        how = draw(st.sampled_from(["drop", "attr", "kind", "cycle", "truncate"]))
        if how == "drop":
            text = urdf_text(drop=draw(st.sampled_from(["parent", "child", "origin", "axis", "limit"])))
        elif how == "attr":
            text = urdf_text(attr=(draw(st.sampled_from(["origin", "axis", "limit"])),
                                   draw(st.sampled_from(["0 0", "nan nan nan", "", "a b c", "1e400 0 0", "0 0 0",
                                                         "1 2 3 4", "nan", "inf 0 0", "-inf"]))))
        elif how == "kind":
            j = list(URDF_JOINTS)
            j[1] = j[1][:3] + (draw(st.sampled_from(["floating", "planar", "", "continuous", "fixed"])),) + j[1][4:]
            text = urdf_text(j)
        elif how == "cycle":
            j = list(URDF_JOINTS)
            j[3] = ("j4", "l3", "base", *j[3][3:])
            text = urdf_text(j)
        else:
            full = urdf_text()
            text = full[: draw(st.integers(0, len(full)))]
        return "r.urdf", text.encode()
    return draw(st.sampled_from(["r.toml", "r.dh.csv", "r.urdf"])), draw(st.binary(max_size=200))


# ------------------------------------------------------------------------------ data files

def _pose_file_text() -> str:
    from station.core.kinematics.poses import spread_joints
    from station.core.kinematics.transforms import matrix_to_pose
    from station.core.measurement.measurements import synthetic_set
    from station.io.robot.files import load_robot

    model = load_robot("sr800")
    rng = np.random.default_rng(7)
    q = spread_joints(model, 12, rng)
    data = synthetic_set(model, "pose", q, model.nominal, sigma=np.array([0.005] * 3 + [2.4e-5] * 3), rng=rng)
    pose = matrix_to_pose(data.measured)
    qd = np.array(q)
    qd[:, [0, 1, 3]] = np.degrees(qd[:, [0, 1, 3]])
    pose[:, 3:] = np.degrees(pose[:, 3:])
    head = "q1 [deg],q2 [deg],q3 [mm],q4 [deg],x [mm],y [mm],z [mm],roll [deg],pitch [deg],yaw [deg]"
    return head + "\n" + "\n".join(",".join(repr(float(v)) for v in row) for row in np.column_stack([qd, pose])) + "\n"


POSE_FILE = _pose_file_text()


@st.composite
def data_files(draw) -> bytes:
    """The pose file with mutated cells, header units, rows or columns, a BOM, or raw bytes."""
    lines = POSE_FILE.splitlines()
    how = draw(st.sampled_from(["cell", "cell", "header", "drop_rows", "drop_col", "dup_rows", "bom", "raw", "zeros"]))
    rows = [ln.split(",") for ln in lines]
    if how == "cell":
        for _ in range(draw(st.integers(1, 3))):
            i, j = draw(st.integers(1, len(rows) - 1)), draw(st.integers(0, 9))
            rows[i][j] = draw(st.one_of(st.sampled_from(CELL_TOKENS), st.floats().map(repr)))
    elif how == "header":
        j = draw(st.integers(0, 9))
        rows[0][j] = draw(st.sampled_from(["q1", "q1 [furlong]", "q3 [deg]", "x [m]", "q9 [deg]", "x [mm]", "", "roll [rad]"]))
    elif how == "drop_rows":
        rows = rows[: draw(st.integers(0, len(rows)))]
    elif how == "drop_col":
        j = draw(st.integers(0, 9))
        rows = [r[:j] + r[j + 1:] for r in rows]
    elif how == "dup_rows":
        rows = rows[:1] + [rows[1]] * draw(st.integers(2, 30))
    elif how == "zeros":
        rows = rows[:1] + [["0"] * 10] * draw(st.integers(2, 20))
    text = "\n".join(",".join(r) for r in rows) + "\n"
    if how == "bom":
        return b"\xef\xbb\xbf" + text.encode()
    if how == "raw":
        return draw(st.binary(max_size=300))
    return text.encode("utf-8", "surrogatepass")


# ------------------------------------------------------------------------------ the CLI

def _special_paths(d: Path) -> dict[str, str]:
    fifo = d / "fifo.csv"
    if not fifo.exists():
        os.mkfifo(fifo)
    (d / "dir.dh.csv").mkdir(exist_ok=True)
    (d / "empty.toml").write_text("")
    (d / "text.urdf").write_text("not xml")
    (d / "joints.csv").write_text("q1 [deg],q2 [deg],q3 [mm],q4 [deg]\n0,10,-100,0\n5,-10,-50,90\n")
    (d / "bad_joints.csv").write_text("q1 [deg],q2 [deg],q3 [mm],q4 [deg]\nnan,10,-100,0\n0,1e400,-50,90\n")
    (d / "robot.urdf").write_text(urdf_text())
    (d / "db.sqlite").write_bytes(b"SQLite format 3\x00" + b"\x00" * 100)
    return {"fifo": str(fifo), "dir": str(d / "dir.dh.csv"), "empty": str(d / "empty.toml"),
            "text": str(d / "text.urdf"), "zero": "/dev/zero", "null": "/dev/null", "missing": str(d / "no.toml"),
            "joints": str(d / "joints.csv"), "bad_joints": str(d / "bad_joints.csv"), "urdf": str(d / "robot.urdf"),
            "db": str(d / "db.sqlite"), "sr800": "sr800", "long": "x" * 5000}  # argv never holds a NUL


@st.composite
def cli_args(draw) -> list[str]:
    """argv of analyze / predict / export with odd paths and numbers (keys of _special_paths)."""
    path = st.sampled_from(["fifo", "dir", "empty", "text", "zero", "null", "missing", "joints", "bad_joints",
                            "urdf", "sr800", "long"])
    number = st.sampled_from(["0", "-1", "1", "2", "7", "nan", "x", "1e3", "100"])
    cmd = draw(st.sampled_from(["analyze", "analyze", "predict", "predict", "export"]))
    if cmd == "analyze":
        argv = ["analyze", "--robot", "@" + draw(path)]
        if draw(st.booleans()):
            argv += ["--poses", draw(number)]
        if draw(st.booleans()):
            argv += ["--joints", "@" + draw(path)]
        if draw(st.booleans()):
            argv += ["--kind", draw(st.sampled_from(["pose", "position", "distance", "bogus"]))]
        if draw(st.booleans()):
            argv += ["--prefer", draw(st.sampled_from(["K.x", "Q.q", ",", "", "K.x,K.x"]))]
        return argv
    if cmd == "predict":
        return ["predict", "@" + draw(path), "@" + draw(path)] + (["--json"] if draw(st.booleans()) else [])
    argv = ["export", "--db", "@" + draw(st.sampled_from(["db", "fifo", "dir", "zero", "missing", "empty"]))]
    if draw(st.booleans()):
        argv += ["--run", draw(number)]
    return argv + ["@" + draw(st.sampled_from(["dir", "missing", "null", "long"]))]


# ------------------------------------------------------------------------------ the targets

def _write(d: Path, name: str, content: bytes) -> Path:
    p = d / name
    p.write_bytes(content)
    return p


def check_config_text(text: str, d: Path) -> str:
    return call_typed(lambda: parse_text(text, str(d / "cell.toml")))


def check_config_dict(data: dict, d: Path) -> str:
    return call_typed(lambda: parse_config(data, str(d / "cell.toml")))


def check_robot_file(case: tuple[str, bytes], d: Path) -> str:
    from station.io.robot.files import load_robot

    p = _write(d, *case)
    return call_typed(lambda: load_robot(p))


def check_config_file(case: tuple[str, bytes], d: Path) -> str:
    """A configuration whose robot is the fuzzed robot file, read through load_config."""
    from station.cell.config.cell_config import load_config

    robot = _write(d, *case)
    cfg = _write(d, "cell.toml", TEMPLATE.replace('model = "sr800"', f'model = "{robot.name}"').encode())
    return call_typed(lambda: load_config(cfg))


def check_data_file(content: bytes, d: Path) -> str:
    from station.io.datafile import read_measurements
    from station.io.robot.files import load_robot

    p = _write(d, "data.csv", content)
    return call_typed(lambda: read_measurements(p, load_robot("sr800")))


def check_identify(content: bytes, d: Path) -> str:
    p = _write(d, "data.csv", content)
    return run_cli(["identify", str(p)], d)


def check_cli(argv: list[str], d: Path) -> str:
    paths = _special_paths(d)
    return run_cli([paths[a[1:]] if a.startswith("@") else a for a in argv], d)


@dataclass(frozen=True)
class Target:
    category: str
    name: str
    strategy: Any
    check: Callable[[Any, Path], str]
    examples: int  # in the test; the campaign script multiplies


TARGETS = [
    Target("configuration", "TOML text", config_texts(), check_config_text, 90),
    Target("configuration", "structured", config_dicts(), check_config_dict, 90),
    Target("robot files", "TOML, DH/MDH CSV, URDF, bytes", robot_files(), check_robot_file, 70),
    Target("robot files", "via load_config", robot_files(), check_config_file, 20),
    Target("data files", "read_measurements", data_files(), check_data_file, 40),
    Target("data files", "station identify", data_files(), check_identify, 15),
    Target("CLI", "analyze / predict / export", cli_args(), check_cli, 30),
]

FUZZ_SETTINGS = dict(derandomize=True, database=None, deadline=None, print_blob=False,
                     suppress_health_check=list(HealthCheck))


@pytest.mark.parametrize("target", TARGETS, ids=[f"{t.category}: {t.name}" for t in TARGETS])
def test_fuzz_typed_errors_only_and_no_hang(target: Target):
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)

        @settings(max_examples=target.examples, **FUZZ_SETTINGS)
        @given(target.strategy)
        def one(case):
            target.check(case, d)  # raises Traceback_ or Hang

        one()


def test_the_campaign_tries_at_least_300_inputs():
    assert sum(t.examples for t in TARGETS) >= 300


def test_the_harness_sees_a_traceback_and_a_hang(tmp_path):
    with pytest.raises(Traceback_):
        call_typed(lambda: {}["x"])
    with pytest.raises(Hang):
        with time_budget(1):
            while True:
                pass
    assert call_typed(lambda: parse_text("[robot")) == "refused"
    assert run_cli(["predict", "sr800", "/dev/zero"], tmp_path) == "refused"
