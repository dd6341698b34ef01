"""The benchmark scripts stay importable: they are run by hand, so an API change must not break
them silently (their figures are quoted in README)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

BENCHMARKS = sorted(p for p in (Path(__file__).resolve().parents[1] / "benchmarks").glob("*.py")
                    if not p.name.startswith("_"))  # _timing.py: shared helpers, no script


@pytest.mark.parametrize("path", BENCHMARKS, ids=[p.stem for p in BENCHMARKS])
def test_benchmark_imports_and_has_a_main(path):
    spec = importlib.util.spec_from_file_location(f"bench_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)  # their work is behind main(), not at import
    assert callable(getattr(module, "main", None)), f"{path.name} has no main()"
