"""The fuzz families of issue 33 (``benchmarks/_fuzz_issue33.py``), a few inputs each: robot-file
typos, URDF structure, float limits and overflowing integers give no internal error, no hang and no
silent acceptance (exit 0 for an input that must be refused). The campaign runs them at scale
(``benchmarks/fuzz_campaign.py``, README); the record-field and full-disk families need a stored
run and are covered here by ``tests/cell/test_record_fields.py`` and
``tests/test_float_limits_and_full_disk.py``."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"


@pytest.fixture(scope="module")
def families():
    sys.path.insert(0, str(BENCH))
    try:
        import _fuzz_issue33

        yield _fuzz_issue33
    finally:
        sys.path.remove(str(BENCH))


@pytest.mark.parametrize("name, scale, at_least", [("typos", 1, 100), ("urdf", 1, 30), ("floats", 1, 100),
                                                   ("ints", 1, 100)])
def test_a_family_finds_no_internal_error_no_hang_no_silent_acceptance(families, name, scale, at_least):
    fam = families.FAMILIES[name](scale)
    assert fam.tried >= at_least
    assert (fam.internal, fam.hangs, fam.silent) == (0, 0, 0), fam.failures[:5]


def test_the_harness_counts_a_silent_acceptance(families, tmp_path):
    """An input that should be refused but exits 0 is counted: the family would see a regression."""
    fam = families.Family("probe")
    families._one(fam, ["export-model", "sr800", "--format", "toml", "-o", str(tmp_path / "m.toml")], tmp_path,
                  "a good command", families._refused)
    assert fam.tried == 1 and fam.silent == 1 and fam.by_exit[0] == 1
