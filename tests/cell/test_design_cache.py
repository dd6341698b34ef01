"""The correction design kept on disk between processes (issue 42): the same cell and code give the
same design without designing again, any input changed designs anew, a damaged file is ignored,
``off`` keeps nothing."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from station.cell.config.cell_config import load_config
from station.cell.correction import design as design_module
from station.cell.correction.design_cache import CACHE_ENV, load_design
from station.cell.plan.measurement_plan import build_plan

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "scara600" / "cell.toml"


def _same(a, b) -> None:
    """Two designs equal field by field (arrays by value)."""
    for f in dataclasses.fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if dataclasses.is_dataclass(x):
            _same(x, y)
        elif isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
            assert np.array_equal(x, y), f.name
        else:
            assert type(x) is type(y) and (x == y or (x != x and y != y)), (f.name, x, y)


@pytest.fixture
def cache(tmp_path, monkeypatch):
    folder = tmp_path / "designs"
    monkeypatch.setenv(CACHE_ENV, str(folder))
    monkeypatch.setattr(design_module, "_DESIGNS", {})  # a fresh process, as far as the design knows
    return folder


def _no_design(*args, **kwargs):
    raise AssertionError("designed again although the same design is kept")


def test_a_second_process_reads_the_kept_design_and_a_changed_bound_designs_anew(cache, monkeypatch):
    cfg = load_config(EXAMPLE)
    plan = build_plan(cfg)
    made = design_module.design_for(cfg, plan)
    files = list(cache.glob("*.json"))
    assert len(files) == 1 and load_design(files[0].stem) is not None
    monkeypatch.setattr(design_module, "_DESIGNS", {})
    monkeypatch.setattr(design_module, "design_table", _no_design)
    _same(design_module.design_for(cfg, plan), made)
    looser = dataclasses.replace(cfg, correction=dataclasses.replace(
        cfg.correction, max_interpolation_um=cfg.correction.max_interpolation_um + 1.0))
    with pytest.raises(AssertionError, match="designed again"):  # another bound: another design
        design_module.design_for(looser, plan)


@pytest.mark.slow  # an end-to-end session: the slow tier (README), run by CI
def test_a_damaged_file_is_designed_again_and_off_keeps_nothing(cache, monkeypatch):
    cfg = load_config(EXAMPLE)
    plan = build_plan(cfg)
    made = design_module.design_for(cfg, plan)
    (kept,) = cache.glob("*.json")
    kept.write_text(kept.read_text()[:100])  # a writer that died half-way
    monkeypatch.setattr(design_module, "_DESIGNS", {})
    _same(design_module.design_for(cfg, plan), made)
    assert load_design(kept.stem) is not None  # written whole again
    off = cache.parent / "off-cache"
    monkeypatch.setenv(CACHE_ENV, "off")
    monkeypatch.setattr(design_module, "_DESIGNS", {})
    design_module.design_for(cfg, plan)
    assert not off.exists() and len(list(cache.glob("*.json"))) == 1
