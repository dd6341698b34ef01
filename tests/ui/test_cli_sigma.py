"""`station identify --json` says what the a-posteriori check found (issue 38): weights that assume
half the noise the data carry are caught, and the σ reported are the scaled ones."""

from __future__ import annotations

import json

import numpy as np

from station.core.kinematics.poses import spread_joints
from station.core.kinematics.transforms import matrix_to_pose
from station.core.measurement.measurements import synthetic_set
from station.io.datafile import write_csv
from station.io.robot.files import load_robot
from station.ui.cli.main import main

HEADER = ["q1 [deg]", "q2 [deg]", "q3 [mm]", "q4 [deg]", "x [mm]", "y [mm]", "z [mm]", "roll [deg]", "pitch [deg]",
          "yaw [deg]"]


def _pose_file(path):
    """60 poses of a perturbed SR 800 with 5 µm / 5″ noise, in degrees."""
    model = load_robot("sr800")
    rng = np.random.default_rng(21)
    true = model.nominal + rng.standard_normal(36) * np.where(model.is_angle(), 5e-4, 0.1)
    q = spread_joints(model, 60, rng)
    data = synthetic_set(model, "pose", q, true, sigma=np.array([0.005] * 3 + [5 * np.pi / 180 / 3600] * 3), rng=rng)
    pose = matrix_to_pose(data.measured)
    pose[:, 3:] = np.degrees(pose[:, 3:])
    qd = np.array(q)
    qd[:, [0, 1, 3]] = np.degrees(qd[:, [0, 1, 3]])
    write_csv(path, HEADER, np.column_stack([qd, pose]))
    return path


def _identify(capsys, f, sigma) -> dict:
    rc = main(["identify", str(f), "--sigma-position", str(sigma), "--sigma-angle", str(sigma), "--json"])
    out = capsys.readouterr().out
    assert rc == 0
    return json.loads(out)


def test_identify_json_scales_the_sigma_of_weights_that_assume_half_the_noise(tmp_path, capsys):
    f = _pose_file(tmp_path / "poses.csv")
    right, half = _identify(capsys, f, 5), _identify(capsys, f, 2.5)
    assert right["variance_factor"]["scaled"] is False and right["variance_factor"]["factor"] == 1.0
    v = half["variance_factor"]
    assert v["scaled"] is True and 1.7 < v["s0"] < 2.3 and v["factor"] == v["s0"] and v["s0"] > v["limit"]
    assert v["level"] == 0.05 and v["degrees_of_freedom"] == 60 * 6 - len(half["parameters"])
    # half the assumed σ halves the a-priori σ; s0 brings them back to what the 5 µm weights report
    for name, p in half["parameters"].items():
        key = "sigma_um" if "sigma_um" in p else "sigma_arcsec"
        assert 0.8 < p[key] / right["parameters"][name][key] < 1.25, name
    assert any("σ are scaled by" in n for n in half["notes"])
