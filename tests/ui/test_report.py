"""Calibration report: ReportData checks, the Markdown beside the HTML, unit conversion."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from station.cell.records.summary import (
    ErrorStats,
    IdentificationSummary,
    ParameterEstimate,
    RunSummary,
    UploadSummary,
)
from station.core.units import ARCSEC
from station.errors import ConfigError, Outcome
from station.ui.report.run import correlation_from_covariance
from station.ui.report.tables import split_label
from station.ui.report.writer import ReportData, write_report


def make_data(*, oracle: bool = True, residual_cols: int = 6, seed: int = 1, after: bool = True) -> ReportData:
    rng = np.random.default_rng(seed)
    names = ["R.x", "A2.x", "A3.x", "A3.z", "A1.roll", "A2.pitch", "K.yaw", "K.z"]
    is_angle = [False, False, False, False, True, True, True, False]
    nominal = np.array([-450.0, 445.0, 355.0, -240.0, 0.0, 0.0, 0.0, -128.478])
    identified = nominal + np.array([3.1675, 0.0123, -0.0205, 0.004, 12.0 * ARCSEC, -3.5 * ARCSEC, 0.0, 0.0])
    sigma = np.array([0.002, 0.007, 0.0155, 0.033, 0.8 * ARCSEC, 15.0 * ARCSEC, float("nan"), float("nan")])
    corr = np.eye(8)
    corr[1, 5] = corr[5, 1] = 0.95  # A2.x ~ A2.pitch: strongly correlated
    corr[2, 3] = corr[3, 2] = -0.5
    corr[6, :] = corr[:, 6] = np.nan  # held
    corr[7, :] = corr[:, 7] = np.nan
    n = 25
    if residual_cols == 6:
        residuals = np.hstack([rng.normal(0, 0.008, (n, 3)), rng.normal(0, 5 * ARCSEC, (n, 3))])
    else:
        residuals = rng.normal(0, 0.008, (n, residual_cols))
    th = np.linspace(-2.2, 2.2, 15)
    r = np.linspace(300, 780, 6)
    xy = np.array([[ri * math.cos(t), ri * math.sin(t)] for ri in r for t in th])
    xy = np.vstack([xy, xy])  # every position twice (two elbows)
    acc = 0.004 + 0.005 * (np.hypot(xy[:, 0], xy[:, 1]) / 800.0) ** 2
    elbows = [1] * 90 + [-1] * 90
    points = ["C1.b", "C1.d", "C2.b", "C2.d"]
    labels = [f"{p} elbow {(-1 if i % 2 == 0 else 1):+d} #{c}" for i, p in enumerate(points) for c in (1, 2, 3)]
    k = len(labels)
    before = rng.uniform(300, 1200, k)
    after_um = rng.uniform(10, 40, k)
    return ReportData(
        robot_name="Bosch SR 800",
        run_id=42,
        param_names=names,
        param_nominal=nominal,
        param_identified=identified,
        param_sigma=sigma,
        param_is_angle=is_angle,
        param_correlation=corr,
        residuals=residuals,
        pose_labels=[f"C{1 + i // 5}.a elbow +1 #{1 + i % 5}" for i in range(n)],
        accuracy_xy_mm=xy,
        accuracy_sigma_mm=acc,
        accuracy_elbows=elbows,
        accuracy_where="a test grid",
        errors_before_um=before,
        errors_after_um=after_um if after else np.zeros(0),
        oracle_after_um=(after_um * 0.9) if oracle and after else None,
        summary=RunSummary(outcome=Outcome.SUCCESS if after else Outcome.NOT_UPLOADED, run_id=1, robot="SR 800",
                           cell="sim", before=ErrorStats(k, 812.44, 900.0, 850.0, 20.0),
                           after=ErrorStats(k, 23.61, 30.0, 25.0, 10.0) if after else None,
                           oracle=ErrorStats(k, 21.9, 28.0, 22.0, 9.0) if after and oracle else None,
                           upload_skipped=not after),
        verify_labels=labels,
        config_toml='[cell]\nname = "test <cell> & co"\n',
        station_version="9.9.9",
        devices={"probe_interface": "model X, firmware 1", "controller_map_version": "3"},
    )


def test_writes_html_and_markdown(tmp_path):
    path = write_report(tmp_path / "out", make_data())
    assert path == tmp_path / "out" / "report.html" and path.is_file()
    assert (tmp_path / "out" / "report.md").is_file()
    assert not list((tmp_path / "out").glob("*.png"))  # plots live inside the HTML
    assert not list((tmp_path / "out").glob("*.tmp"))
    assert write_report(tmp_path / "only", make_data(), markdown=False).is_file()
    assert not (tmp_path / "only" / "report.md").exists()


def test_parameter_tables_in_people_units_and_split(tmp_path):
    write_report(tmp_path, make_data())
    text = (tmp_path / "report.md").read_text(encoding="utf-8")
    # lengths and angles in tables of their own: one unit per column, named in its heading
    assert "mm / µm" not in text and "° / ″" not in text
    assert text.count("| parameter | nominal mm | identified mm | Δ µm | σ µm |") == 3  # robot, set-up, head
    assert text.count("| parameter | nominal ° | identified ° | Δ ″ | σ ″ |") == 2  # robot, head
    # lengths: nominal/identified mm, Δ and σ µm
    assert "| A2.x | 445.0000 | 445.0123 | 12.3 | 7.0 |" in text
    assert "| A3.x | 355.0000 | 354.9795 | -20.5 | 15.5 |" in text
    # angles: nominal/identified degrees, Δ and σ arc seconds
    assert f"| A1.roll | 0.00000 | {12.0 / 3600:.5f} | 12.0 | 0.8 |" in text
    assert "| A2.pitch | 0.00000 | -0.00097 | -3.5 | 15.0 |" in text
    # held parameters have no σ
    assert "| K.yaw | 0.00000 | 0.00000 | 0.0 | held |" in text
    assert "8 parameters, 6 identified" in text
    robot = text.index("### Robot's own parameters")
    setup = text.index("### Set-up R.*")
    head = text.index("### Head / tool K.*")
    assert robot < setup < head
    assert setup < text.index("| R.x |") < head  # R.x only in the set-up table
    assert robot < text.index("| A2.x |") < setup
    assert text.index("| K.z |") > head
    assert text.count("| R.x |") == 1
    # strong correlations
    assert "| A2.x | A2.pitch | +0.950 |" in text
    assert "A3.x | A3.z" not in text  # |r| = 0.5 is not marked


def test_summary_and_verification_tables(tmp_path):
    d = make_data()
    write_report(tmp_path, d)
    text = (tmp_path / "report.md").read_text(encoding="utf-8")
    assert "| outcome | SUCCESS |" in text
    assert "| RMS before | 812.4 µm |" in text
    assert "| RMS after | 23.6 µm |" in text
    assert "| improvement ratio | 34.4 × |" in text
    assert "| oracle RMS after | 21.9 µm |" in text
    assert "| exit code | 0 |" in text
    assert text.count("| outcome |") == 1 and text.count("| exit code |") == 1
    assert "oracle µm" in text
    # one row per pose (point, elbow), RMS over its cycles
    b, a, o = d.errors_before_um[:3], d.errors_after_um[:3], d.oracle_after_um[:3]

    def r(x):
        return f"{math.sqrt(np.mean(x**2)):.1f}"

    assert f"| C1.b | -1 | 3 | {r(b)} | {r(a)} | {a.max():.1f} | {r(o)} |" in text
    assert text.count("| C1.b |") == 1
    assert f"**{r(d.errors_before_um)}**" in text
    # per elbow
    assert "| +1 | 2 |" in text and "| -1 | 2 |" in text
    # residual statistics in µm and arc seconds
    pos = np.linalg.norm(d.residuals[:, :3], axis=1) * 1000
    ori = np.linalg.norm(d.residuals[:, 3:], axis=1) * (1 / ARCSEC)
    assert f"RMS position residual {math.sqrt(np.mean(pos**2)):.1f} µm" in text
    assert f"RMS orientation residual {math.sqrt(np.mean(ori**2)):.1f} ″" in text
    # accuracy: the count is what was evaluated, the positions are distinct x-y positions
    assert "| +1 | 90 | 90 |" in text and "| -1 | 90 | 90 |" in text
    assert "parameter uncertainty only" in text and "repeatability" in text
    # the record
    assert "| station version | 9.9.9 |" in text and "| controller map version | 3 |" in text
    assert '[cell]\nname = "test <cell> & co"' in text


def test_without_upload(tmp_path):
    d = make_data(after=False)
    write_report(tmp_path, d)
    text = (tmp_path / "report.md").read_text(encoding="utf-8")
    assert "| outcome | NOT_UPLOADED |" in text and "| exit code | 11 |" in text
    assert "skipped (--no-upload)" in text
    assert "after µm" not in text and "oracle µm" not in text
    assert "no 'after' measurements" in text


def test_without_oracle_and_position_only_residuals(tmp_path):
    write_report(tmp_path, make_data(oracle=False, residual_cols=3))
    text = (tmp_path / "report.md").read_text(encoding="utf-8")
    assert "oracle µm" not in text
    assert "orientation residual" not in text


def test_distance_residuals(tmp_path):
    d = make_data(residual_cols=1)
    d = dataclasses.replace(d, pose_labels=None)
    write_report(tmp_path, d)
    assert "25 distances" in (tmp_path / "report.md").read_text(encoding="utf-8")


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
    with pytest.raises(ConfigError):
        ReportData(**{**d.__dict__, "param_correlation": np.eye(3)})
    with pytest.raises(ConfigError):
        ReportData(**{**d.__dict__, "accuracy_elbows": [1, -1]})


def test_report_data_is_frozen():
    d = make_data()
    with pytest.raises(dataclasses.FrozenInstanceError):
        d.run_id = 3  # type: ignore[misc]
    with pytest.raises(ValueError):
        d.param_nominal[0] = 1.0
    assert d.param_correlation is not None
    with pytest.raises(ValueError):
        d.param_correlation[0, 0] = 2.0


def test_correlation_from_covariance():
    s = np.array([2.0, 3.0, 0.0])
    r = np.array([[1.0, 0.95, 0.0], [0.95, 1.0, 0.0], [0.0, 0.0, 1.0]])
    cov = r * np.outer(s, s)
    c = correlation_from_covariance(cov)
    assert c[0, 1] == pytest.approx(0.95) and c[1, 0] == pytest.approx(0.95)
    assert np.all(np.diag(c) == 1.0)
    assert np.isnan(c[0, 2])  # σ = 0: no correlation to give


def test_labels_split_into_point_elbow_cycle():
    assert split_label("C1.b elbow -1 #2") == ("C1.b", -1, 2)
    assert split_label("C5.c elbow +1 cycle 2 #1") == ("C5.c", 1, 1)
    assert split_label("V7") == ("V7", None, None)


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
    write_report(tmp_path, d)
    text = (tmp_path / "report.md").read_text(encoding="utf-8")
    for row in ("| outcome | SUCCESS |", "| robot | Bosch SR 800 |", "| cell | sim |", "| RMS before | 1012.3 µm |",
                "| RMS after | 24.6 µm |", "| improvement ratio | 41.1 × |", "| oracle RMS after | 20.1 µm |",
                "| after / oracle | 1.22 × |", "| AP max after (ISO 9283) | 35.5 µm |",
                "| identified parameters | 20 |", "| exit code | 0 |",
                "| upload (read back, activated) | 0.42 s |"):
        assert row in text, row
    assert "deadbeef" in text  # the uploaded table's CRC, in the table section
    assert "errors_um" not in text
