"""Calibration report: files, valid PNGs, unit conversion in the markdown."""

from __future__ import annotations

import dataclasses
import math
import struct

import numpy as np
import pytest

from station.cell.summary import (
    ErrorStats,
    IdentificationSummary,
    ParameterEstimate,
    RunSummary,
    UploadSummary,
)
from station.core.units import ARCSEC
from station.errors import ConfigError, Outcome
from station.ui.report import ReportData, write_report

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def make_data(*, oracle: bool = True, residual_cols: int = 6, seed: int = 1) -> ReportData:
    rng = np.random.default_rng(seed)
    names = ["A2.x", "A3.x", "A3.z", "A1.roll", "A2.pitch", "K.yaw", "K.z"]
    is_angle = [False, False, False, True, True, True, False]
    nominal = np.array([445.0, 355.0, -240.0, 0.0, 0.0, 0.0, -128.478])
    identified = nominal + np.array([0.0123, -0.0205, 0.004, 12.0 * ARCSEC, -3.5 * ARCSEC, 0.0, 0.0])
    sigma = np.array([0.007, 0.0155, 0.033, 0.8 * ARCSEC, 15.0 * ARCSEC, float("nan"), float("nan")])
    n = 25
    if residual_cols == 6:
        residuals = np.hstack([rng.normal(0, 0.008, (n, 3)), rng.normal(0, 5 * ARCSEC, (n, 3))])
    else:
        residuals = rng.normal(0, 0.008, (n, residual_cols))
    th = np.linspace(-2.2, 2.2, 15)
    r = np.linspace(300, 780, 6)
    xy = np.array([[ri * math.cos(t), ri * math.sin(t)] for ri in r for t in th])
    acc = 0.004 + 0.005 * (np.hypot(xy[:, 0], xy[:, 1]) / 800.0) ** 2
    k = 12
    before = rng.uniform(300, 1200, k)
    after = rng.uniform(10, 40, k)
    return ReportData(
        robot_name="Bosch SR 800",
        run_id=42,
        param_names=names,
        param_nominal=nominal,
        param_identified=identified,
        param_sigma=sigma,
        param_is_angle=is_angle,
        residuals=residuals,
        accuracy_xy_mm=xy,
        accuracy_sigma_mm=acc,
        errors_before_um=before,
        errors_after_um=after,
        oracle_after_um=(after * 0.9) if oracle else None,
        summary=RunSummary(outcome=Outcome.SUCCESS, run_id=1, robot="SR 800", cell="sim",
                           before=ErrorStats(k, 812.44, 900.0, 850.0, 20.0),
                           after=ErrorStats(k, 23.61, 30.0, 25.0, 10.0),
                           oracle=ErrorStats(k, 21.9, 28.0, 22.0, 9.0)),
        verify_labels=[f"V{i + 1}" for i in range(k)],
    )


def png_size(path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == PNG_SIGNATURE, f"{path.name} is not a PNG"
    assert data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24])


def test_writes_markdown_and_valid_pngs(tmp_path):
    md = write_report(tmp_path / "out", make_data())
    assert md == tmp_path / "out" / "report.md" and md.is_file()
    text = md.read_text(encoding="utf-8")
    for name in ("residuals.png", "parameters.png", "accuracy.png", "verification.png"):
        p = tmp_path / "out" / name
        assert p.is_file(), name
        assert p.stat().st_size > 10_000, f"{name} suspiciously small"
        w, h = png_size(p)
        assert w >= 400 and h >= 300
        assert f"]({name})" in text  # linked from the markdown


def test_parameter_table_in_people_units(tmp_path):
    text = write_report(tmp_path, make_data()).read_text(encoding="utf-8")
    # lengths: nominal/identified mm, Δ and σ µm
    assert "| A2.x | mm / µm | 445.0000 | 445.0123 | 12.3 | 7.0 |" in text
    assert "| A3.x | mm / µm | 355.0000 | 354.9795 | -20.5 | 15.5 |" in text
    # angles: nominal/identified degrees, Δ and σ arc seconds
    assert f"| A1.roll | ° / ″ | 0.00000 | {12.0 / 3600:.5f} | 12.0 | 0.8 |" in text
    assert "| A2.pitch | ° / ″ | 0.00000 | -0.00097 | -3.5 | 15.0 |" in text
    # held parameters have no σ
    assert "| K.yaw | ° / ″ | 0.00000 | 0.00000 | 0.0 | held |" in text
    assert "7 parameters, 5 identified" in text


def test_summary_and_verification_tables(tmp_path):
    d = make_data()
    text = write_report(tmp_path, d).read_text(encoding="utf-8")
    assert "| outcome | SUCCESS |" in text
    assert "| RMS before | 812.4 µm |" in text
    assert "| RMS after | 23.6 µm |" in text
    assert "| improvement ratio | 34.4 × |" in text
    assert "| oracle RMS after | 21.9 µm |" in text
    assert "| exit code | 0 |" in text
    assert "oracle µm" in text
    b, a, o = d.errors_before_um[0], d.errors_after_um[0], d.oracle_after_um[0]
    assert f"| V1 | {b:.1f} | {a:.1f} | {o:.1f} |" in text
    rms_b = math.sqrt(np.mean(d.errors_before_um**2))
    assert f"**{rms_b:.1f}**" in text
    # residual statistics in µm and arc seconds
    pos = np.linalg.norm(d.residuals[:, :3], axis=1) * 1000
    ori = np.linalg.norm(d.residuals[:, 3:], axis=1) * (1 / ARCSEC)
    assert f"RMS position residual {math.sqrt(np.mean(pos**2)):.1f} µm" in text
    assert f"RMS orientation residual {math.sqrt(np.mean(ori**2)):.1f} ″" in text
    acc = d.accuracy_sigma_mm * 1000
    assert f"max {acc.max():.1f} µm" in text


def test_without_oracle_and_position_only_residuals(tmp_path):
    text = write_report(tmp_path, make_data(oracle=False, residual_cols=3)).read_text(encoding="utf-8")
    assert "oracle µm" not in text
    assert "orientation residual" not in text
    for name in ("residuals.png", "verification.png"):
        assert (tmp_path / name).read_bytes()[:8] == PNG_SIGNATURE


def test_distance_residuals(tmp_path):
    text = write_report(tmp_path, make_data(residual_cols=1)).read_text(encoding="utf-8")
    assert "25 distances" in text


def test_does_not_switch_the_global_backend(tmp_path):
    import matplotlib

    before = matplotlib.get_backend()
    write_report(tmp_path, make_data())
    assert matplotlib.get_backend() == before


def test_shape_errors_are_config_errors():
    d = make_data()
    with pytest.raises(ConfigError):
        ReportData(**{**d.__dict__, "param_sigma": np.zeros(3)})
    with pytest.raises(ConfigError):
        ReportData(**{**d.__dict__, "errors_after_um": np.zeros(3)})
    with pytest.raises(ConfigError):
        ReportData(**{**d.__dict__, "residuals": np.zeros((4, 5))})


def test_report_data_is_frozen():
    d = make_data()
    with pytest.raises(dataclasses.FrozenInstanceError):
        d.run_id = 3  # type: ignore[misc]
    with pytest.raises(ValueError):
        d.param_nominal[0] = 1.0


def test_pipeline_summary_layout(tmp_path):
    """The run summary as the pipeline stores it (JSON) reads back into the report's table."""
    summary = RunSummary(
        outcome=Outcome.SUCCESS, run_id=7, cell="sim", robot="SR 800",
        identification=IdentificationSummary("pose", 120, 20, 0.9, 9.87, (), (ParameterEstimate("A2.x", 1.0, 1e-3),)),
        before=ErrorStats(12, 1012.34, 1500.0, 1400.0, 40.0, (1.0, 2.0)),
        after=ErrorStats(12, 24.61, 40.0, 35.5, 30.2), oracle=ErrorStats(12, 20.1, 30.0, 28.0, 25.0),
        upload=UploadSummary("deadbeef", 0.42))
    summary = RunSummary.from_json(summary.to_json())
    d = make_data()
    d = ReportData(**{**d.__dict__, "summary": summary})
    text = write_report(tmp_path, d).read_text(encoding="utf-8")
    for row in ("| outcome | SUCCESS |", "| robot | SR 800 |", "| RMS before | 1012.3 µm |",
                "| RMS after | 24.6 µm |", "| improvement ratio | 41.1 × |", "| oracle RMS after | 20.1 µm |",
                "| after / oracle | 1.22 × |", "| AP max after (ISO 9283) | 35.5 µm |",
                "| identified parameters | 20 |", "| upload.crc32 | deadbeef |", "| exit code | 0 |",
                "| upload (read back, activated) | 0.42 s |"):
        assert row in text, row
    assert "errors_um" not in text
