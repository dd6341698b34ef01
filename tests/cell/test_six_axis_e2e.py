"""End to end on the simulated six-axis cell (issue 9): plan, measure, identify, compensate,
verify — the figures of the issue's checks on seed 1 (benchmarks/bench_six_axis.py runs seeds
1, 2 and 3)."""

from __future__ import annotations

import pytest

from station.cell.plan.steps import StepKind
from station.cell.records.rundb import RunDB
from station.cell.session.calibrate import CellRequest, run_calibration_session
from station.errors import Outcome
from station.ui.simulated_cell import load_cell


@pytest.mark.slow  # an end-to-end session: the slow tier (README), run by CI
def test_six_axis_cell_calibrates_through_compensated_targets(tmp_path):
    db = str(tmp_path / "six.sqlite")
    s = run_calibration_session(CellRequest(simulated=True, robot="irb2600", seed=1, db=db), lambda e: None,
                                load=load_cell)
    assert s.outcome is Outcome.SUCCESS, s.failure
    assert s.robot == "irb2600" and s.identification is not None and s.run_id is not None
    assert s.identification.n_parameters == 30
    assert s.correction is None and s.upload is None  # no table: compensated targets
    # the plain and the compensated targets' paths checked before they moved (issue 40), each clear of the margin
    assert [c.check for c in s.clearances] == ["pre-motion", "before (plain)", "after (compensated)",
                                               "oracle (compensated)"]
    assert all(c.least_mm is None or c.least_mm >= c.margin_mm for c in s.clearances)
    assert s.before is not None and s.after is not None and s.oracle is not None
    # the checks: ≥ 10× better, within 1.2× of the oracle's
    assert s.gain is not None and s.gain >= 10.0
    assert s.after_vs_oracle is not None and 0.7 <= s.after_vs_oracle <= 1.2, s.after_vs_oracle
    assert s.after.rms_um < 60.0, s.after.rms_um  # µm, where the robot ends up
    assert s.after.ap_max_um < s.before.ap_max_um and s.after.rp_max_um is not None
    with RunDB(db) as rdb:
        extra = rdb.load_result(s.run_id, "articulated")
        assert rdb.completed_steps(s.run_id, ok_only=True)
        after = rdb.measurements(s.run_id, kind=StepKind.VERIFY_AFTER.value)
    assert all(r.ok for r in after)
    # orientation in arc seconds, corrected too
    o = extra["orientation"]
    assert o["verification_after"]["rms_arcsec"] < 0.2 * o["verification_before"]["rms_arcsec"]
    assert o["oracle"]["rms_arcsec"] > 0
    # the joint-offset-only correction beside the full model, on the same targets
    acc = extra["joint_offsets_only"]["accuracy"]
    assert acc["targets"] == extra["n_targets"] == len({(r.point_id, r.label.split(" cycle")[0]) for r in after})
    jo, full, unc = (acc[k]["rms_position_um"] for k in ("joint_offsets", "full_model", "uncorrected"))
    assert full < jo < unc
    assert any("joint-zero offsets only" in n for n in s.notes)
    assert any("orientation error RMS" in n and "″" in n for n in s.notes)
    # the same figures as fields of the summary (the --json object and the report read them)
    c = s.compensation
    assert c is not None and c.method == "compensated targets" and c.n_targets == extra["n_targets"]
    assert c.orientation_after_arcsec == o["verification_after"]["rms_arcsec"]
    assert c.joint_offsets_rms_um == jo and c.full_model_rms_um == full
    back = type(s).from_json(s.to_json())
    assert back.compensation == c and s.to_json()["compensation"]["orientation_before_arcsec"] > 0


def test_simulated_robot_without_a_built_in_cell_is_refused(tmp_path):
    s = run_calibration_session(CellRequest(simulated=True, robot="puma560", db=str(tmp_path / "x.sqlite")),
                                lambda e: None, load=load_cell)
    assert s.outcome is Outcome.CONFIG_ERROR and s.exit_code == 2
    assert s.failure is not None and "irb2600" in s.failure.message


def _cfg_and_cell(seed: int = 2):
    from simulators.six_axis_cell import six_axis_cell, six_axis_config_text
    from station.cell.config.cell_config import parse_text

    class S:
        def __init__(self) -> None:
            self.cell = six_axis_cell(seed)
            self.probe_port = "socket://127.0.0.1:1"
            self.controller_host = "127.0.0.1"
            self.controller_port = 1502

    servers = S()
    return parse_text(six_axis_config_text(servers, seed), "<six-axis>"), servers.cell


def test_oracle_folds_the_half_backlash_into_the_joint_zeros_of_tilted_frames():
    """Arriving from below, a joint stands half its backlash short: the oracle's model at the
    commanded joints is the true robot at the physical ones (A2 … A6 are tilted frames, where a
    joint's zero is not the transform's yaw)."""
    import numpy as np

    from station.cell.pipeline.calibration import reference_params
    from station.core.kinematics.forward import forward

    cfg, cell = _cfg_and_cell()
    t = cell.truth
    q = np.deg2rad([[10.0, 30.0, -20.0, 40.0, 50.0, -60.0], [-20.0, 10.0, 5.0, -30.0, -70.0, 100.0]])
    np.testing.assert_allclose(forward(cfg.model, q, reference_params(cfg, t)),
                               forward(cfg.model, q - 0.5 * t.backlash, t.params), atol=1e-9)


def test_compensated_verification_targets_put_the_true_robot_on_target():
    """With the true parameters, the commanded Cartesian targets make the nominal controller command
    joints at which the true robot's head lies on the wanted world pose (the oracle's premise)."""
    import numpy as np

    from station.cell.pipeline.calibration import articulated_targets, reference_params
    from station.cell.plan.measurement_plan import build_plan, head_targets_world
    from station.core.kinematics.forward import forward
    from station.core.kinematics.transforms import pose_to_matrix

    cfg, cell = _cfg_and_cell()
    steps = build_plan(cfg).run_steps(1, True)
    p_true = reference_params(cfg, cell.truth)
    targets = articulated_targets(cfg, steps, p_true, p_true[:6])
    plain = articulated_targets(cfg, steps, None, p_true[:6])
    assert targets.keys() == plain.keys() and len(targets) == len(build_plan(cfg).verification)
    heads = head_targets_world(cfg)
    for (point, code), (q, pose) in targets.items():
        np.testing.assert_allclose(forward(cfg.model, q[None], p_true)[0], heads[point], atol=1e-6)
        # the command is the nominal pose of those joints, in the base frame
        np.testing.assert_allclose(pose_to_matrix(pose), forward(cfg.model, q[None], setup=False)[0], atol=1e-9)
        # and it differs from the plain target by the robot's error (≈ 1 mm), not by nothing
        assert 0.05 < np.linalg.norm(pose[:3] - plain[(point, code)][1][:3]) < 10.0
