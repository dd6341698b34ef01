"""Error terms beyond geometry that the robot's URDF and UR's kinematics YAML cannot hold (issue 41
§2): each term is named in the written file's header and on stderr, with what leaving it out
costs; the file then holds the geometric fit of the same data where the model carries one, and a
model without terms names none."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from station.core.kinematics.model import robot_to_toml
from station.io.robot.files import load_robot
from station.io.robot.terms import error_terms_toml
from station.ui.cli.main import main

ROOT = Path(__file__).resolve().parents[2]
UR5E = str(ROOT / "examples" / "ur5e" / "ur5e.urdf")
LINKS = ["--robot", UR5E, "--base-link", "base_link_inertia", "--tip-link", "tool0"]
FAMILIES = ("compliance", "cyclic.q2")
NAMES = ("compliance.q2", "compliance.q3", "cyclic.q2.cos1", "cyclic.q2.sin1")
VALUES = (2e-6, 3e-6, 1e-4, -6e-5)
FORMATS = [("urdf", "URDF", "<!--"), ("ur-calibration", "UR-CALIBRATION", "# NOT HELD:")]


def _model_file(tmp_path: Path, *, geometric: np.ndarray | None = None, terms: bool = True) -> tuple[Path, np.ndarray]:
    nominal = load_robot(UR5E, "base_link_inertia", "tool0")
    d = np.random.default_rng(11).normal(size=nominal.nominal.shape).reshape(-1, 6)
    d[:, :3] *= 0.3
    d[:, 3:] *= 5e-4
    p = np.asarray(nominal.nominal) + d.ravel()
    text = robot_to_toml(nominal, p, angle_unit="rad")
    if terms:
        text += error_terms_toml(FAMILIES, NAMES, VALUES, (0.0,) * 4, ("rad/(N·m)",) * 2 + ("rad",) * 2,
                                 effect_on_fit_um=None if geometric is None else 37.5, geometric_params=geometric)
    f = tmp_path / "identified.toml"
    f.write_text(text)
    return f, p


def _export(f: Path, fmt: str, out: Path, capsys) -> tuple[str, str]:
    assert main(["export-model", str(f), "--format", fmt, "-o", str(out), "--json", *LINKS]) == 0
    captured = capsys.readouterr()
    return out.read_text(), captured.err + "\n" + json.dumps(json.loads(captured.out)["not_held"])


@pytest.mark.parametrize("fmt, upper, header", FORMATS)
def test_error_terms_are_named_in_the_header_and_on_stderr(fmt, upper, header, tmp_path, capsys):
    f, _ = _model_file(tmp_path)
    text, err = _export(f, fmt, tmp_path / "out", capsys)
    head = text[:text.index("<robot")] if fmt == "urdf" else "\n".join(
        line for line in text.splitlines() if line.startswith("#"))
    said = re.search(r"the error terms beyond geometry \(([^)]*)\) are not written in (\S+): they move the tool by "
                     r"([0-9.]+) µm RMS", head)
    assert said is not None, head
    assert said.group(1).split(", ") == list(NAMES) and said.group(2) == upper
    assert float(said.group(3)) > 1.0  # the terms move the tool: a figure, not a formality
    assert header in head
    assert f"station: not held: {said.group(0)}" in err  # the same words on stderr


@pytest.mark.parametrize("fmt, upper, header", FORMATS)
def test_the_file_holds_the_geometric_fit_and_says_so(fmt, upper, header, tmp_path, capsys):
    nominal = load_robot(UR5E, "base_link_inertia", "tool0")
    geometric = np.asarray(nominal.nominal) + 1e-3  # the geometric fit of the same data: other numbers
    f, full = _model_file(tmp_path, geometric=geometric)
    text, err = _export(f, fmt, tmp_path / "out", capsys)
    words = (f"are not written in {upper}: it holds the geometric fit of the same data instead, which misses the "
             f"full model by 37.5 µm RMS at the poses they were fitted on")
    assert words in text and words in err
    if fmt == "ur-calibration":  # the shoulder frame is A1: the geometric fit's, not the full model's
        shoulder = yaml.safe_load(text)["kinematics"]["shoulder"]
        assert shoulder["z"] == pytest.approx(geometric[8] * 1e-3, abs=1e-12)
        assert shoulder["z"] != pytest.approx(full[8] * 1e-3, abs=1e-9)


@pytest.mark.parametrize("fmt, upper, header", FORMATS)
def test_a_model_without_terms_names_none(fmt, upper, header, tmp_path, capsys):
    f, _ = _model_file(tmp_path, terms=False)
    text, err = _export(f, fmt, tmp_path / "out", capsys)
    assert "error terms" not in text and "error terms" not in err
