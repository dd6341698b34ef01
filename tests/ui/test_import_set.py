"""What ``station --help`` and ``station identify`` import: the numeric core only.

A user scripting hundreds of fits, or an operator waiting for ``--help``, must not pay for the
cell layer, its devices, the TUI or the plots (issue 21). Each command runs in a fresh
interpreter, which then lists ``sys.modules``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from station.core.kinematics.poses import spread_joints
from station.core.measurement.measurements import synthetic_set
from station.io.datafile import write_csv
from station.io.robot.files import load_robot
from station.ui.cli.main import build_parser

ROOT = Path(__file__).resolve().parents[2]

#: modules neither command may load (a prefix matches the package and all below it)
FORBIDDEN = ("station.cell", "drivers", "simulators", "pymodbus", "serial", "textual", "matplotlib",
             "scipy.stats")

# Runs the console script's main() with argv, then writes the loaded modules to a file: stdout
# belongs to the command.
RUNNER = """
import json, sys
from station.ui.cli.main import main
out, argv = sys.argv[1], sys.argv[2:]
try:
    rc = main(argv)
except SystemExit as e:
    rc = e.code
with open(out, "w") as f:
    json.dump({"rc": rc, "modules": sorted(sys.modules)}, f)
"""


@pytest.fixture(scope="module")
def position_file(tmp_path_factory) -> Path:
    """30 SR 800 positions with 10 µm noise, joints in degrees (docs/data-files.md)."""
    model = load_robot("sr800")
    rng = np.random.default_rng(7)
    q = spread_joints(model, 30, rng)
    data = synthetic_set(model, "position", q, model.nominal, sigma=np.full(3, 0.010), rng=rng)
    q_file = np.array(q)
    q_file[:, [0, 1, 3]] = np.degrees(q_file[:, [0, 1, 3]])
    path = tmp_path_factory.mktemp("imports") / "positions.csv"
    write_csv(path, ["q1 [deg]", "q2 [deg]", "q3 [mm]", "q4 [deg]", "x [mm]", "y [mm]", "z [mm]"],
              np.column_stack([q_file, data.measured]))
    return path


def _loaded(tmp_path: Path, *argv: str) -> tuple[int, str, set[str]]:
    out = tmp_path / "modules.json"
    r = subprocess.run([sys.executable, "-c", RUNNER, str(out), *argv], cwd=ROOT, capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    d = json.loads(out.read_text())
    return d["rc"], r.stdout, set(d["modules"])


def _forbidden(modules: set[str]) -> list[str]:
    return sorted(m for m in modules if any(m == f or m.startswith(f + ".") for f in FORBIDDEN))


def test_help_loads_no_cell_devices_tui_or_plots(tmp_path):
    rc, out, modules = _loaded(tmp_path, "--help")
    assert rc == 0 and "identify" in out and "calibrate" in out
    assert _forbidden(modules) == []
    assert not any(m.startswith("station.core") for m in modules)  # help needs no numbers at all


def test_identify_loads_the_core_only(tmp_path, position_file):
    rc, out, modules = _loaded(tmp_path, "identify", str(position_file), "--objective", "position")
    assert rc == 0 and "identified" in out
    assert "station.core.identification.identify" in modules  # it did fit
    assert _forbidden(modules) == []
    assert not any(m.startswith("station.ui.commands_") and m != "station.ui.cli.commands_core" for m in modules)


def test_every_command_names_a_function_that_exists():
    """The commands are imported by name when they run: a misspelt name fails here, not for a user."""
    from station.ui.cli.main import _command

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    assert {"identify", "calibrate", "recheck", "tui", "compensate", "conformance"} <= set(sub.choices)
    for name, parser in sub.choices.items():
        spec = parser.get_default("func")
        assert callable(_command(spec)), f"station {name}: {spec}"
