"""``[body] file`` (the CMM report) in the cell configuration, its σ, and the identification of a
simulated run with it (issue 8.3)."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from simulators import SimulatedCellServers
from simulators.cell import SimulatedCell
from simulators.reference_cell import cell_config_text
from station.cell.config.cell_config import load_config, parse_text
from station.cell.config.template import TEMPLATE
from station.cell.pipeline.calibration import identify_run
from station.cell.plan.measurement_plan import build_plan, retracted
from station.cell.run.runner import Checkpoint, MoveJoints, ReadJoints, ReadProbes, Settle, approach_and_read
from station.core.kinematics.transforms import matrix_to_pose
from station.core.units import ARCSEC, UM
from station.errors import ConfigError

EXAMPLE = Path(__file__).parents[2] / "examples" / "bodies" / "reference-body.csv"
INLINE = re.compile(r"points = \[\n.*?\n\]\n", re.S)


def _with_body(text: str, body_lines: str) -> str:
    """``text`` with its inline ``points = [...]`` replaced by ``body_lines``."""
    assert INLINE.search(text)
    return INLINE.sub(body_lines.replace("\\", "\\\\"), text, count=1)


def _sim_text(seed: int = 3) -> str:
    cell = SimulatedCell(seed=seed)
    fake = SimulatedCellServers(cell, SimpleNamespace(host="127.0.0.1", port=502), SimpleNamespace(port="/dev/null"), seed)
    return cell_config_text(fake, seed)


def _csv_of(cfg, sigma_cols: str = "", sigma_row: str = "") -> str:
    lines = ["id,x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg" + sigma_cols]
    for pid, T in zip(cfg.point_ids, cfg.body_points):
        p = matrix_to_pose(T)
        lines.append(",".join([pid, *(repr(float(v)) for v in [*p[:3], *np.degrees(p[3:])])]) + sigma_row)
    return "\n".join(lines) + "\n"


def test_body_file_beside_the_config_equals_inline_points(tmp_path):
    inline = parse_text(TEMPLATE)
    (tmp_path / "body.csv").write_text(_csv_of(inline))
    cfg_path = tmp_path / "cell.toml"
    cfg_path.write_text(_with_body(TEMPLATE, 'file = "body.csv"\n'))
    cfg = load_config(cfg_path)
    assert cfg.point_ids == inline.point_ids
    np.testing.assert_allclose(cfg.body_points, inline.body_points, atol=1e-12)
    assert cfg.body_sigma is not None and np.all(cfg.body_sigma == 0)  # default: exact


def test_file_sigma_and_defaults(tmp_path):
    inline = parse_text(TEMPLATE)
    csv = _csv_of(inline, ",sigma_position_um,sigma_angle_arcsec", ",,").splitlines()
    # first and third point: none given → the defaults; second: its position σ only
    csv[2] = csv[2][:-1] + "4.0,"
    (tmp_path / "b.csv").write_text("\n".join(csv) + "\n")
    text = _with_body(TEMPLATE, 'file = "b.csv"\n').replace(
        "default_sigma_position_um = 0.0", "default_sigma_position_um = 12.0").replace(
        "default_sigma_angle_arcsec = 0.0", "default_sigma_angle_arcsec = 7.0")
    (tmp_path / "c.toml").write_text(text)
    cfg = load_config(tmp_path / "c.toml")
    np.testing.assert_allclose(np.asarray(cfg.body_sigma)[:3], np.array([[12 * UM, 7 * ARCSEC], [4 * UM, 7 * ARCSEC], [12 * UM, 7 * ARCSEC]]))
    np.testing.assert_allclose(np.asarray(cfg.body_sigma)[3:], [[12 * UM, 7 * ARCSEC]] * (len(cfg.body_sigma) - 3))


def test_inline_points_with_sigma():
    text = TEMPLATE.replace('pose = [11.1, -312.8, 40.0, 0.0, 0.0, 100.0] }',
                            'pose = [11.1, -312.8, 40.0, 0.0, 0.0, 100.0], sigma_position_um = 3.0, sigma_angle_arcsec = 2.0 }')
    text = text.replace("default_sigma_position_um = 0.0", "default_sigma_position_um = 1.5")
    cfg = parse_text(text)
    np.testing.assert_allclose(np.asarray(cfg.body_sigma)[:3], np.array([[1.5 * UM, 0.0], [3 * UM, 2 * ARCSEC], [1.5 * UM, 0.0]]))
    np.testing.assert_allclose(np.asarray(cfg.body_sigma)[3:], [[1.5 * UM, 0.0]] * (len(cfg.body_sigma) - 3))


def test_file_and_points_together_or_neither_refused(tmp_path):
    both = TEMPLATE.replace("cube_edge_mm = 40.0", 'cube_edge_mm = 40.0\nfile = "body.csv"')
    with pytest.raises(ConfigError, match=r"body: give the measuring points either .*exactly one"):
        parse_text(both)
    with pytest.raises(ConfigError, match=r"exactly one"):
        parse_text(_with_body(TEMPLATE, ""))


def test_missing_or_bad_body_file_names_config_key_and_file(tmp_path):
    cfg_path = tmp_path / "cell.toml"
    cfg_path.write_text(_with_body(TEMPLATE, 'file = "nope.csv"\n'))
    with pytest.raises(ConfigError, match=r"cell\.toml: body\.file: .*nope\.csv: no such body file"):
        load_config(cfg_path)
    (tmp_path / "bad.csv").write_text("id,x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg\nA,1,2,3,0,0,0\nB,1,2,x,0,0,0\n")
    cfg_path.write_text(_with_body(TEMPLATE, 'file = "bad.csv"\n'))
    with pytest.raises(ConfigError, match=r"body\.file: .*bad\.csv: line 3, column 'z_mm'"):
        load_config(cfg_path)


# ------------------------------------------------------------------ a simulated run's identification

def _measure(cfg, cell, steps):
    """The runner's procedures executed on the simulated cell's physics, in process."""
    out = []
    for st in steps:
        proc, value = approach_and_read(cfg, st.q, st.direction, cycle=st.cycle), None
        while True:
            try:
                msg = proc.send(value)
            except StopIteration as stop:
                r = stop.value
                break
            value = None
            if isinstance(msg, MoveJoints):
                cell.command_joints(retracted(cfg, cell.encoder_joints()) if msg.q is None else msg.q)
            elif isinstance(msg, ReadProbes):
                vals = np.mean([cell.probe_values() for _ in range(cfg.plan.samples)], axis=0)
                value = SimpleNamespace(values_mm=vals, status=tuple("ok" for _ in vals), raw=b"")
            elif isinstance(msg, ReadJoints):
                value = cell.encoder_joints()
            else:
                assert isinstance(msg, (Checkpoint, Settle))
        out.append(SimpleNamespace(step_index=st.index, point_id=st.point_id, label=st.label, ok=r.ok,
                                   pose=r.pose, joints_read=r.joints_read))
    return out


def test_identify_run_uses_the_body_sigma(tmp_path):
    """The same measurements, identified with the example body's CMM σ (2 µm, 3″) and with an
    exact body: the fit says the body's σ is in, and the parameters' σ grow."""
    text = _sim_text()
    exact = parse_text(text)
    (tmp_path / "body.csv").write_text(_csv_of(exact, ",sigma_position_um,sigma_angle_arcsec", ",20,10"))
    (tmp_path / "cell.toml").write_text(_with_body(text, 'file = "body.csv"\n'))
    with_body = load_config(tmp_path / "cell.toml")
    steps = build_plan(exact).identification[:48]
    records = _measure(exact, SimulatedCell(seed=3), steps)
    a = identify_run(exact, records)
    b = identify_run(with_body, records)
    assert a.chosen == b.chosen
    assert not any("body uncertainty" in n for n in a.notes)
    n_points = len({r.point_id for r in records if r.ok})
    assert f"body uncertainty included: {n_points} points, σ 20 µm, 10 ″" in " ".join(b.notes)
    assert np.median(b.uncertainty.sigma / a.uncertainty.sigma) > 1.2
    # σ 0 (the default) is the fit without any body σ, bit for bit
    assert exact.body_sigma is not None and not np.any(exact.body_sigma)
    c = identify_run(dataclasses.replace(exact, body_sigma=None), records)
    assert np.array_equal(a.params, c.params) and np.array_equal(a.uncertainty.covariance, c.uncertainty.covariance)
    # the same points from a file (σ 0): the same fit, to the last digits the CSV keeps
    (tmp_path / "body0.csv").write_text(_csv_of(exact))
    (tmp_path / "cell0.toml").write_text(_with_body(text, 'file = "body0.csv"\n'))
    d = identify_run(load_config(tmp_path / "cell0.toml"), records)
    # atol 1e-9 (mm or rad: a picometre, a nanoradian): the fit's last digits follow the BLAS
    # kernel (OpenBLAS's Haswell kernels on an AMD machine differ from its Zen ones by 2e-11 here)
    np.testing.assert_allclose(d.params, a.params, rtol=1e-9, atol=1e-9)
    assert d.notes == a.notes


def test_example_body_file_reads_as_the_builtin_cells_body(tmp_path):
    text = _sim_text()
    cfg = parse_text(_with_body(text, f'file = "{EXAMPLE}"\n'))
    builtin = parse_text(text)
    assert cfg.point_ids == builtin.point_ids
    np.testing.assert_allclose(cfg.body_points, builtin.body_points, atol=1e-6)
    np.testing.assert_allclose(np.asarray(cfg.body_sigma), np.tile([2 * UM, 3 * ARCSEC], (len(cfg.point_ids), 1)))


def test_an_edited_body_file_changes_the_fingerprint(tmp_path):
    """A resume refuses a run whose body file was edited since (the file name alone is the same)."""
    from station.cell.records.fingerprint import check_same_cell, fingerprint

    inline = parse_text(TEMPLATE)
    assert "body points" not in fingerprint(inline)  # inline points: the [body] section is the digest
    (tmp_path / "body.csv").write_text(_csv_of(inline))
    (tmp_path / "cell.toml").write_text(_with_body(TEMPLATE, 'file = "body.csv"\n'))
    before = fingerprint(load_config(tmp_path / "cell.toml"))
    check_same_cell(before, fingerprint(load_config(tmp_path / "cell.toml")), 1)
    (tmp_path / "body.csv").write_text(_csv_of(inline).replace("C1.b,11.1", "C1.b,11.2"))
    with pytest.raises(ConfigError, match="body points"):
        check_same_cell(before, fingerprint(load_config(tmp_path / "cell.toml")), 1)
