"""The calibration body from its CMM report (CSV): what is read, and every malformed file refused
with the file, the line, the column and the fix."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from station.core.units import ARCSEC, DEG, UM
from station.errors import ConfigError
from station.io.body_file import read_body_file

EXAMPLE = Path(__file__).parents[2] / "examples" / "bodies" / "reference-body.csv"
HEADER = "id,x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg"
ROWS = ["C1.a,-28.3,-319.7,40.0,0.0,0.0,10.0", "C1.b,11.1,-312.8,40.0,0.0,0.0,100.0",
        "C1.c,4.1,-273.4,40.0,0.0,0.0,190.0"]


def _write(tmp_path: Path, text: str, name: str = "body.csv") -> Path:
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


def test_reads_points_in_mm_and_rad(tmp_path):
    body = read_body_file(_write(tmp_path, "# CMM report B-2\n\n" + HEADER + "\n" + "\n".join(ROWS) + "\n"))
    assert body.ids == ("C1.a", "C1.b", "C1.c")
    np.testing.assert_allclose(body.poses[1], [11.1, -312.8, 40.0, 0.0, 0.0, 100.0 * DEG])
    assert np.all(np.isnan(body.sigma))  # not given: the configuration's default applies
    np.testing.assert_allclose(body.sigma_with_default(0.005, 2 * ARCSEC), np.tile([0.005, 2 * ARCSEC], (3, 1)))
    T = body.matrices()
    assert T.shape == (3, 4, 4)
    np.testing.assert_allclose(T[0, :3, 3], [-28.3, -319.7, 40.0])


def test_sigma_columns_per_row_and_blank_cells(tmp_path):
    text = (HEADER + ",sigma_position_um,sigma_angle_arcsec\n" + ROWS[0] + ",2.0,5.0\n" + ROWS[1] + ",,\n"
            + ROWS[2] + ",20,\n")
    body = read_body_file(_write(tmp_path, text))
    np.testing.assert_allclose(body.sigma[0], [2 * UM, 5 * ARCSEC])
    assert np.all(np.isnan(body.sigma[1]))
    assert body.sigma[2, 0] == pytest.approx(20 * UM) and np.isnan(body.sigma[2, 1])
    filled = body.sigma_with_default(1e-3, 1 * ARCSEC)
    np.testing.assert_allclose(filled[1], [1e-3, ARCSEC])
    np.testing.assert_allclose(filled[2], [20 * UM, ARCSEC])


def test_units_in_brackets_metres_and_radians_and_column_order(tmp_path):
    text = ("yaw [rad],id,x [m],y [m],z [m],roll [rad],pitch [rad],sigma_position [mm],sigma_angle [deg]\n"
            "0.1745,C1.a,-0.0283,-0.3197,0.04,0,0,0.002,0.001\n"
            "1.7453,C1.b,0.0111,-0.3128,0.04,0,0,0.002,0.001\n"
            "3.3161,C1.c,0.0041,-0.2734,0.04,0,0,0.002,0.001\n")
    body = read_body_file(_write(tmp_path, text))
    np.testing.assert_allclose(body.poses[0], [-28.3, -319.7, 40.0, 0.0, 0.0, 0.1745], atol=1e-9)
    np.testing.assert_allclose(body.sigma[0], [0.002, 0.001 * DEG])


def test_semicolons_and_decimal_commas(tmp_path):
    text = ("id;x_mm;y_mm;z_mm;roll_deg;pitch_deg;yaw_deg\n"
            "C1.a;-28,3;-319,7;40,0;0;0;10\nC1.b;11,1;-312,8;40;0;0;100\nC1.c;4,1;-273,4;40;0;0;190\n")
    body = read_body_file(_write(tmp_path, text))
    np.testing.assert_allclose(body.poses[:, 0], [-28.3, 11.1, 4.1])


def test_byte_order_mark_is_dropped(tmp_path):
    p = tmp_path / "bom.csv"
    p.write_bytes(b"\xef\xbb\xbf" + (HEADER + "\n" + "\n".join(ROWS) + "\n").encode())
    assert read_body_file(p).ids[0] == "C1.a"


def test_example_is_the_builtin_cells_body():
    from simulators.cell import CalibrationBody

    ref = CalibrationBody.generate()
    body = read_body_file(EXAMPLE)
    assert body.ids == tuple(f"C{c + 1}.{'abcd'[k]}" for c, k in ref.labels)
    np.testing.assert_allclose(body.matrices(), ref.nominal, atol=1e-6)
    np.testing.assert_allclose(body.sigma, np.tile([2 * UM, 3 * ARCSEC], (len(ref.labels), 1)))


def _err(tmp_path, text, *parts):
    p = _write(tmp_path, text)
    with pytest.raises(ConfigError) as exc:
        read_body_file(p)
    msg = str(exc.value)
    assert str(p) in msg
    for part in parts:
        assert part in msg, msg
    return msg


def test_missing_column(tmp_path):
    text = "id,x_mm,y_mm,roll_deg,pitch_deg,yaw_deg\n" + "\n".join(r.rsplit(",", 4)[0] + ",0,0,10" for r in ROWS)
    _err(tmp_path, text, "line 1", "z_mm", "missing", "id,x_mm,y_mm,z_mm,roll_deg")


def test_column_without_unit(tmp_path):
    _err(tmp_path, HEADER.replace("x_mm", "x") + "\n" + "\n".join(ROWS), "line 1", "'x'", "no unit", "x_mm")


def test_wrong_unit_kind_and_unknown_unit(tmp_path):
    _err(tmp_path, HEADER.replace("yaw_deg", "yaw [mm]") + "\n" + "\n".join(ROWS), "'yaw [mm]'",
         "not an angle unit", "deg, rad, arcsec")
    _err(tmp_path, HEADER.replace("x_mm", "x [inch]") + "\n" + "\n".join(ROWS), "'x [inch]'", "not a length unit")
    _err(tmp_path, HEADER.replace("x_mm", "x_inch") + "\n" + "\n".join(ROWS), "'x_inch'", "'inch' is not a length unit")


def test_empty_header_cell(tmp_path):
    _err(tmp_path, HEADER + ",\n" + "\n".join(r + "," for r in ROWS), "line 1", "without a name", "trailing separator")


def test_unknown_and_duplicate_columns(tmp_path):
    _err(tmp_path, HEADER + ",temp_deg\n" + "\n".join(r + ",1" for r in ROWS), "unknown column 'temp'")
    _err(tmp_path, HEADER + ",x [m]\n" + "\n".join(r + ",1" for r in ROWS), "'x [m]'", "appears twice")


def test_bad_number_names_line_and_column(tmp_path):
    rows = [*ROWS[:2], ROWS[2].replace("-273.4", "-273.4mm")]
    _err(tmp_path, "# report\n" + HEADER + "\n" + "\n".join(rows), "line 5", "'y_mm'", "'-273.4mm' is not a number")


def test_nan_and_empty_pose_cell_refused(tmp_path):
    _err(tmp_path, HEADER + "\n" + "\n".join([*ROWS[:2], ROWS[2].replace("190.0", "nan")]), "line 4", "'yaw_deg'",
         "not a finite number")
    _err(tmp_path, HEADER + "\n" + "\n".join([*ROWS[:2], ROWS[2].replace("40.0", "")]), "line 4", "'z_mm'",
         "an empty cell is not a number")


def test_row_length(tmp_path):
    _err(tmp_path, HEADER + "\n" + "\n".join([*ROWS[:2], ROWS[2] + ",1"]), "line 4", "8 values", "7 columns")


def test_duplicate_id(tmp_path):
    rows = [*ROWS, ROWS[0].replace("-28.3", "0.0")]
    _err(tmp_path, HEADER + "\n" + "\n".join(rows), "line 5", "'id'", "'C1.a' was already given on line 2", "unique")


def test_empty_id_and_too_few_points(tmp_path):
    _err(tmp_path, HEADER + "\n" + "\n".join([*ROWS[:2], ROWS[2].replace("C1.c", " ")]), "line 4", "1 … 64")
    _err(tmp_path, HEADER + "\n" + "\n".join(ROWS[:2]), "2 measuring points", "3 … 5000")
    _err(tmp_path, "# only a comment\n", "empty")


def test_out_of_bounds_values(tmp_path):
    _err(tmp_path, HEADER + "\n" + "\n".join([*ROWS[:2], ROWS[2].replace("4.1", "40000")]), "line 4", "'x_mm'",
         "±10000 mm")
    rad = HEADER.replace("yaw_deg", "yaw_rad")
    _err(tmp_path, rad + "\n" + "\n".join(ROWS), "line 2", "'yaw_rad'", "±360 deg", "degrees in a rad column")
    sig = HEADER + ",sigma_position_um\n" + "\n".join([*(r + ",2" for r in ROWS[:2]), ROWS[2] + ",-1"])
    _err(tmp_path, sig, "line 4", "'sigma_position_um'", "outside 0 … 1000 µm")
    sig = HEADER + ",sigma_angle_arcsec\n" + "\n".join([*(r + ",2" for r in ROWS[:2]), ROWS[2] + ",99999"])
    _err(tmp_path, sig, "line 4", "'sigma_angle_arcsec'", "3600 arc seconds")


def test_report_in_metres_labelled_mm_is_refused(tmp_path):
    rows = ["C1.a,-0.0283,-0.3197,0.04,0,0,10", "C1.b,0.0111,-0.3128,0.04,0,0,100", "C1.c,0.0041,-0.2734,0.04,0,0,190"]
    _err(tmp_path, HEADER + "\n" + "\n".join(rows), "in metres", "x_m, y_m, z_m")


def test_not_a_regular_file(tmp_path):
    with pytest.raises(ConfigError, match="directory"):
        read_body_file(tmp_path)
    with pytest.raises(ConfigError, match="no such body file"):
        read_body_file(tmp_path / "nope.csv")
    fifo = tmp_path / "fifo.csv"
    os.mkfifo(fifo)
    with pytest.raises(ConfigError, match="not a regular file"):
        read_body_file(fifo)


def test_not_utf8(tmp_path):
    p = tmp_path / "latin1.csv"
    p.write_bytes((HEADER + "\n" + "\n".join(ROWS)).encode() + b"\n# \xe9\n")
    with pytest.raises(ConfigError, match="UTF-8"):
        read_body_file(p)
