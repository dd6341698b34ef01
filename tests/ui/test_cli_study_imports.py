"""``station study`` loads the numeric core only (issue 38): no cell layer, pipeline, drivers,
plots, TUI, OPC UA or collision library, so a study's time is its arithmetic. The command runs in
a fresh interpreter, which then lists ``sys.modules``."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

#: packages a study must not load (a prefix matches the package and all below it)
FORBIDDEN = ("station.cell", "station.fleet", "station.ui.report", "station.ui.tui", "station.ui.opcua",
             "drivers", "simulators", "matplotlib", "textual", "asyncua", "fcl", "pymodbus", "serial")

RUNNER = """
import json, sys
from station.ui.cli.main import main
out, argv = sys.argv[1], sys.argv[2:]
rc = main(argv)
with open(out, "w") as f:
    json.dump({"rc": rc, "modules": sorted(sys.modules)}, f)
"""


def test_study_imports_no_cell_plots_tui_or_collision(tmp_path):
    out = tmp_path / "modules.json"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run([sys.executable, "-c", RUNNER, str(out), "study", "--quick", "--json"], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(out.read_text())
    assert doc["rc"] == 0
    assert json.loads(proc.stdout)["studies"], "the study ran"
    loaded = [m for m in doc["modules"] if any(m == f or m.startswith(f + ".") for f in FORBIDDEN)]
    assert loaded == []
    assert "station.core.accuracy.studies" in doc["modules"]
