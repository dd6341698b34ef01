"""A six-axis plan names the points it leaves out (issue 37 §3): point, configuration and why, as a
SCARA's plan does; ``station plan`` warns when points are measured in no pose at all. Before, a point
that no configuration reached was dropped without a word (8 of 24 on a KUKA cell)."""

from __future__ import annotations

import shutil
from pathlib import Path

from station.cell.config.cell_config import load_config
from station.cell.plan.measurement_plan import build_plan
from station.ui.cli.main import main

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "puma560"
#: two corners far beyond the arm's reach (body frame; the robot base stands at x = -550)
FAR = ("FAR1,900.0,-40.0,40,0,0,15,2.0,3.0\n", "FAR2,-50.0,1400.0,40,0,0,105,2.0,3.0\n")


def _cell(tmp_path: Path) -> Path:
    for name in ("puma560.mdh.csv", "head.toml", "cell.toml"):
        shutil.copy(EXAMPLE / name, tmp_path / name)
    (tmp_path / "body.csv").write_text((EXAMPLE / "body.csv").read_text() + "".join(FAR), encoding="utf-8")
    return tmp_path / "cell.toml"


def test_points_out_of_reach_of_a_six_axis_arm_are_named_with_configuration_and_reason(tmp_path, capsys):
    path = _cell(tmp_path)
    plan = build_plan(load_config(path))
    named = {pid: why for pid, _, why in plan.rejected if pid in ("FAR1", "FAR2")}
    assert set(named) == {"FAR1", "FAR2"}, plan.rejected[:5]
    assert all("configuration" in why and len(why.split(": ", 1)[1]) > 5 for why in named.values()), named
    assert not {s.point_id for s in plan.identification} & {"FAR1", "FAR2"}
    assert main(["plan", str(path)]) == 0
    out = capsys.readouterr().out
    assert "NOT measured: FAR1 configuration " in out and "elbow" not in out.split("NOT measured: FAR1")[1][:30]
    warning = next(line for line in out.splitlines() if "measuring points are measured in no pose" in line)
    assert "of 26 measuring points" in warning and "FAR1, FAR2" in warning, warning
