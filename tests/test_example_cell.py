"""The example cell shipped in examples/scara600 (issue 8's check): a cell that shares nothing with
the built-in one (its own SCARA robot file, a 7-probe head, a body of other layout), rehearsed in
simulation from its own files, gains ≥ 20× and ends near the oracle (seed 1 here; seeds 1, 2, 3 and
their median in benchmarks/bench_example_cell.py); its 200 mm gripper's own correction is within
1.2× of the gripper's oracle."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from station.cell.config.cell_config import load_config
from station.ui.cli.main import main

CELL = Path(__file__).resolve().parents[1] / "examples" / "scara600" / "cell.toml"


def test_the_example_cell_shares_nothing_with_the_built_in_one():
    from simulators import start_simulated_cell
    from simulators.reference_cell import cell_config_text
    from station.cell.config.cell_config import parse_text

    cfg = load_config(CELL)
    with start_simulated_cell(seed=1) as sim:
        builtin = parse_text(cell_config_text(sim, 1))
    assert cfg.model.name != builtin.model.name and cfg.model.is_scara
    assert not np.allclose(cfg.model.nominal[6:], builtin.model.nominal[6:])  # other arm geometry
    assert cfg.head.n_probes == 7 and builtin.head.n_probes == 6
    assert cfg.cube_edge_mm != builtin.cube_edge_mm
    d = np.linalg.norm(cfg.body_points[:, None, :3, 3] - builtin.body_points[None, :, :3, 3], axis=-1)
    assert d.min() > 1.0  # no measuring point in common
    assert cfg.body_sigma is not None and np.all(cfg.body_sigma > 0)  # the CMM report's σ


def test_plan_of_the_example_cell(capsys):
    assert main(["plan", str(CELL), "--json"]) == 0
    p = json.loads(capsys.readouterr().out)
    assert p["outcome"] == "SUCCESS" and p["exit_code"] == 0  # every --json object routes (issue 29)
    assert p["robot"] == "scara600" and not p["rejected"]
    assert p["n_identification"] >= 100 and p["motion_s_estimate"] > 0


@pytest.mark.parametrize("seed", [1])
@pytest.mark.slow  # an end-to-end session: the slow tier (README), run by CI
def test_rehearsal_of_the_example_cell(seed, tmp_path, capsys):
    """One seed: each costs a whole simulated session of the example cell, and seeds 2 and 3 asserted
    the same bounds again (issue 42: the suite's time); benchmarks/bench_example_cell.py runs seeds
    1, 2, 3 and prints each one's gain and after/oracle with their median and worst. One seed's
    after/oracle is a random variable, not a property of the code: the simulated noise is keyed to
    the commanded joints to 1e-9 rad (a resumed run repeats its physics), so a last-digit difference
    of the BLAS kernel (OpenBLAS's Haswell kernels against its Zen ones on the same AMD machine)
    draws another realisation, and seed 3 then gives 1.23 where it gave 1.10. So the seed is bounded
    on both sides with room for that scatter (0.7 … 1.3) and "after" in µm; the mean over seeds is
    the benchmark's (benchmarks/bench_table_design.py)."""
    code = main(["calibrate", "--simulated", str(CELL), "--json", "--seed", str(seed),
                 "--db", str(tmp_path / f"runs-{seed}.sqlite")])
    out = json.loads(capsys.readouterr().out)
    assert code == 0, (seed, out.get("failure"))
    assert out["robot"] == "scara600"
    assert out["gain"] >= 20.0, seed
    assert 0.7 <= out["after_vs_oracle"] <= 1.3, (seed, out["after_vs_oracle"])
    assert out["after"]["rms_um"] <= 15.0, (seed, out["after"]["rms_um"])
    # the gripper that replaces the head: its own correction is as good as its oracle's, and
    # the head's table would leave it far worse (issue 8, point 8)
    (tool,) = out["tools"]
    assert tool["name"] == "gripper"
    assert 0.7 <= tool["after_vs_oracle"] <= 1.2, (seed, tool["after_vs_oracle"])
    assert tool["head_rms_um"] > 4 * tool["after_rms_um"]
