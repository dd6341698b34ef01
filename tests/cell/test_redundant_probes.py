"""Redundant probes detect a bad touch: calibrations on the simulator with a seven-probe head
(examples/heads/seven-probe.toml) and a ten-probe head, a stuck probe and debris injected on one
probe. The bad probe is named in the run database's messages, the readings stay valid where the
other probes fix the pose, and the identified robot agrees with a fault-free run of the same
seed."""

from __future__ import annotations

from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from simulators import start_simulated_cell
from simulators.cell import CellTruth, SimulatedCell
from simulators.probe_head_sim import ProbeHeadPhysics
from simulators.reference_cell import cell_config_text
from station.cell.config.cell_config import CellConfig, parse_text
from station.cell.pipeline.calibration import Options, run_calibration
from station.cell.records.run_records import MeasurementRecord
from station.cell.records.rundb import RunDB
from station.cell.records.summary import RunSummary
from station.cell.run.facts.events import MeasurementRecorded, Notice
from station.cell.run.runner import Reading, failure_cause, probe_readings
from station.cell.session.calibrate import open_cell
from station.core.kinematics.forward import forward
from station.core.kinematics.transforms import pose_to_matrix
from station.core.probe.geometry import FACE_NORMALS, ProbeHeadGeometry
from station.errors import ConfigError, MeasurementFault
from station.io.head_file import head_to_toml, load_head
from station.io.robot.files import load_robot
from tests.once import once_per_session

SEVEN = Path(__file__).resolve().parents[2] / "examples" / "heads" / "seven-probe.toml"
SEED = 1
#: a short plan: two visits per identification pose, one verification cycle
PLAN = {"repeats = 4": "repeats = 2", "verification_cycles = 5": "verification_cycles = 1"}
INJECT_AFTER = 5  # measurements before a fault is injected


@dataclass
class Run:
    cfg: CellConfig
    summary: RunSummary | None
    records: list[MeasurementRecord]
    events: list
    error: BaseException | None = None


def ten_probe_head(path: Path) -> Path:
    """A ten-probe head on which any one bad probe can be singled out from one touch."""
    contacts = [(0, (5, 5, 0)), (0, (35, 5, 0)), (0, (20, 35, 0)), (0, (35, 30, 0)), (1, (0, 6, -8)),
                (1, (0, 34, -12)), (1, (0, 20, -30)), (2, (6, 0, -10)), (2, (34, 0, -8)), (2, (20, 0, -30))]
    M0 = pose_to_matrix(np.array([0.0, 0.0, -60.0, 0.0, 0.0, 0.0]))
    pts = np.array([M0[:3, :3] @ (np.array(p, float) + FACE_NORMALS[f]) + M0[:3, 3] for f, p in contacts])
    dirs = np.array([-FACE_NORMALS[f] for f, _ in contacts])
    geom = ProbeHeadGeometry(pts, dirs, np.array([f for f, _ in contacts]), 1.0, 10.0, 40.0, M0,
                             ids=tuple(f"Q{i + 1}" for i in range(10)), name="ten-probe head")
    path.write_text(head_to_toml(geom, load_robot("sr800").nominal[-6:]), encoding="utf-8")
    return path


def calibrate(tmp_path: Path, head_file: Path, fault=None, every: int | None = None) -> Run:
    """A calibration (no upload) of the simulated cell with the head of ``head_file``; ``fault``
    (physics -> None) is applied after :data:`INJECT_AFTER` measurements (and after every
    ``every``-th measurement from then on, when given)."""
    tmp_path.mkdir(parents=True, exist_ok=True)
    head = load_head(head_file, 40.0)
    truth = CellTruth.generate(model=load_robot("sr800").with_tool(head.frame_pose), seed=SEED)
    phys = ProbeHeadPhysics(geometry=head.geometry, seed=SEED + 1)
    cell = SimulatedCell(truth=truth, seed=SEED, probe=phys)
    events: list = []
    seen = [0]

    def emit(e) -> None:
        events.append(e)
        if isinstance(e, MeasurementRecorded) and fault is not None:
            seen[0] += 1
            n = seen[0]
            if n == INJECT_AFTER or (every and n > INJECT_AFTER and (n - INJECT_AFTER) % every == 0):
                fault(phys)

    with ExitStack() as stack:
        srv = start_simulated_cell(seed=SEED, cell=cell)
        stack.callback(srv.stop)
        phys.server = srv  # type: ignore[attr-defined]  # a fault may act on the unit (a dead channel)
        text = cell_config_text(srv, SEED) + f'\n[head]\nfile = "{head_file}"\n'
        for old, new in PLAN.items():
            text = text.replace(old, new)
        cfg = parse_text(text, str(tmp_path / "cell.toml"))
        db = stack.enter_context(RunDB(tmp_path / "runs.sqlite"))
        dev = open_cell(cfg, stack)
        summary, error = None, None
        try:
            summary = run_calibration(cfg, dev.probe, dev.controller, db, emit, options=Options(upload=False))
        except MeasurementFault as exc:
            error = exc
        records = db.measurements(db.latest_run().id)
    return Run(cfg, summary, records, events, error)


def positions(run: Run, q: np.ndarray) -> np.ndarray:
    """Head positions (n,3) [mm] of the run's identified model at joints ``q``."""
    m = run.cfg.model
    p = np.array(m.nominal)
    assert run.summary is not None and run.summary.identification is not None
    for e in run.summary.identification.parameters:
        p[m.param_index(e.name)] = e.value
    return forward(m, q, params=p, setup=True)[:, :3, 3]


#: how far a fault run's identified robot may lie from the fault-free run's over its poses [µm]:
#: within the identified position's own uncertainty ('station plan' predicts 2.8–4.0 µm for the
#: built-in cell; with register map 2's integer joints two fault-free realisations differ by 3.8)
AGREE_UM = 5.0


def agreement_um(run: Run, base: Run) -> float:
    """RMS difference [µm] of two identified models over the baseline's measured poses."""
    q = np.array([r.joints_read for r in base.records if r.ok and r.joints_read is not None])
    return float(np.sqrt(np.mean(np.sum((positions(run, q) - positions(base, q)) ** 2, axis=1))) * 1e3)


def recorded_after(run: Run, n: int) -> list[MeasurementRecord]:
    """The run's measurements recorded after the first ``n``, in the order they were recorded. The
    body's locating touches come first and out of the plan's order (issue 37), so a step's index
    says nothing about when it was measured; the order is that of the MeasurementRecorded events,
    the same count :func:`calibrate` injects its faults by."""
    by_step = {r.step_index: r for r in run.records}
    order = [e.index for e in run.events if isinstance(e, MeasurementRecorded)]
    assert sorted(order) == sorted(by_step), "every stored measurement was announced once"
    return [by_step[i] for i in order[n:]]


def after_fault(run: Run) -> list[MeasurementRecord]:
    # the touch during which the fault appears still reads right (a probe sticks at its reading)
    return recorded_after(run, INJECT_AFTER + 1)


@pytest.fixture(scope="module")
def seven_baseline(tmp_path_factory) -> Run:
    """The fault-free seven-probe run four tests compare with: once per session, not once per
    xdist worker their tests land on (issue 42)."""
    return once_per_session(tmp_path_factory, "seven-probe-baseline", lambda tmp: calibrate(tmp, SEVEN))


def test_fault_free_seven_probe_run_reports_a_residual_and_needs_no_remeasure(seven_baseline):
    run = seven_baseline
    assert run.error is None and run.summary is not None and run.summary.identification is not None
    assert all(r.ok for r in run.records)
    res = [r.pose_residual_um for r in run.records]
    assert all(v is not None for v in res) and 0.0 < float(np.median(res)) < 2.0  # µm: a real figure
    assert sum("disagree" in r.message for r in run.records) <= 2  # false alarms at alpha 1e-3
    # the readings are stored per probe (head order) with the probes' channels
    assert all(len(r.readings_mm) == 7 for r in run.records)


def test_a_stuck_probe_is_named_and_the_identification_is_unaffected(tmp_path, seven_baseline):
    run = calibrate(tmp_path, SEVEN, lambda phys: phys.inject_stuck("P3"))
    assert run.error is None and run.summary is not None
    later = after_fault(run)
    named = [r for r in later if "probe P3 (channel 4) excluded" in r.message and "stuck" in r.message]
    assert len(named) >= 0.95 * len(later), [r.message for r in later if r not in named][:3]
    assert sum(r.ok for r in later) >= 0.95 * len(later)
    notices = [e.message for e in run.events if isinstance(e, Notice)]
    assert any(m.startswith("probe P3 (channel 4) is stuck") for m in notices)
    # the identified robot: within a few µm of the fault-free run over the measured poses
    assert agreement_um(run, seven_baseline) < AGREE_UM


def test_debris_for_one_touch_is_detected_re_measured_and_the_reading_kept(tmp_path, seven_baseline):
    run = calibrate(tmp_path, SEVEN, lambda phys: phys.inject_debris("P6", 0.020, touches=1), every=7)
    assert run.error is None and run.summary is not None
    # the touch after each injection carries the debris: the 6th, 13th, ... recorded
    hit = [r for r in recorded_after(run, INJECT_AFTER) if "measured again" in r.message]
    injected = 1 + (len(run.records) - INJECT_AFTER) // 7
    assert len(hit) >= 0.95 * injected
    # each such touch was re-measured; the second touch agreed and is the stored reading
    assert all(r.ok and "the re-measured touch agrees" in r.message for r in hit)
    assert agreement_um(run, seven_baseline) < AGREE_UM


def test_debris_that_stays_on_a_seven_probe_head_stops_the_run_naming_the_candidates(tmp_path):
    run = calibrate(tmp_path, SEVEN, lambda phys: phys.inject_debris("P6", 0.020))
    assert isinstance(run.error, MeasurementFault)
    assert "probes disagree" in str(run.error)
    bad = [r for r in recorded_after(run, INJECT_AFTER) if not r.ok]  # debris: from its first touch
    assert len(bad) == 3 and all("P6 (channel 7)" in r.message and "cannot single out" in r.message for r in bad)


@pytest.mark.slow  # an end-to-end session: the slow tier (README), run by CI
def test_a_ten_probe_head_names_permanent_debris_and_keeps_the_identification(tmp_path):
    head = ten_probe_head(tmp_path / "ten.toml")
    base = calibrate(tmp_path / "base", head)
    run = calibrate(tmp_path / "debris", head, lambda phys: phys.inject_debris("Q6", 0.020))
    assert base.error is None and run.error is None and run.summary is not None
    later = recorded_after(run, INJECT_AFTER)
    named = [r for r in later if "probe Q6 (channel 6) excluded" in r.message and "off by +" in r.message]
    assert len(named) >= 0.95 * len(later)
    assert all(r.ok for r in named)
    assert agreement_um(run, base) < AGREE_UM


# --- the runner's small parts ------------------------------------------------------------------

def test_channels_are_mapped_and_scaled_and_a_missing_channel_is_a_config_error():
    geom = load_head(SEVEN).geometry
    values = np.arange(1.0, 9.0) / 10
    status = ["invalid"] + ["ok"] * 7
    r, st = probe_readings(geom, values, status)
    np.testing.assert_allclose(r, values[1:] * geom.probe_scales)
    assert st == ("ok",) * 7
    with pytest.raises(ConfigError, match=r"reports 6 channels.*probe P7 \(channel 8\)"):
        probe_readings(geom, values[:6], status[:6])


def test_failure_cause_names_probe_and_channel():
    def reading(status, probes=()):
        return Reading(np.zeros(4), None, b"", None, status, None, None, False, "pose not solved: x", None, probes)

    assert failure_cause(reading(("ok", "over_range", "ok"))) == "probe 2 over range"
    named = reading(("ok", "under_range"), (("P1", 2), ("P2", 3)))
    assert failure_cause(named) == "probe P2 under range (channel 3)"


def test_a_dead_channel_on_a_redundant_head_is_left_out_and_the_run_goes_on(tmp_path, seven_baseline):
    from drivers.probe_protocol import ChannelStatus

    # P6 sits on channel 7: the unit's channel index 6 reports invalid from the 6th touch on
    run = calibrate(tmp_path, SEVEN, lambda phys: phys.server.probe_server.faults.force_status(6, ChannelStatus.INVALID))
    assert run.error is None and run.summary is not None
    later = recorded_after(run, INJECT_AFTER)
    assert all(r.ok and r.message.startswith("probe P6 (channel 7) gave no reading (invalid)") for r in later)
    assert all(r.channel_status[5] == "invalid" for r in later)
    notices = [e.message for e in run.events if isinstance(e, Notice)]
    assert any(m.startswith("probe P6 (channel 7) stuck? check it") for m in notices)
    assert agreement_um(run, seven_baseline) < AGREE_UM
