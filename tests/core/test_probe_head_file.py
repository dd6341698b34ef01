"""The probe-head file: loading, every malformed input a ConfigError naming its key, the
arrangement check (unfixed motions named with the probes and the fix), the sensitivity figures
against a Monte Carlo of the pose solver, and the [head] section of a cell configuration."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

from station.core.kinematics.transforms import matrix_to_pose, pose_to_matrix
from station.core.probe.check import (
    check_arrangement,
    check_head,
    contact_jacobian,
    diagnose,
    frozen_probes,
    isolable_probes,
    leave_one_out,
    residual_test,
    sensitivity,
)
from station.core.probe.geometry import (
    FACE_NORMALS,
    ProbeHeadGeometry,
    default_probe_head,
    readings_from_pose,
    solve_pose,
)
from station.errors import ConfigError
from station.io.head_file import head_to_toml, load_head, parse_head

ROOT = Path(__file__).resolve().parents[2]
REFERENCE = ROOT / "examples" / "heads" / "reference-321.toml"
SEVEN = ROOT / "examples" / "heads" / "seven-probe.toml"
ARCSEC = np.pi / (180 * 3600)
M0 = pose_to_matrix(np.array([0.0, 0.0, -60.0, 0.0, 0.0, 0.0]))


def reference_data() -> dict:
    return tomllib.loads(REFERENCE.read_text(encoding="utf-8"))


def head_from_contacts(contacts, rho=1.0, **kw) -> ProbeHeadGeometry:
    """A head whose probes point straight into their faces at the given MPKS contacts."""
    pts, dirs, faces = arrays_from_contacts(contacts, rho)
    return ProbeHeadGeometry(pts, dirs, faces, rho, 10.0, 40.0, M0, **kw)


def arrays_from_contacts(contacts, rho=1.0):
    pts, dirs, faces = [], [], []
    for f, p in contacts:
        n = FACE_NORMALS[f]
        pts.append(M0[:3, :3] @ (np.array(p, float) + rho * n) + M0[:3, 3])
        dirs.append(-(M0[:3, :3] @ n))
        faces.append(f)
    return np.array(pts), np.array(dirs), np.array(faces)


#: a ten-probe head on which every single bad probe can be singled out from one touch
TEN = [(0, (5, 5, 0)), (0, (35, 5, 0)), (0, (20, 35, 0)), (0, (35, 30, 0)), (1, (0, 6, -8)), (1, (0, 34, -12)),
       (1, (0, 20, -30)), (2, (6, 0, -10)), (2, (34, 0, -8)), (2, (20, 0, -30))]


# --- the files shipped in examples/heads ------------------------------------------------------

def test_reference_file_is_exactly_the_built_in_head():
    h = load_head(REFERENCE, 40.0)
    d = default_probe_head()
    g = h.geometry
    for attr in ("mount_points", "directions", "faces", "tip_radii", "strokes", "probe_channels",
                 "probe_scales", "nominal_pose"):
        np.testing.assert_array_equal(getattr(g, attr), getattr(d, attr), err_msg=attr)
    assert g.probe_ids == d.probe_ids and g.name == d.name
    assert g.reading_sigma_mm == d.reading_sigma_mm
    # its frame is the built-in robot's nominal K
    from station.io.robot.files import load_robot

    np.testing.assert_allclose(h.frame_pose, load_robot("sr800").nominal[-6:], atol=1e-12)
    # and it round-trips through head_to_toml
    again = parse_head(tomllib.loads(head_to_toml(g, h.frame_pose)), "<round trip>", 40.0)
    np.testing.assert_allclose(again.geometry.mount_points, g.mount_points, atol=1e-9)


def test_seven_probe_file_reads_off_zero_and_maps_channels():
    h = load_head(SEVEN, 40.0)
    g = h.geometry
    assert g.n_probes == 7 and g.probe_ids[2] == "P3" and g.probe_channels.tolist() == [2, 3, 4, 5, 6, 7, 8]
    assert g.probe_scales[2] == pytest.approx(1.0004)
    # a real head: the probes do not all read 0 at the nominal touch, but inside their stroke
    s0 = g.nominal_readings()
    assert np.max(np.abs(s0)) > 0.1 and np.all(np.abs(s0) < 0.3 * g.strokes)
    assert np.linalg.norm(g.directions[4]) == pytest.approx(1.0)
    assert h.report.rank == 6 and h.report.redundancy == 1 and h.report.isolable == ()
    np.testing.assert_allclose(np.degrees(h.frame_pose[5]), 30.0)


# --- malformed files: a ConfigError naming the key -----------------------------------------------

def _set(data: dict, path: tuple, value) -> dict:
    d = data
    for p in path[:-1]:
        d = d[p]
    if value is _DELETE:
        del d[path[-1]]
    else:
        d[path[-1]] = value
    return data


_DELETE = object()


@pytest.mark.parametrize("path, value, expect", [
    (("head", "frame_in_flange"), _DELETE, r"head\.frame_in_flange is missing"),
    (("head", "nominal_contact"), [0.0, 0.0, -60.0], r"head\.nominal_contact"),
    (("head", "frame_in_flange"), [0.0, 0.0, float("nan"), 0.0, 0.0, 0.0], r"head\.frame_in_flange\[2\].*finite"),
    (("head", "reading_sigma_um"), 0.0, r"head\.reading_sigma_um = 0\.0: out of range"),
    (("head", "colour"), "red", r"head: unknown key 'colour'"),
    (("probe", 0, "channel"), 0, r"probe\[0\]\.channel \(probe '1'\) = 0: out of range"),
    (("probe", 0, "channel"), 2, r"probe: two probes have channel 2"),
    (("probe", 1, "id"), "1", r"probe: two probes have id '1'"),
    (("probe", 0, "channel"), 1.0, r"probe\[0\]\.channel .*expected an integer"),
    (("probe", 2, "direction"), [0.0, 0.0, -2.0], r"probe\[2\]\.direction \(probe '3'\): has length 2; give a unit vector"),
    (("probe", 2, "direction"), [0.0, 0.0], r"probe\[2\]\.direction"),
    (("probe", 3, "face"), "bottom", r"probe\[3\]\.face .*not one of the allowed values"),
    (("probe", 3, "stroke_mm"), -1.0, r"probe\[3\]\.stroke_mm .*out of range"),
    (("probe", 3, "tip_radius_mm"), "1", r"probe\[3\]\.tip_radius_mm .*expected a number"),
    (("probe", 4, "scale"), 3.0, r"probe\[4\]\.scale .*out of range"),
    (("probe", 4, "mount_mm"), _DELETE, r"probe\[4\]\.mount_mm \(probe '5'\) is missing"),
    (("probe", 5, "spring"), 1, r"probe\[5\]: unknown key 'spring'"),
])
def test_malformed_head_file_names_the_key(path, value, expect):
    data = _set(reference_data(), path, value)
    with pytest.raises(ConfigError, match=expect):
        parse_head(data, "head.toml")


def test_too_many_probes_and_no_probe_table():
    data = reference_data()
    data["probe"] = [dict(data["probe"][0], id=str(i), channel=i) for i in range(1, 17)]
    with pytest.raises(ConfigError, match=r"probe = .*has too many items; expected 6 … 15"):
        parse_head(data, "head.toml")
    data = reference_data()
    del data["probe"]
    with pytest.raises(ConfigError, match=r"probe is missing"):
        parse_head(data, "head.toml")


def test_nominal_reading_outside_the_stroke_names_the_probe():
    data = reference_data()
    data["probe"][4]["mount_mm"] = [-4.5, 32.0, -75.0]  # 3.5 mm pre-travel on a 10 mm stroke
    with pytest.raises(ConfigError, match=r"head\.toml: .*probe 5 \(channel 5\) reads 3\.500 mm, allowed ±3\.000 mm"):
        parse_head(data, "head.toml")


def test_missing_and_garbage_files(tmp_path):
    with pytest.raises(ConfigError, match="no such probe-head file"):
        load_head(tmp_path / "nope.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[head\nname=1", encoding="utf-8")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_head(bad)


# --- the arrangement check -----------------------------------------------------------------------

def test_five_probes_name_the_motion_nobody_fixes():
    contacts = [(0, (5, 5, 0)), (0, (35, 5, 0)), (0, (20, 35, 0)), (1, (0, 8, -15)), (1, (0, 32, -15))]
    pts, dirs, faces = arrays_from_contacts(contacts)
    with pytest.raises(ConfigError, match=r"does not fix y translation .*rank 5 of 6.*5 probe\(s\).*add a probe on the y face"):
        check_arrangement(pts, dirs, faces, 1.0, M0, 40.0, [str(i + 1) for i in range(5)])
    # through the file as well, with the [[probe]] key
    data = reference_data()
    del data["probe"][5]
    with pytest.raises(ConfigError, match=r"head\.toml: \[\[probe\]\]: the probe arrangement does not fix y translation"):
        parse_head(data, "head.toml")


def test_six_probes_on_the_top_face_leave_x_y_and_yaw_free():
    contacts = [(0, (5, 5, 0)), (0, (35, 5, 0)), (0, (20, 35, 0)), (0, (10, 30, 0)), (0, (30, 20, 0)),
                (0, (15, 15, 0))]
    pts, dirs, faces = arrays_from_contacts(contacts)
    labels = [f"P{i + 1} (channel {i + 1})" for i in range(6)]
    with pytest.raises(ConfigError) as exc:
        check_arrangement(pts, dirs, faces, 1.0, M0, 40.0, labels)
    msg = str(exc.value)
    assert "x translation, y translation and yaw" in msg and "rank 3 of 6" in msg
    assert all(lb in msg for lb in labels)  # every probe is involved: they all measure z, roll, pitch
    assert "add probes on the x face and the y face" in msg


def test_collinear_top_probes_name_the_probes_and_the_motion():
    # the three top probes on one line along x: nothing on top sees roll; the one y-face probe
    # cannot tell roll from y translation
    contacts = [(0, (5, 20, 0)), (0, (20, 20, 0)), (0, (35, 20, 0)), (1, (0, 8, -15)), (1, (0, 32, -15)),
                (2, (20, 0, -15))]
    pts, dirs, faces = arrays_from_contacts(contacts)
    labels = ["T1", "T2", "T3", "X1", "X2", "Y1"]
    with pytest.raises(ConfigError) as exc:
        check_arrangement(pts, dirs, faces, 1.0, M0, 40.0, labels)
    msg = str(exc.value)
    assert "roll" in msg and "rank 5 of 6" in msg
    assert "probes T1, T2, T3 measure dependent motions" in msg
    assert "add a probe on the top face" in msg


def test_weak_arrangement_is_refused_with_the_weak_motion():
    # the two x-face probes 0.02 mm apart: yaw is fixed only through a 20 µm lever
    contacts = [(0, (5, 5, 0)), (0, (35, 5, 0)), (0, (20, 35, 0)), (1, (0, 20, -15)), (1, (0, 20.02, -15)),
                (2, (20, 0, -15))]
    pts, dirs, faces = arrays_from_contacts(contacts)
    with pytest.raises(ConfigError, match=r"only weakly \(condition .*weakest: yaw"):
        check_arrangement(pts, dirs, faces, 1.0, M0, 40.0, [str(i) for i in range(6)])


def test_report_of_the_reference_head():
    r = check_head(default_probe_head())
    assert r.rank == 6 and 1 < r.condition < 20 and r.redundancy == 0
    assert "a bad touch cannot be detected" in " ".join(r.lines())
    assert r.to_json()["sigma_angle_arcsec_per_um"][2] == pytest.approx(12.2, abs=0.1)


@pytest.mark.parametrize("make", [default_probe_head, lambda: load_head(SEVEN).geometry])
def test_sensitivity_matches_a_monte_carlo_of_the_solver(make):
    geom = make()
    pos_um, ang_arcsec = sensitivity(geom, 0.001)
    M = geom.nominal_contact_pose() @ pose_to_matrix(np.array([0.3, -0.2, 0.1, 0.002, -0.001, 0.003]))
    r0 = readings_from_pose(geom, M)
    rng = np.random.default_rng(11)
    p_true = matrix_to_pose(M)
    d = np.array([matrix_to_pose(solve_pose(geom, r0 + rng.normal(0, 0.001, geom.n_probes),
                                            check_residuals=False).M) - p_true for _ in range(1500)])
    np.testing.assert_allclose(d[:, :3].std(axis=0) * 1000, pos_um, rtol=0.1)
    np.testing.assert_allclose(d[:, 3:].std(axis=0) / ARCSEC, ang_arcsec, rtol=0.1)


# --- redundancy: the residual test, leave-one-out, the frozen reading -----------------------------

def test_residual_test_flags_a_20um_offset_and_names_it_on_an_isolating_head():
    geom = head_from_contacts(TEN)
    assert len(isolable_probes(geom)) == 10
    rng = np.random.default_rng(3)
    M = geom.nominal_contact_pose() @ pose_to_matrix(np.array([0.4, -0.3, 0.2, 0.003, 0.002, -0.004]))
    clean = readings_from_pose(geom, M)
    false_alarms = 0
    for trial in range(200):
        r = clean + rng.normal(0, 0.0005, 10)
        sol = solve_pose(geom, r, check_residuals=False)
        false_alarms += not residual_test(geom, r, sol.M).passed
        if trial < 30:
            k = trial % 10
            bad = r.copy()
            bad[k] += 0.02
            full = residual_test(geom, bad, solve_pose(geom, bad, check_residuals=False).M)
            assert not full.passed
            d = diagnose(geom, bad, full)
            assert d.suspect == k, d.reason
            assert f"probe {geom.label(k)} is off by +" in d.reason
            # the pose from the others is the clean one
            assert np.max(np.abs(d.solution.M[:3, 3] - M[:3, 3])) < 0.003
    assert false_alarms <= 3  # alpha 1e-3 at the head's σ; the simulated noise is the same σ


def test_seven_probes_detect_but_cannot_single_out_an_offset():
    geom = load_head(SEVEN).geometry
    M = geom.nominal_contact_pose() @ pose_to_matrix(np.array([0.2, 0.1, -0.3, 0.001, 0.002, 0.001]))
    r = readings_from_pose(geom, M)
    r[5] += 0.02
    full = residual_test(geom, r, solve_pose(geom, r, check_residuals=False).M)
    assert not full.passed and full.dof == 1
    # every probe's studentised residual is the same (to the 8° tilt of P5, which the solver's
    # unweighted plane fit sees 1 % differently): one redundant reading cannot isolate
    t = np.abs(full.studentised)
    np.testing.assert_allclose(t, t[0], rtol=0.02)
    loo = leave_one_out(geom, r)
    assert loo.named is None and len(loo.candidates) == 7 and loo.verified == ()
    d = diagnose(geom, r, full)
    assert d.suspect is None and "cannot single out an offset" in d.reason


def test_a_frozen_reading_is_named_on_seven_probes():
    geom = load_head(SEVEN).geometry
    Mn = geom.nominal_contact_pose()
    rng = np.random.default_rng(5)
    poses = [Mn @ pose_to_matrix(np.r_[rng.uniform(-0.5, 0.5, 3), rng.uniform(-0.004, 0.004, 3)]) for _ in range(3)]
    touches = [readings_from_pose(geom, M) + rng.normal(0, 0.0005, 7) for M in poses]
    touches[1][2] = touches[0][2]
    touches[2][2] = touches[0][2]  # P3 stuck since the first touch
    full = residual_test(geom, touches[2], solve_pose(geom, touches[2], check_residuals=False).M)
    assert not full.passed
    assert set(frozen_probes(geom, touches[2], [touches[1], touches[0]], tuple(range(7)))) == {2}
    d = diagnose(geom, touches[2], full, [touches[1], touches[0]])
    assert d.suspect == 2 and "P3 (channel 4) stuck?" in d.reason
    # a probe that reads the same but was not expected to move is not called stuck
    assert frozen_probes(geom, touches[0], [touches[0]], tuple(range(7))) == {}


def test_contact_jacobian_is_the_reading_derivative():
    geom = load_head(SEVEN).geometry
    G = contact_jacobian(geom)
    Mn = geom.nominal_contact_pose()
    dp = np.array([0.001, -0.002, 0.0015, 1e-5, -2e-5, 1.5e-5])
    ds = readings_from_pose(geom, pose_to_matrix(matrix_to_pose(Mn) + dp)) - geom.nominal_readings()
    np.testing.assert_allclose(ds, G @ dp, atol=1e-8)


# --- [head] in the cell configuration --------------------------------------------------------------

def _config_text(head_line: str = "") -> str:
    from station.cell.config.template import TEMPLATE

    return TEMPLATE + head_line


def test_config_without_head_keeps_the_built_in_head():
    from station.cell.config.cell_config import parse_text

    cfg = parse_text(_config_text(), "cell.toml")
    d = default_probe_head(cube_edge_mm=cfg.cube_edge_mm)
    np.testing.assert_array_equal(cfg.head.mount_points, d.mount_points)
    np.testing.assert_allclose(cfg.head_in_flange, pose_to_matrix(cfg.model.nominal[-6:]))
    assert cfg.plan.remeasure_attempts == 1


def test_config_head_file_beside_the_config_sets_geometry_and_nominal_k(tmp_path):
    from station.cell.config.cell_config import load_config

    (tmp_path / "head.toml").write_text(SEVEN.read_text(encoding="utf-8"), encoding="utf-8")
    cfg_path = tmp_path / "cell.toml"
    cfg_path.write_text(_config_text('\n[head]\nfile = "head.toml"\n'), encoding="utf-8")
    cfg = load_config(cfg_path)
    assert cfg.head.n_probes == 7
    frame = load_head(SEVEN).frame_pose
    np.testing.assert_allclose(cfg.model.nominal[cfg.model.param_index("K.x"):][:6], frame)
    np.testing.assert_allclose(cfg.head_in_flange, pose_to_matrix(frame))
    from station.cell.plan.measurement_plan import nominal_contact

    np.testing.assert_array_equal(nominal_contact(cfg), cfg.head.nominal_contact_pose())


def test_config_head_errors_name_the_key(tmp_path):
    from station.cell.config.cell_config import load_config

    cfg_path = tmp_path / "cell.toml"
    cfg_path.write_text(_config_text('\n[head]\nfile = "missing.toml"\n'), encoding="utf-8")
    with pytest.raises(ConfigError, match=r"cell\.toml: head\.file: .*missing\.toml.*no such probe-head file"):
        load_config(cfg_path)
    cfg_path.write_text(_config_text('\n[head]\nfiles = "head.toml"\n'), encoding="utf-8")
    with pytest.raises(ConfigError, match=r"head: unknown key 'files'"):
        load_config(cfg_path)
    cfg_path.write_text(_config_text().replace("remeasure_attempts = 1", "remeasure_attempts = 9"),
                        encoding="utf-8")
    with pytest.raises(ConfigError, match=r"plan\.remeasure_attempts = 9"):
        load_config(cfg_path)


def test_plan_prints_the_heads_check_and_sensitivity(tmp_path, capsys):
    import json

    from station.ui.cli.main import main

    (tmp_path / "head.toml").write_text(SEVEN.read_text(encoding="utf-8"), encoding="utf-8")
    cfg_path = tmp_path / "cell.toml"
    # the template's SR 800 quill tops out at -5 mm, so this head's deepest probe (33.5 mm below the
    # contact) travels 1.8 mm over the highest cube: under the default 2 mm collision margin the
    # plan is refused (issue 40, rightly); a user accepting 1.5 mm says so in [plan]
    text = _config_text('\n[head]\nfile = "head.toml"\n')
    cfg_path.write_text(text.replace("collision_margin_mm = 2.0", "collision_margin_mm = 1.5"), encoding="utf-8")
    assert main(["plan", str(cfg_path)]) == 0
    out = capsys.readouterr().out
    assert "probe head: 7 probes, rank 6 of 6, condition 5.0" in out
    assert "1 µm reading error -> position σ x 1.19" in out
    assert main(["plan", str(cfg_path), "--json"]) == 0
    head = json.loads(capsys.readouterr().out)["head"]
    assert head["redundancy"] == 1 and head["sigma_angle_arcsec_per_um"][2] == pytest.approx(9.84, abs=0.01)


def test_a_probe_no_other_probe_checks_is_reported():
    # the seventh probe on the y face next to the sixth: the top probes' readings are checked by
    # nobody (z, roll, pitch have exactly three readings), the y-face pair checks each other
    contacts = [(0, (5, 5, 0)), (0, (35, 5, 0)), (0, (20, 35, 0)), (1, (0, 8, -15)), (1, (0, 32, -15)),
                (2, (20, 0, -15)), (2, (30, 0, -15))]
    r = check_head(head_from_contacts(contacts))
    assert r.redundancy == 1
    assert r.unchecked == tuple(f"{i} (channel {i})" for i in (1, 2, 3))
    assert any("no other probe checks 1 (channel 1), 2 (channel 2), 3 (channel 3)" in line for line in r.lines())
    assert check_head(load_head(SEVEN).geometry).unchecked == ()


def test_an_edited_head_file_changes_the_runs_fingerprint(tmp_path):
    from station.cell.config.cell_config import load_config
    from station.cell.records.fingerprint import fingerprint

    head = tmp_path / "head.toml"
    head.write_text(SEVEN.read_text(encoding="utf-8"), encoding="utf-8")
    cfg_path = tmp_path / "cell.toml"
    cfg_path.write_text(_config_text('\n[head]\nfile = "head.toml"\n'), encoding="utf-8")
    before = fingerprint(load_config(cfg_path))
    head.write_text(SEVEN.read_text(encoding="utf-8").replace("tip_radius_mm = 1.5", "tip_radius_mm = 1.25", 1),
                    encoding="utf-8")
    after = fingerprint(load_config(cfg_path))
    assert {k for k in before if before[k] != after[k]} == {"probe head"}


@pytest.mark.parametrize("junk", [None, True, "x", 1e308, -1, [], [1, 2], {"a": 1}, float("inf"), "\x00"])
def test_any_junk_value_is_a_config_error_never_a_traceback(junk):
    base = reference_data()
    keys = [("head", k) for k in base["head"]] + [("probe", 3, k) for k in base["probe"][3]]
    for path in keys:
        data = reference_data()
        if junk is None:
            _set(data, path, _DELETE)
        else:
            _set(data, path, junk)
        try:
            parse_head(data, "head.toml")
        except ConfigError as exc:
            assert "head.toml" in str(exc)
    for top in (None, [], "x", {"head": 1, "probe": 2}):
        with pytest.raises(ConfigError):
            parse_head(top, "head.toml")


def test_a_probe_that_misses_its_face_at_the_nominal_touch_is_named():
    data = reference_data()
    data["probe"][1]["mount_mm"] = [45.0, 5.0, -59.0]  # beyond the 40 mm cube's top face
    with pytest.raises(ConfigError, match=r"probes 2 \(channel 2\) land outside their cube face"):
        parse_head(data, "head.toml")
    data = reference_data()
    data["probe"][0]["direction"] = [0.0, 0.0, 1.0]  # pointing away from its face
    with pytest.raises(ConfigError, match=r"probe 1 \(channel 1\) does not point into its face"):
        parse_head(data, "head.toml")
