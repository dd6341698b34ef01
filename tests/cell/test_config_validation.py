"""Configuration validation (issue 12): bounds on every number, finite ordered limits, the
correction grid and σ checked at load time, typed errors naming the key; robot files and
configuration files refused before reading when they are not regular files; CSV export safe to
open in a spreadsheet."""

from __future__ import annotations

import csv
import os
import re

import numpy as np
import pytest

from drivers.controller_map import MAX_TABLE_VALUES
from station.cell.config import cell_config as cfgmod
from station.cell.config import schema
from station.cell.config.cell_config import correction_grid, load_config, parse_config, parse_text
from station.cell.config.template import TEMPLATE
from station.cell.records.reading.run_export import csv_text, export_csv
from station.cell.records.rundb import RunDB
from station.errors import ConfigError
from station.io.robot.files import load_robot

DH_HEADER = "type,theta [deg],d [mm],a [mm],alpha [deg],lower [deg|mm],upper [deg|mm]\n"
DH_ROWS = ["revolute,0,0,445,0,-130,130", "revolute,0,0,355,0,-140,140",
           "prismatic,0,0,0,180,-195,-5", "revolute,0,0,0,0,-355,355"]


def bad(old: str, new: str, template: str = TEMPLATE) -> str:
    assert old in template, old
    return template.replace(old, new, 1)


#: the template with its commented grid keys given: an explicit grid instead of the station's design
EXPLICIT = TEMPLATE
for _k in ("x_mm", "y_mm", "z_mm", "yaw_step_deg"):
    EXPLICIT = EXPLICIT.replace(f"# {_k} = ", f"{_k} = ", 1)


def refused(text: str, *patterns: str) -> str:
    with pytest.raises(ConfigError) as info:
        parse_text(text, "cell.toml")
    msg = str(info.value)
    for p in patterns:
        assert re.search(p, msg), (p, msg)
    return msg


# ------------------------------------------------------------------------------ numeric bounds

def _numeric_fields():
    """(section, key, FieldInfo) of every bounded number of the schema."""
    for section, sinfo in schema._CellFile.model_fields.items():
        model = schema._section_of(sinfo.annotation)
        for key, info in model.model_fields.items():
            if info.annotation in (int, float) and schema.bounds_text(info):
                yield section, key, info


NUMERIC = list(_numeric_fields())


def test_every_number_has_bounds():
    keys = {f"{s}.{k}" for s, k, _ in NUMERIC}
    for key in ("plan.samples", "plan.repeats", "plan.verification_cycles", "plan.settle_s",
                "plan.select", "devices.motion_timeout_s", "identification.sigma_position_um",
                "identification.sigma_angle_arcsec", "correction.yaw_step_deg", "simulation.seed"):
        assert key in keys
    for section, sinfo in schema._CellFile.model_fields.items():  # no unbounded number anywhere
        model = schema._section_of(sinfo.annotation)
        for key, info in model.model_fields.items():
            if info.annotation in (int, float):
                assert schema.bounds_text(info), f"{section}.{key} has no bounds"


@pytest.mark.parametrize("section,key,info", [n for n in NUMERIC if n[0] != "simulation"],
                         ids=[f"{s}.{k}" for s, k, _ in NUMERIC if s != "simulation"])
def test_template_states_the_bounds(section, key, info):
    """The template's comment on each number states the schema's bounds (one source)."""
    line = next(ln for ln in TEMPLATE.splitlines() if ln.startswith((f"{key} =", f"# {key} =")))
    assert schema.bounds_text(info) in line, (line, schema.bounds_text(info))


def _limit(info, kind):
    import annotated_types as at

    for m in info.metadata:
        if kind == "low" and isinstance(m, (at.Ge, at.Gt)):
            return (m.ge if isinstance(m, at.Ge) else m.gt), isinstance(m, at.Gt)
        if kind == "high" and isinstance(m, at.Le):
            return m.le, False
    raise AssertionError(info)


@pytest.mark.parametrize("section,key,info", NUMERIC, ids=[f"{s}.{k}" for s, k, _ in NUMERIC])
def test_out_of_bounds_names_key_and_range(section, key, info):
    """Just outside each bound, a bool and a string: refused, naming the key and the range."""
    text = TEMPLATE if f"[{section}]" in TEMPLATE else TEMPLATE + f"\n[{section}]\n"
    header = f"[{section}]\n"
    lo, lo_open = _limit(info, "low")
    hi, _ = _limit(info, "high")
    is_int = info.annotation is int
    below = lo if lo_open else (lo - 1 if is_int else lo - abs(lo) * 0.01 - 0.001)
    above = hi + 1 if is_int else hi * 1.01 + 0.001
    for v in (below, above, "true", '"3"', "nan" if not is_int else "1.5"):
        lines = [ln for ln in text.splitlines() if not ln.startswith(f"{key} =")]
        t = ("\n".join(lines) + "\n").replace(header, f"{header}{key} = {v}\n", 1)
        refused(t, re.escape(f"{section}.{key}"), re.escape(schema.bounds_text(info)))


def test_bounds_found_by_the_campaign_hang_no_more():
    for key, v in (("samples = 4 ", "samples = 100000000 "), ("repeats = 2", "repeats = 1000000"),
                   ("verification_cycles = 3", "verification_cycles = 999999"),
                   ("settle_s = 0.2", "settle_s = 1e12")):
        refused(bad(key, v), re.escape(f"plan.{v.split()[0]}"), "…")


def test_int_is_never_a_bool_or_float():
    refused(bad("device_id = 1", "device_id = true"), r"devices\.device_id", "integer")
    refused(bad("device_id = 1", "device_id = 1.0"), r"devices\.device_id", "integer")
    refused(bad("both_directions = false", "both_directions = 0"), r"plan\.both_directions", "true or false")


# ------------------------------------------------------------------------------------ limits

@pytest.mark.parametrize("pair,why", [
    ("[nan, 125.0]", "finite"), ("[-125.0, nan]", "finite"), ("[-inf, 125.0]", "finite"),
    ("[-125.0, inf]", "finite"), ("[125.0, -125.0]", "lower must be < upper"),
    ("[5.0, 5.0]", "lower must be < upper"), ("[-125.0, 300.0]", "exceed the robot's limits"),
    ('["a", 1]', "two numbers"), ("[1.0]", "two numbers"), ("5", "two numbers"),
])
def test_limits_finite_ordered_named_by_joint(pair, why):
    refused(bad("joints = [[-125.0, 125.0],", f"joints = [{pair},"), r"limits\.joints", "joint 1", re.escape(why))
    second = bad("[-140.0, 140.0]", pair)
    refused(second, r"limits\.joints", "joint 2", re.escape(why))


def test_limits_wrong_joint_count():
    refused(bad("[-355.0, 355.0]]", "[-355.0, 355.0], [-1.0, 1.0]]"), r"limits\.joints", "has 4")


def test_nan_limits_never_reach_the_soft_limits():
    cfg = parse_text(TEMPLATE)
    assert np.all(np.isfinite(cfg.soft_limits)) and np.all(cfg.soft_limits[:, 0] < cfg.soft_limits[:, 1])


# -------------------------------------------------------------------- grid and σ at load time

@pytest.mark.parametrize("old,new,pattern", [
    ("x_mm = [250.0, 650.0, 40.0]", "x_mm = [250.0, 650.0, 1.0]", r"32000"),  # capacity
    ("x_mm = [250.0, 650.0, 40.0]", "x_mm = [250.0, 650.0, 1e-6]", r"correction\.x_mm\[2\].*1 … 10000"),
    ("x_mm = [250.0, 650.0, 40.0]", "x_mm = [250.0, 650.0, 30.0]", r"correction\.x_mm: .*whole number"),
    ("x_mm = [250.0, 650.0, 40.0]", "x_mm = [650.0, 250.0, 40.0]", r"correction\.x_mm.*stop > start"),
    ("y_mm = [-350.0, 350.0, 50.0]", "y_mm = [-350.0, 350.0]", r"correction\.y_mm"),
    ("z_mm = [250.0, 450.0, 200.0]", "z_mm = [250.0, inf, 200.0]", r"correction\.z_mm\[1\].*finite"),
    ("yaw_step_deg = 30.0", "yaw_step_deg = 7.0", r"correction\.yaw_step_deg = 7: must divide 360.*use e\.g\. 6 or 7\.2"),
    ("yaw_step_deg = 30.0", "yaw_step_deg = 0.0", r"correction\.yaw_step_deg.*1 … 180"),
    ("sigma_position_um = 15.0", "sigma_position_um = 0.0", r"identification\.sigma_position_um.*0\.01 … 1000"),
    ("sigma_position_um = 15.0", "sigma_position_um = -3.0", r"identification\.sigma_position_um"),
    ("sigma_angle_arcsec = 20.0", "sigma_angle_arcsec = nan", r"identification\.sigma_angle_arcsec.*finite"),
    ("elbows = [1, -1]", "elbows = [-1, 1]", r"plan\.elbows.*\[1, -1\] or \[1\]"),
    ("elbows = [1, -1]", "elbows = [2]", r"plan\.elbows\[0\]"),
])
def test_grid_and_sigma_refused_when_the_file_is_read(old, new, pattern):
    refused(bad(old, new, EXPLICIT), pattern)


def test_a_grid_is_given_whole_or_designed():
    assert not parse_text(TEMPLATE).correction.explicit  # the template: the station designs the grid
    refused(bad("z_mm = [250.0, 450.0, 200.0]\n", "", EXPLICIT), r"correction: the grid is given by x_mm, y_mm and "
            r"z_mm together: add z_mm")
    refused(bad("# region = {", "region = {", EXPLICIT), r"either region .* or x_mm, y_mm, z_mm")
    refused(bad("# region = { x_mm = [300.0, 650.0]", "region = { x_mm = [650.0, 300.0]"), r"low < high")


def test_the_grid_checked_is_the_grid_the_pipeline_builds():
    cfg = parse_text(EXPLICIT)
    grid = correction_grid(cfg.correction, cfg.plan.elbows)
    grid.check_capacity(cfg.model.n_joints, MAX_TABLE_VALUES)
    assert grid.shape == (11, 15, 2, 12)


# ----------------------------------------------------------------------------- other keys

@pytest.mark.parametrize("old,new,pattern", [
    ("# prefer", "prefer = 5 #", r"identification\.prefer = 5: expected a list"),
    ("# prefer", 'prefer = ["Q.x"] #', r"identification\.prefer: unknown parameter 'Q\.x'"),
    ("# fix = []", "fix = [1]", r"identification\.fix\[0\]"),
    ('{ id = "C1.b"', '{ id = "C1.a"', r"body\.points: point id 'C1\.a' appears twice"),
    ('{ id = "C1.b"', "{ id = 7", r"body\.points\[1\]\.id"),
    ('{ id = "C1.b", pose = [11.1', '{ id = "C1.b", pose = [nan', r"body\.points\[1\]\.pose\[0\] = nan: not a finite"),
    ("setup = [-450.0, 0.0, -170.0, 0.0, 0.0, 0.0]", "setup = [1.0]", r"robot\.setup"),
    ("setup = [-450.0, 0.0, -170.0, 0.0, 0.0, 0.0]", "setup = [0.0, 0.0, 0.0, 0.0, 0.0, 999.0]", r"robot\.setup\[5\]"),
    ('controller = "192.168.0.10:502"', 'controller = "h:0"', r"devices\.controller = 'h:0'.*1 … 65535"),
    ('controller = "192.168.0.10:502"', 'controller = "h:²"', r"devices\.controller"),
    ('name = "cell 1"', 'name = "a\\u0000b"', r"cell\.name.*control characters"),
    ('model = "sr800"', 'model = "/dev/zero"', r"/dev/zero: .*not a regular file"),
    ('model = "sr800"', 'model = "' + "x" * 300 + '"', r"cannot open the robot file"),
    ("[cell]", "[cell]\ncolour = 1", r"cell: unknown key 'colour'; allowed: name"),
    ("[plan]", "[plan]\nsamles = 3", r"plan: unknown key 'samles'; did you mean 'samples'\? allowed: "),
    ("[simulation]", "[simulation]\nseed = -1", r"simulation\.seed") if "[simulation]" in TEMPLATE
    else ("[cell]", "[simulation]\nseed = -1\n[cell]", r"simulation\.seed"),
])
def test_other_keys_name_the_key(old, new, pattern):
    refused(bad(old, new), pattern)


@pytest.mark.parametrize("data", [[], "x", 5, {"robot": 5}, {"robot": {"model": "sr800"}},
                                  {"robot": {"model": "sr800"}, "body": {"points": 3}}, {"body": {}}])
def test_structure_errors_are_config_errors(data):
    with pytest.raises(ConfigError):
        parse_config(data)  # type: ignore[arg-type]


def test_several_errors_reported_together():
    msg = refused(bad("samples = 4 ", "samples = 0 ").replace("repeats = 2", "repeats = 0"),
                  r"plan\.samples", r"plan\.repeats")
    assert "Traceback" not in msg


# ---------------------------------------------------------------------------------- files

def test_load_config_refuses_what_is_not_a_regular_file(tmp_path):
    with pytest.raises(ConfigError, match="not a regular file"):
        load_config("/dev/zero")
    with pytest.raises(ConfigError, match="directory"):
        load_config(tmp_path)
    fifo = tmp_path / "cell.toml"
    os.mkfifo(fifo)
    with pytest.raises(ConfigError, match="not a regular file"):
        load_config(fifo)  # refused from its stat: never opened, so never blocks
    big = tmp_path / "big.toml"
    with open(big, "wb") as f:
        f.truncate(cfgmod.MAX_CONFIG_BYTES + 1)
    with pytest.raises(ConfigError, match="bytes"):
        load_config(big)
    binary = tmp_path / "bin.toml"
    binary.write_bytes(b"\xff\xfe[cell]\n")
    with pytest.raises(ConfigError, match="UTF-8"):
        load_config(binary)
    with pytest.raises(ConfigError, match="station init"):
        load_config(tmp_path / "missing.toml")


def test_load_config_accepts_a_byte_order_mark(tmp_path):
    p = tmp_path / "cell.toml"
    p.write_bytes(b"\xef\xbb\xbf" + TEMPLATE.encode())
    assert load_config(p).model.name == "sr800"


def test_robot_files_refused_before_reading(tmp_path):
    with pytest.raises(ConfigError, match="not a regular file"):
        load_robot("/dev/zero")
    fifo = tmp_path / "robot.toml"
    os.mkfifo(fifo)
    with pytest.raises(ConfigError, match="not a regular file"):
        load_robot(fifo)
    big = tmp_path / "big.urdf"
    with open(big, "wb") as f:
        f.truncate(64 * 1024 * 1024)
    with pytest.raises(ConfigError, match="bytes"):
        load_robot(big)
    dh = tmp_path / "r.dh.csv"
    dh.write_bytes(DH_HEADER.encode() + b"revolute,\xff,0,0,0,-1,1\n")
    with pytest.raises(ConfigError, match="UTF-8"):
        load_robot(dh)


def test_nan_in_a_robot_file_is_named(tmp_path):
    dh = tmp_path / "r.dh.csv"
    dh.write_text(DH_HEADER + "\n".join(["revolute,0,nan,445,0,-130,130"] + DH_ROWS[1:]) + "\n")
    with pytest.raises(ConfigError, match=r"line 2: d must be a finite number, got 'nan'"):  # named where it is
        load_robot(dh)
    dh.write_text(DH_HEADER + "\n".join(["revolute,0,0,445,0,nan,130"] + DH_ROWS[1:]) + "\n")
    with pytest.raises(ConfigError, match=r"line 2: lower must be a finite number|joint 1 has limits \[nan"):
        load_robot(dh)
    urdf = tmp_path / "r.urdf"
    urdf.write_text('<robot name="r"><link name="a"/><link name="b"/><joint name="j" type="revolute">'
                    '<parent link="a"/><child link="b"/><origin xyz="nan 0 0"/></joint></robot>')
    with pytest.raises(ConfigError, match=r"parameter A1\.x is nan"):
        load_robot(urdf)
    toml = tmp_path / "r.toml"
    toml.write_text('[robot]\nname = "r"\n[[transform]]\nname = "R"\n[[transform]]\nname = "A1"\n'
                    'joint = "revolute"\nlimits = [-90, 90]\nz = nan\n[[transform]]\nname = "K"\n')
    with pytest.raises(ConfigError, match=r"A1\.z must be a finite number, got nan"):
        load_robot(toml)


@pytest.mark.parametrize("head,pattern", [
    ("prefer = 5", r"\[robot\]\.prefer must be a list"),
    ('prefer = [1]', r"\[robot\]\.prefer must be a list"),
    ("name = 5", r"'name' \(a string\)"),
])
def test_robot_file_types(tmp_path, head, pattern):
    toml = tmp_path / "r.toml"
    toml.write_text(f'[robot]\nname = "r"\n{head}\n[[transform]]\nname = "R"\n[[transform]]\nname = "A1"\n'
                    'joint = "revolute"\nlimits = [-90, 90]\n[[transform]]\nname = "K"\n'.replace(
                        'name = "r"\nname = 5', "name = 5"))
    with pytest.raises(ConfigError, match=pattern):
        load_robot(toml)


def test_robot_file_limits_ordered(tmp_path):
    toml = tmp_path / "r.toml"
    toml.write_text('[robot]\nname = "r"\n[[transform]]\nname = "R"\n[[transform]]\nname = "A1"\n'
                    'joint = "revolute"\nlimits = [90, -90]\n[[transform]]\nname = "K"\n')
    with pytest.raises(ConfigError, match=r"'A1': limits .* lower < upper"):
        load_robot(toml)


def test_config_robot_file_beside_the_config(tmp_path):
    (tmp_path / "r.dh.csv").write_text(DH_HEADER + "\n".join(DH_ROWS) + "\n")
    text = bad('model = "sr800"', 'model = "r.dh.csv"').replace("[-195.0, -5.0]", "[-190.0, -10.0]")
    (tmp_path / "cell.toml").write_text(text)
    assert load_config(tmp_path / "cell.toml").model.n_joints == 4


# ----------------------------------------------------------------------------- CSV export

@pytest.mark.parametrize("text,safe", [
    ('=HYPERLINK("http://x","y")', '\'=HYPERLINK("http://x","y")'), ("+1", "'+1"), ("-1", "'-1"),
    ("@SUM(A1)", "'@SUM(A1)"), ("\tx", "'\tx"), ("\rx", "'\rx"), ("C1.a", "C1.a"), ("", ""),
    ("a=b", "a=b"),
])
def test_csv_text_escapes_formulas(text, safe):
    assert csv_text(text) == safe


def test_export_escapes_formula_point_ids(tmp_path):
    with RunDB(tmp_path / "runs.db") as db:
        plan = [{"kind": "identification", "point": "=HYPERLINK(\"http://evil\",\"C1\")", "q": [0.0] * 4}]
        rid = db.create_run("[cell]\nname = 'x'\n", plan)
        db.record_measurement(rid, 0, kind="identification", joints_commanded=[0.0, 0.1, -1.0, 0.2],
                              point_id='=HYPERLINK("http://evil","C1")', label="@cmd", message="-2+3",
                              readings_mm=[-0.5] * 6, ok=False)
        out = export_csv(db, rid, tmp_path / "m.csv")
    with open(out, newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    assert rows[0]["point_id"] == '\'=HYPERLINK("http://evil","C1")'
    assert rows[0]["label"] == "'@cmd" and rows[0]["message"] == "'-2+3"
    assert float(rows[0]["p1 [mm]"]) == -0.5  # numbers stay numbers
    for row in rows:
        for v in row.values():
            assert (v or " ")[0] not in "=+@\t\r", v
