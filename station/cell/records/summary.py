"""The run summary: the one record of how a run ended, read alike by the CLI, ``--json``, the
terminal UI and the report.

It is frozen; the pipeline builds it once per outcome, stores its JSON form in the run database
(``summary`` result) and returns it. :meth:`RunSummary.to_json` is the ``--json`` output;
:meth:`RunSummary.from_json` reads a stored one back. Units are in the key names (``_um``,
``_s``); ``units`` in the JSON says so once more for a reader without this module.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from station.cell.records.judge import JudgeFigure
from station.cell.records.missed import MissedLimit, failure_json, missed_from_json
from station.core.accuracy.iso9283 import iso9283_pose
from station.errors import Outcome


@dataclass(frozen=True)
class ErrorStats:
    """Position errors of held-out poses [µm]: RMS and max over all cycles, and the largest
    ISO 9283 pose accuracy AP and repeatability RP over the poses."""

    n: int
    rms_um: float
    max_um: float
    ap_max_um: float
    rp_max_um: float | None  # None: no pose was measured twice
    errors_um: tuple[float, ...] = ()
    #: RP over the poses measured at least twice: mean and standard deviation from pose to pose [µm]
    rp_mean_um: float | None = None
    rp_sd_um: float | None = None
    n_poses: int = 0  # held-out poses with a valid measurement
    cycles: int = 0  # the most cycles measured at one pose (ISO 9283 repetitions)

    @classmethod
    def from_errors(cls, errors_by_pose: Mapping[Any, np.ndarray]) -> ErrorStats | None:
        """``errors_by_pose``: per pose, the ``(n_cycles, 3)`` position errors [mm] of its
        cycles. None when nothing was measured. RP needs two cycles of a pose; with one cycle
        per pose (``verification_cycles = 1``) it is None and AP is the error itself."""
        if not errors_by_pose:
            return None
        cycles = [np.asarray(e, dtype=float).reshape(-1, 3) for e in errors_by_pose.values()]
        norms = np.linalg.norm(np.concatenate(cycles), axis=1) * 1e3
        ap, rp = [], []
        for e in cycles:
            if len(e) >= 2:
                st = iso9283_pose(np.zeros(3), e)
                ap.append(st.AP * 1e3)
                rp.append(st.RP * 1e3)
            else:
                ap.append(float(np.linalg.norm(e.mean(axis=0))) * 1e3)
        return cls(n=int(norms.size), rms_um=float(np.sqrt(np.mean(norms**2))), max_um=float(norms.max()),
                   ap_max_um=float(max(ap)), rp_max_um=float(max(rp)) if rp else None,
                   errors_um=tuple(float(v) for v in norms),
                   rp_mean_um=float(np.mean(rp)) if rp else None,
                   rp_sd_um=float(np.std(rp, ddof=1)) if len(rp) > 1 else None,
                   n_poses=len(cycles), cycles=max(len(e) for e in cycles))


@dataclass(frozen=True)
class ParameterEstimate:
    """An identified parameter: value and σ in the model's units [mm | rad]."""

    name: str
    value: float
    sigma: float


@dataclass(frozen=True)
class IdentificationSummary:
    objective: str
    n_measurements: int
    n_parameters: int
    rms_normalized: float
    rms_residual_um: float
    outliers: tuple[int, ...]
    parameters: tuple[ParameterEstimate, ...]
    #: the a-posteriori check (issue 38): s0 = √(rᵀWr/(m − n)), the χ² limit it was tested against
    #: (5 %), and what the parameters' σ were multiplied by (1.0: the residuals agree with the noise)
    variance_factor_s0: float | None = None
    variance_limit_s0: float | None = None
    sigma_scaled_by: float = 1.0


@dataclass(frozen=True)
class CorrectionSummary:
    """The run's correction table: its values, CRC-32 and interpolation bound [µm] (over the cells
    the verification targets use, for a designed grid); the bound predicted before motion (the
    median of the sampled robots' tables on the designed grid), the grid's node counts (x, y, z,
    yaw), whether the grid was refined for the identified robot, and the limit it was judged by."""

    n_values: int
    interpolation_bound_um: float
    crc32: str
    predicted_bound_um: float | None = None
    grid_shape: tuple[int, ...] = ()
    refined: bool = False
    limit_um: float | None = None


@dataclass(frozen=True)
class UploadSummary:
    """A verified upload: the table was read back identical, staged, activated and its active
    CRC-32 checked; ``seconds`` is the whole sequence."""

    crc32: str
    seconds: float
    verified: bool = True


@dataclass(frozen=True)
class TableSummary:
    """Which correction table the controller applied when the run started and when it ended
    (CRC-32 as 8 hex digits, or "none"); ``restored``: the run put the table of its start back
    (declined, aborted, failed or not uploaded)."""

    active_at_start: str
    active_at_end: str
    restored: bool = False


@dataclass(frozen=True)
class ReversalSummary:
    """Position difference between approaching each pose from either side [µm]."""

    n: int
    rms_um: float
    max_um: float


@dataclass(frozen=True)
class ToolSummary:
    """A configured tool's own correction (``[[tool]]``, :mod:`station.cell.correction.robot_tools`).

    ``tcp_mm_deg``: x, y, z [mm], roll, pitch, yaw [deg] in the flange frame; ``kind``: "table"
    (SCARA) or "targets" (compensated targets); ``flange_shift_um`` / ``flange_rotation_arcsec``:
    the identified tool-mount frame against the nominal one (what K absorbed).
    ``head_predicted_*``: what the head's correction would leave at the tool's targets, predicted
    from the identified model. ``after_*`` / ``oracle_*`` / ``head_*`` (simulation only): the
    real robot's error at the tool's ``n_targets`` verification targets with the tool's own
    correction, the oracle's (the simulated cell's reference), and the head's; None for a real cell."""

    name: str
    tcp_mm_deg: tuple[float, ...]
    kind: str
    n_targets: int
    crc32: str | None = None
    n_values: int | None = None
    interpolation_bound_um: float | None = None
    flange_shift_um: float = 0.0
    flange_rotation_arcsec: float = 0.0
    head_predicted_rms_um: float | None = None
    head_predicted_max_um: float | None = None
    after_rms_um: float | None = None
    after_max_um: float | None = None
    oracle_rms_um: float | None = None
    oracle_max_um: float | None = None
    head_rms_um: float | None = None
    head_max_um: float | None = None
    n_after: int = 0
    n_head: int = 0

    @property
    def after_vs_oracle(self) -> float | None:
        if self.after_rms_um is None or self.oracle_rms_um is None:
            return None
        return self.after_rms_um / max(self.oracle_rms_um, 1e-9)

    @property
    def head_vs_after(self) -> float | None:
        """How much larger the head's correction leaves the error than the tool's own."""
        if self.after_rms_um is None or self.head_rms_um is None:
            return None
        return self.head_rms_um / max(self.after_rms_um, 1e-9)


@dataclass(frozen=True)
class CompensationSummary:
    """An articulated arm's correction: compensated targets, no table (``station/cell/pipeline/calibration.py``).

    ``orientation_*_arcsec``: RMS orientation error of the verification before, after and with
    the oracle (simulation) [″]. ``joint_offsets_*``: what joint-zero offsets alone reach on the
    same targets, beside the full model's and the uncorrected robot's, predicted from the
    identified model (``offsets_reference`` says against what: the simulated robot in simulation)."""

    method: str
    n_targets: int
    orientation_before_arcsec: float | None = None
    orientation_after_arcsec: float | None = None
    orientation_oracle_arcsec: float | None = None
    joint_offsets_rms_um: float | None = None
    joint_offsets_rms_arcsec: float | None = None
    full_model_rms_um: float | None = None
    full_model_rms_arcsec: float | None = None
    uncorrected_rms_um: float | None = None
    offsets_reference: str = ""


@dataclass(frozen=True)
class ErrorTermEstimate:
    """A fitted error term beyond geometry: value and σ in ``unit`` (rad, rad/(N·m), mm, …)."""

    name: str
    value: float
    sigma: float
    unit: str


@dataclass(frozen=True)
class ErrorModelSummary:
    """``[identification] model`` (issue 30, docs/error-terms.md): the families ``chosen`` (empty:
    the geometric fit), how they were chosen (``summary``, ``cv``), the cross-validated position RMS
    of the geometric and of the chosen model [µm], the kept ``terms``, and the identification's
    position residual RMS with them [µm]."""

    model: str
    chosen: tuple[str, ...]
    summary: str
    cv: str
    cv_geometric_um: float
    cv_chosen_um: float
    rms_residual_um: float
    terms: tuple[ErrorTermEstimate, ...] = ()
    #: the a-posteriori variance factor of the fit with the terms, where its χ² test (5 %) scaled
    #: the terms' σ (1.0: the residuals agree with the assumed noise; issue 38)
    sigma_scaled_by: float = 1.0


@dataclass(frozen=True)
class RecentringStats:
    """Readings of one kind that were re-centred to bring the probes into their stroke
    (:mod:`station.cell.run.recentring`): how many of how many, and the displacement's position
    part, largest and RMS over the re-centred ones [µm]. In verification the displacement is
    part of the measured error."""

    kind: str
    n_readings: int
    n_recentred: int
    max_um: float = 0.0
    rms_um: float = 0.0


@dataclass(frozen=True)
class ClearanceSummary:
    """A collision check's least clearance [mm] (issue 40, docs/collision.md): ``check`` says which
    ("pre-motion": the plan at its nominal joints; "after (shifted)" / "oracle (shifted)":
    the verification path with that table's correction added, station/cell/plan/moved_path/shifted_check.py;
    "after (compensated)" / "oracle (compensated)": an arm's at its compensated joints,
    station/cell/plan/moved_path/compensated_check.py; "before (plain)": an arm's plain targets before correction,
    station/cell/plan/moved_path/plain_check.py),
    ``least_mm`` None where no pair held to the margin came within twice ``margin_mm``; the pair and
    where it comes closest."""

    check: str
    least_mm: float | None
    margin_mm: float
    poses: int
    a: str = ""
    b: str = ""
    where: str = ""

    def text(self) -> str:
        """E.g. "after (shifted) 3.4 mm (head mount ↔ obstacle 'post')"; over twice the margin: "over 4 mm"."""
        if self.least_mm is None:
            return f"{self.check} over {2 * self.margin_mm:g} mm"
        return f"{self.check} {self.least_mm:.1f} mm ({self.a} ↔ {self.b})"


@dataclass(frozen=True)
class Failure:
    """Why a run stopped early: the error's type and message and what to do."""

    error_type: str
    message: str
    hint: str = ""
    log_file: str | None = None  # traceback of an internal error
    device: str = ""  # whose error: "controller", "probe" or "" (station/cell/pipeline/outcomes.py, by type)
    link: bool = False  # the fault is that device's link: no answer, connection lost


@dataclass(frozen=True)
class RunSummary:
    """How a run ended. ``run_id`` is None when it failed before a run was created."""

    outcome: Outcome
    run_id: int | None = None
    cell: str = ""
    robot: str = ""
    db: str | None = None
    identification: IdentificationSummary | None = None
    correction: CorrectionSummary | None = None
    before: ErrorStats | None = None
    after: ErrorStats | None = None
    oracle: ErrorStats | None = None
    upload: UploadSummary | None = None
    upload_skipped: bool = False
    reversal: ReversalSummary | None = None
    failure: Failure | None = None
    report: str | None = None
    notes: tuple[str, ...] = field(default=())
    tools: tuple[ToolSummary, ...] = field(default=())  # [[tool]]: each tool's own correction
    compensation: CompensationSummary | None = None  # an articulated arm's compensated targets
    tables: TableSummary | None = None  # the controller's active table at the run's start and end
    recentring: tuple[RecentringStats, ...] = field(default=())  # re-centred readings per kind
    #: why a run that identified ends NOT_UPLOADED by itself: "correction_bound" (no table within the
    #: controller's capacity meets correction.max_interpolation_um for the identified robot); None otherwise
    not_uploaded_reason: str | None = None
    error_model: ErrorModelSummary | None = None  # [identification] model other than geometric (issue 30)
    #: a simulated cell's judge's figures (station/cell/records/judge.py); empty for a real cell
    simulation: tuple[JudgeFigure, ...] = field(default=())
    #: TARGET_MISSED: the acceptance limits missed (station/cell/records/missed.py); the JSON's failure
    missed: tuple[MissedLimit, ...] = field(default=())
    #: the collision checks' least clearances [mm]: the pre-motion one, then each table's shifted one
    clearances: tuple[ClearanceSummary, ...] = field(default=())

    @property
    def exit_code(self) -> int:
        return int(self.outcome)

    @property
    def ok(self) -> bool:
        return self.outcome is Outcome.SUCCESS

    @property
    def gain(self) -> float | None:
        """RMS before / RMS after correction."""
        if self.before is None or self.after is None:
            return None
        return self.before.rms_um / max(self.after.rms_um, 1e-9)

    @property
    def after_vs_oracle(self) -> float | None:
        """RMS after the station's correction / RMS after the true correction (simulation)."""
        if self.after is None or self.oracle is None or not self.oracle.n:
            return None
        return self.after.rms_um / max(self.oracle.rms_um, 1e-9)

    def replace(self, **changes: Any) -> RunSummary:
        return dataclasses.replace(self, **changes)

    def recentring_text(self) -> str | None:
        """One line on the re-centred readings (None when none was re-centred)."""
        if not any(r.n_recentred for r in self.recentring):
            return None
        parts = [f"{_KIND_WORDS.get(r.kind, r.kind)} {r.n_recentred} of {r.n_readings}"
                 + (f" (up to {r.max_um:.0f} µm)" if r.n_recentred else "") for r in self.recentring]
        return ("re-centred to bring the probes into their stroke: " + ", ".join(parts)
                + "; in verification the re-centring's move is counted in the error")

    def rp_text(self) -> str | None:
        """What RP before and after measured, and whether they differ beyond their spread (a
        correction moves where the robot goes, not how well it repeats); None without RP."""
        b, a = self.before, self.after
        if b is None or a is None or b.rp_mean_um is None or a.rp_mean_um is None or b.rp_max_um is None \
                or a.rp_max_um is None:
            return None
        text = (f"RP (ISO 9283 repeatability, {a.cycles} cycles at each of {a.n_poses} poses): before mean "
                f"{b.rp_mean_um:.1f} µm, worst pose {b.rp_max_um:.1f}; after mean {a.rp_mean_um:.1f} µm, worst "
                f"pose {a.rp_max_um:.1f}")
        if b.rp_sd_um is None or a.rp_sd_um is None:
            return text
        # the standard error of each mean over the poses; 3 of them apart is a real change. The
        # statement is computed from the figures it stands beside (issue 29: "the means agree"
        # was said of 13.4 and 26.4 µm): it gives the difference and the threshold, never a claim
        se = float(np.hypot(b.rp_sd_um / np.sqrt(b.n_poses), a.rp_sd_um / np.sqrt(a.n_poses)))
        diff = a.rp_mean_um - b.rp_mean_um
        if abs(diff) <= 3.0 * se:
            return (f"{text}. The means differ by {diff:+.1f} µm, less than 3× their standard error "
                    f"(3 × {se:.2f} = {3.0 * se:.1f} µm over {a.n_poses} poses of {a.cycles} cycles): a change this "
                    f"size cannot be told from the scatter of RP from pose to pose ({max(a.rp_sd_um, b.rp_sd_um):.1f} "
                    f"µm); a correction changes where the robot goes, not how well it repeats. RP against a limit is "
                    f"judged per pose ([verification] max_rp_um)")
        return (f"{text}. The means differ by {diff:+.1f} µm, more than 3× their standard error (3 × {se:.2f} = "
                f"{3.0 * se:.1f} µm): the robot repeated {'worse' if diff > 0 else 'better'} after the correction; "
                f"check what changed between the two (warm-up, backlash, the approach)")

    def figures(self) -> list[tuple[str, float, str, int]]:
        """(label, value, unit, digits) of the headline figures, in display order; the UI and
        the report show these."""
        spec: list[tuple[str, float | None, str, int]] = [
            ("RMS before", self.before.rms_um if self.before else None, "µm", 1),
            ("RMS after", self.after.rms_um if self.after else None, "µm", 1),
            ("improvement ratio", self.gain, "×", 1),
            ("oracle RMS after", self.oracle.rms_um if self.oracle else None, "µm", 1),
            ("after / oracle", self.after_vs_oracle, "×", 2),
            ("orientation RMS after",
             self.compensation.orientation_after_arcsec if self.compensation else None, "″", 1),
            ("AP max after (ISO 9283)", self.after.ap_max_um if self.after else None, "µm", 1),
            ("RP max after (ISO 9283)", self.after.rp_max_um if self.after else None, "µm", 1),
            ("identified parameters", self.identification.n_parameters if self.identification else None, "", 0),
            ("identification residual RMS",
             self.identification.rms_residual_um if self.identification else None, "µm", 1),
            ("upload (read back, activated)", self.upload.seconds if self.upload else None, "s", 2),
        ]
        return [(label, float(v), unit, d) for label, v, unit, d in spec if v is not None]

    # -- JSON ------------------------------------------------------------------------------
    def to_json(self) -> dict[str, Any]:
        """The ``--json`` object: plain JSON types, units in the key names."""
        out: dict[str, Any] = {"outcome": self.outcome.name, "exit_code": self.exit_code,
                               "run_id": self.run_id, "cell": self.cell, "robot": self.robot}
        if self.db is not None:
            out["db"] = self.db
        for key in ("identification", "correction", "compensation", "before", "after", "oracle", "upload",
                    "reversal", "failure", "tables", "error_model"):
            value = getattr(self, key)
            if value is not None:
                out[key] = _plain(dataclasses.asdict(value))
        if self.failure is None and self.missed and self.outcome is Outcome.TARGET_MISSED:
            out["failure"] = failure_json(self.missed)
        if self.upload_skipped:
            out["upload_skipped"] = True
        if self.not_uploaded_reason is not None:
            out["not_uploaded_reason"] = self.not_uploaded_reason
        if self.gain is not None:
            out["gain"] = self.gain
        if self.after_vs_oracle is not None:
            out["after_vs_oracle"] = self.after_vs_oracle
        if self.report is not None:
            out["report"] = self.report
        if self.notes:
            out["notes"] = list(self.notes)
        if self.recentring:
            out["recentring"] = [_plain(dataclasses.asdict(r)) for r in self.recentring]
        if self.clearances:
            out["clearances"] = [_plain(dataclasses.asdict(c)) for c in self.clearances]
        if self.tools:
            out["tools"] = [{**_plain(dataclasses.asdict(t)), "after_vs_oracle": t.after_vs_oracle}
                            for t in self.tools]
        if self.simulation:  # each figure with its unit: µm, or × for a ratio
            out["simulation"] = {f.name: {"value": f.value, "unit": f.unit, "caption": f.caption}
                                 for f in self.simulation}
        out["units"] = {"lengths": "µm (keys *_um)", "times": "s (keys *_s, seconds)",
                        "parameters": "mm and rad (identification.parameters)",
                        "error terms": "each term's own unit (error_model.terms[].unit)",
                        "clearances": "mm (keys *_mm)"}
        return out

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> RunSummary:
        """Read a stored :meth:`to_json` object back."""
        def sub(key: str, typ: type) -> Any:
            v = d.get(key)
            return None if v is None else _build(typ, v)

        return cls(
            outcome=Outcome[d["outcome"]], run_id=d.get("run_id"), cell=d.get("cell", ""),
            robot=d.get("robot", ""), db=d.get("db"),
            identification=sub("identification", IdentificationSummary),
            correction=sub("correction", CorrectionSummary), before=sub("before", ErrorStats),
            after=sub("after", ErrorStats), oracle=sub("oracle", ErrorStats),
            upload=sub("upload", UploadSummary), upload_skipped=bool(d.get("upload_skipped", False)),
            reversal=sub("reversal", ReversalSummary),
            failure=None if missed_from_json(d.get("failure")) else sub("failure", Failure),
            missed=missed_from_json(d.get("failure")),
            report=d.get("report"), notes=tuple(d.get("notes", ())),
            tools=tuple(_build(ToolSummary, t) for t in d.get("tools", ())),
            compensation=sub("compensation", CompensationSummary), tables=sub("tables", TableSummary),
            recentring=tuple(_build(RecentringStats, r) for r in d.get("recentring", ())),
            clearances=tuple(_build(ClearanceSummary, c) for c in d.get("clearances", ())),
            not_uploaded_reason=d.get("not_uploaded_reason"), error_model=sub("error_model", ErrorModelSummary),
            simulation=tuple(JudgeFigure(k, float(v["value"]), str(v["unit"]), str(v.get("caption", "")))
                             for k, v in (d.get("simulation") or {}).items()))


_KIND_WORDS = {"identification": "identification", "reversal": "reversal", "verification_before": "before",
               "verification_after": "after", "oracle": "oracle"}


def _plain(obj: Any) -> Any:
    if isinstance(obj, Mapping):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    return obj


def _build(typ: type, value: Any) -> Any:
    """A summary dataclass from its JSON dict (tuples and nested parameters restored)."""
    kwargs = {}
    for f in dataclasses.fields(typ):
        if f.name not in value:
            continue
        v = value[f.name]
        if f.name == "parameters":
            v = tuple(ParameterEstimate(**p) for p in v)
        elif f.name == "terms" and typ is ErrorModelSummary:
            v = tuple(ErrorTermEstimate(**t) for t in v)
        elif isinstance(v, Sequence) and not isinstance(v, str):
            v = tuple(v)
        kwargs[f.name] = v
    return typ(**kwargs)
