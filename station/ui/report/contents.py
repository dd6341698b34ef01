"""What a calibration report shows: :class:`ReportData` (the run's figures as plain arrays and
strings, checked on construction) and :class:`TrendRun` (one run of the robot's history).

The bottom of the report's modules: :mod:`~station.ui.report.tables` and
:mod:`~station.ui.report.render.plots` read it, :mod:`~station.ui.report.render.html_page` and
:mod:`~station.ui.report.render.markdown_page` format it, :mod:`station.ui.report.writer` writes the files, and
:mod:`station.ui.report.run` fills it from a stored run. It imports none of them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from station.cell.records.summary import RunSummary
from station.core.units import ARCSEC, UM
from station.errors import ConfigError

__all__ = ["ReportData", "TrendRun", "IsoPose", "TestConditions", "Acceptance", "Traceability", "HTML_NAME",
           "MARKDOWN_NAME"]

HTML_NAME = "report.html"
MARKDOWN_NAME = "report.md"


def _arr(a: Any, ndim: int | None = None, name: str = "") -> np.ndarray:
    out = np.array(a, dtype=float)
    if ndim is not None and out.ndim != ndim:
        raise ConfigError(f"report: {name} must be {ndim}-dimensional, got shape {out.shape}")
    out.setflags(write=False)
    return out


def _labels(value: Any, n: int, name: str) -> tuple[str, ...] | None:
    if value is None:
        return None
    labels = tuple(str(x) for x in value)
    if len(labels) != n:
        raise ConfigError(f"report: {name} has {len(labels)} entries, expected {n}")
    return labels


@dataclass(frozen=True)
class TrendRun:
    """One run of the robot's history (the report's trend): a calibration with its RMS after
    correction [µm] (None when nothing was uploaded or it did not finish), or a recheck with its
    RMS position drift against its baseline and the tolerance [µm]."""

    run_id: int
    created: str = ""  # the run database's created_utc
    kind: str = "calibration"  # or "recheck"
    outcome: str = ""  # the stored outcome's name; "" while unfinished
    status: str = ""  # the run database's status (shown while there is no outcome)
    rms_after_um: float | None = None
    drift_rms_um: float | None = None
    drift_tolerance_um: float | None = None
    moved: Sequence[str] = ()
    baseline: int | None = None  # a recheck's baseline calibration

    def __post_init__(self) -> None:
        object.__setattr__(self, "run_id", int(self.run_id))
        object.__setattr__(self, "moved", tuple(str(m) for m in self.moved))
        for attr in ("rms_after_um", "drift_rms_um", "drift_tolerance_um"):
            v = getattr(self, attr)
            object.__setattr__(self, attr, None if v is None else float(v))

    @property
    def is_recheck(self) -> bool:
        return self.kind == "recheck"

    @property
    def figure_um(self) -> float | None:
        """The run's accuracy figure: the drift RMS of a recheck, the RMS after correction of a
        calibration."""
        return self.drift_rms_um if self.is_recheck else self.rms_after_um


def _opt(v: Any) -> float | None:
    return None if v is None else float(v)


@dataclass(frozen=True)
class IsoPose:
    """One held-out verification pose as ISO 9283 reports it: where it is (the commanded TCP
    position in the calibration body's frame [mm]), and per series (before / after correction)
    the valid cycles, the pose accuracy AP and the pose repeatability RP [µm]. RP needs two
    cycles (None with one); a series not measured has ``n = 0`` and None figures."""

    point: str
    elbow: int
    target_mm: tuple[float, float, float]
    n_before: int = 0
    ap_before_um: float | None = None
    rp_before_um: float | None = None
    n_after: int = 0
    ap_after_um: float | None = None
    rp_after_um: float | None = None
    #: standard uncertainties of the four figures [µm] (station/core/accuracy/iso9283_uncertainty.py)
    u_ap_before_um: float | None = None
    u_rp_before_um: float | None = None
    u_ap_after_um: float | None = None
    u_rp_after_um: float | None = None

    def __post_init__(self) -> None:
        target = tuple(float(v) for v in self.target_mm)
        if len(target) != 3:
            raise ConfigError(f"report: pose {self.point}: target_mm needs x, y, z, got {len(target)} values")
        object.__setattr__(self, "target_mm", target)
        object.__setattr__(self, "elbow", int(self.elbow))
        for attr in ("ap_before_um", "rp_before_um", "ap_after_um", "rp_after_um", "u_ap_before_um", "u_rp_before_um",
                     "u_ap_after_um", "u_rp_after_um"):
            object.__setattr__(self, attr, _opt(getattr(self, attr)))


@dataclass(frozen=True)
class TestConditions:
    """How the test was made, as the report's "test conditions" state it: the identification's
    poses and visits, the held-out poses and their cycles, speed, settling, the load on the
    flange, the warm-up and the temperature (None / "": not recorded)."""

    __test__ = False  # not a pytest test class, for all its name

    identification_poses: int  # distinct (point, elbow) measured for the identification
    identification_measurements: int  # planned identification measurements (every visit and direction)
    repeats: int  # visits per identification pose
    verification_poses: int
    verification_cycles: int  # ISO 9283 cycles per held-out pose, as planned
    speed: float  # fraction of the robot's maximum speed
    settle_s: float
    samples: int  # probe snapshots averaged per reading
    elbows: Sequence[int] = (1, -1)
    both_directions: bool = False
    load: str = ""  # what is on the flange (the probe head) and where its frame is
    load_kg: float | None = None
    warmup: str = ""  # what the warm-up did ("" : none configured)
    temperature_c: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "elbows", tuple(int(e) for e in self.elbows))
        object.__setattr__(self, "load_kg", _opt(self.load_kg))
        object.__setattr__(self, "temperature_c", _opt(self.temperature_c))


@dataclass(frozen=True)
class Acceptance:
    """What the run is judged against: the improvement ratio the outcome requires
    (``min_gain``), and ``[verification]``'s per-pose limits on AP and RP after correction [µm]
    (None: not specified)."""

    min_gain: float
    max_ap_um: float | None = None
    max_rp_um: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "min_gain", float(self.min_gain))
        object.__setattr__(self, "max_ap_um", _opt(self.max_ap_um))
        object.__setattr__(self, "max_rp_um", _opt(self.max_rp_um))


@dataclass(frozen=True)
class Traceability:
    """Who and what the record traces to ("": not recorded): the robot's serial and the
    controller (``[cell]``), the operator and where the name came from, the probe head and the
    body with their CMM certificates (ID, date), and the software (``software``: name →
    version, in display order)."""

    robot_serial: str = ""
    controller: str = ""
    operator: str = ""
    operator_from: str = ""  # "--operator", "[cell] operator", "the run's record"
    head: str = ""  # the head's name
    head_file: str = ""  # "" : the built-in reference head
    head_certificate_id: str = ""
    head_certificate_date: str = ""
    body: str = ""  # what the body is (its points)
    body_file: str = ""  # "" : points inline in the configuration
    body_certificate_id: str = ""
    body_certificate_date: str = ""
    software: Sequence[tuple[str, str]] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "software", tuple((str(k), str(v)) for k, v in self.software))


@dataclass(frozen=True)
class ReportData:
    """Everything a report shows, as plain arrays and strings.

    Units (inputs): parameters, residuals, accuracy in the station's internal **mm and rad**;
    verification errors in **µm**.

    * ``param_names`` (p,), ``param_nominal`` / ``param_identified`` / ``param_sigma`` (p,),
      ``param_is_angle`` (p,) bool: angle parameters are rad, the others mm.  ``param_sigma``
      may hold NaN for parameters that were held (not identified). Names ``R.*`` are the set-up
      (the robot base's pose in the calibration body's frame), ``K.*`` the head / tool, the others the
      robot's own geometry; the report shows the three apart.
    * ``param_correlation`` (p, p) or None: correlation coefficients of the estimates (from the
      identification's covariance); |r| > 0.9 is marked.
    * ``residuals`` (n, 6) [mm, mm, mm, rad, rad, rad] or (n, 3) [mm] — model − measured per
      identification pose (or per distance: (n, 1) [mm]); ``pose_labels`` (n,) name each row,
      ``outliers`` are row indices the identification flagged.
    * ``accuracy_xy_mm`` (m, 2) evaluation points over the workspace, ``accuracy_sigma_mm`` (m,)
      predicted position σ of the TCP there (parameter uncertainty only); ``accuracy_elbows``
      (m,) the elbow of each point or None; ``accuracy_where`` says what the points are.
    * ``errors_before_um`` / ``errors_after_um`` (k,) position error per verification pose and
      cycle (NaN: that cycle gave no valid measurement; ``errors_after_um`` empty when nothing
      was uploaded), ``oracle_after_um`` (k,) or None: the error after correction as the
      simulated cell's reference correction leaves it (simulated runs only). ``verify_labels`` (k,) read
      ``"<point> elbow <±1> #<cycle>"``; the report shows point and elbow per row from them.
    * ``summary``: the run's :class:`~station.cell.records.summary.RunSummary` (shown first).
    * The record: ``config_toml`` (the run's configuration snapshot), ``station_version``,
      ``devices`` (``probe_interface``, ``controller_map_version``; None for runs from before it
      was stored), ``run_status`` (the run database's status), ``table_info`` (facts about the
      correction table rebuilt from the identification: ``grid``, ``unreachable_nodes``,
      ``max_correction``, ``crc32``, ...), ``notes`` (what the report builder wants said).
    * ``trend``: the robot's history, :class:`TrendRun` per run of the same cell and robot up to
      and including this one (kept in run order); the report shows it from two runs on.
    * ``document_id`` (on every printed page) and ``progress`` (how far an unfinished run got;
      a run stopped before the identification has no parameters: empty arrays).
    * The sign-off: ``simulated`` (a banner on every page), ``conditions``
      (:class:`TestConditions`), ``iso_poses`` (:class:`IsoPose` per held-out pose),
      ``acceptance`` (:class:`Acceptance`) and ``traceability`` (:class:`Traceability`); None or
      empty where not known (the report says so).
    """

    robot_name: str
    run_id: str | int
    param_names: Sequence[str]
    param_nominal: np.ndarray
    param_identified: np.ndarray
    param_sigma: np.ndarray
    param_is_angle: np.ndarray
    residuals: np.ndarray
    accuracy_xy_mm: np.ndarray
    accuracy_sigma_mm: np.ndarray
    errors_before_um: np.ndarray
    errors_after_um: np.ndarray
    oracle_after_um: np.ndarray | None = None
    summary: RunSummary | None = None
    pose_labels: Sequence[str] | None = None  # (n,) labels of the identification poses
    verify_labels: Sequence[str] | None = None  # (k,) labels of the verification poses
    created: str = ""  # timestamp text, set by the caller (kept out for reproducible files)
    param_correlation: np.ndarray | None = None
    outliers: Sequence[int] = ()
    accuracy_elbows: Sequence[int] | None = None
    accuracy_where: str = ""
    config_toml: str = ""
    station_version: str = ""
    devices: Mapping[str, str] | None = None
    run_status: str = ""
    table_info: Mapping[str, Any] | None = None
    notes: Sequence[str] = ()
    trend: Sequence[TrendRun] = ()
    simulated: bool = False
    conditions: TestConditions | None = None
    iso_poses: Sequence[IsoPose] = ()
    acceptance: Acceptance | None = None
    traceability: Traceability | None = None
    #: the document ID every printed page carries (cell, robot serial or name, run, a digest of the
    #: run's creation time and configuration: a rebuilt report keeps it); "" : "run N"
    document_id: str = ""
    #: how far the run got, for a run that did not finish ("" : it finished): the report says it
    #: first, and the sections the run did not reach say so instead of their tables
    progress: str = ""
    #: the cell from above and from the side with the run's planned poses (SVG text, issue 40:
    #: :mod:`station.ui.report.render.cell_picture`); None: not drawn (the notes say why)
    cell_svg: str | None = None

    def __post_init__(self) -> None:
        names = tuple(str(n) for n in self.param_names)
        object.__setattr__(self, "param_names", names)
        p = len(names)
        for attr in ("param_nominal", "param_identified", "param_sigma"):
            a = _arr(getattr(self, attr), 1, attr)
            if a.shape != (p,):
                raise ConfigError(f"report: {attr} has {a.shape[0]} entries, param_names has {p}")
            object.__setattr__(self, attr, a)
        mask = np.array(self.param_is_angle, dtype=bool).reshape(-1)
        if mask.shape != (p,):
            raise ConfigError(f"report: param_is_angle has {mask.shape[0]} entries, param_names has {p}")
        mask.setflags(write=False)
        object.__setattr__(self, "param_is_angle", mask)
        if self.param_correlation is not None:
            corr = _arr(self.param_correlation, 2, "param_correlation")
            if corr.shape != (p, p):
                raise ConfigError(f"report: param_correlation must be ({p}, {p}), got {corr.shape}")
            object.__setattr__(self, "param_correlation", corr)

        res = _arr(self.residuals, None, "residuals")
        if res.ndim == 1:
            res = _arr(res.reshape(-1, 1))
        if res.ndim != 2 or res.shape[1] not in (1, 3, 6):
            raise ConfigError(f"report: residuals must be (n, 6), (n, 3) or (n, 1), got {res.shape}")
        object.__setattr__(self, "residuals", res)
        object.__setattr__(self, "outliers", tuple(int(i) for i in self.outliers))

        xy = _arr(self.accuracy_xy_mm, 2, "accuracy_xy_mm")
        sig = _arr(self.accuracy_sigma_mm, 1, "accuracy_sigma_mm")
        if xy.shape[1:] != (2,) or sig.shape[0] != xy.shape[0]:
            raise ConfigError(f"report: accuracy_xy_mm {xy.shape} and accuracy_sigma_mm {sig.shape} do not match")
        object.__setattr__(self, "accuracy_xy_mm", xy)
        object.__setattr__(self, "accuracy_sigma_mm", sig)
        if self.accuracy_elbows is not None:
            elbows = tuple(int(e) for e in self.accuracy_elbows)
            if len(elbows) != sig.shape[0]:
                raise ConfigError(f"report: accuracy_elbows has {len(elbows)} entries, expected {sig.shape[0]}")
            object.__setattr__(self, "accuracy_elbows", elbows)

        before = _arr(self.errors_before_um, 1, "errors_before_um")
        after = _arr(self.errors_after_um, 1, "errors_after_um")
        if after.size and before.shape != after.shape:  # no 'after' when the upload was skipped
            raise ConfigError(f"report: errors_before_um {before.shape} and errors_after_um {after.shape} differ")
        object.__setattr__(self, "errors_before_um", before)
        object.__setattr__(self, "errors_after_um", after)
        if self.oracle_after_um is not None:
            oracle = _arr(self.oracle_after_um, 1, "oracle_after_um")
            if oracle.shape != after.shape:
                raise ConfigError(f"report: oracle_after_um {oracle.shape} and errors_after_um {after.shape} differ")
            object.__setattr__(self, "oracle_after_um", oracle)
        object.__setattr__(self, "pose_labels", _labels(self.pose_labels, res.shape[0], "pose_labels"))
        object.__setattr__(self, "verify_labels", _labels(self.verify_labels, before.shape[0], "verify_labels"))
        if self.devices is not None:
            object.__setattr__(self, "devices", {str(k): str(v) for k, v in self.devices.items()})
        object.__setattr__(self, "notes", tuple(str(n) for n in self.notes))
        object.__setattr__(self, "trend", tuple(sorted(self.trend, key=lambda r: r.run_id)))
        object.__setattr__(self, "simulated", bool(self.simulated))
        object.__setattr__(self, "iso_poses", tuple(self.iso_poses))
        object.__setattr__(self, "document_id", str(self.document_id) or f"run {self.run_id}")

    # --- derived figures, in people units --------------------------------------------------
    @property
    def position_residuals_um(self) -> np.ndarray:
        """(n, c) position residual components [µm] (c = 3, or 1 for distances)."""
        r = self.residuals
        return r[:, :3] * (1 / UM) if r.shape[1] >= 3 else r * (1 / UM)

    @property
    def orientation_residuals_arcsec(self) -> np.ndarray | None:
        r = self.residuals
        return r[:, 3:6] * (1 / ARCSEC) if r.shape[1] == 6 else None
