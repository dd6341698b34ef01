"""The bad-input campaign of issue 12, kept: malformed configurations, robot files, data files
and CLI arguments, each run with a time budget; prints the inputs tried per category and the
tracebacks and hangs found (both must be 0).

    .venv/bin/python benchmarks/fuzz_campaign.py [--scale N]

The targets and their input generators are the ones of ``tests/test_fuzz_inputs.py`` (the test
runs them with fewer examples); ``--scale`` multiplies the test's example counts (default 3).
Inputs are derandomized: the same command tries the same inputs. Exit status 1 when any
traceback or hang was found (the first few are printed).
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import tempfile
import time
import warnings
from collections import Counter
from pathlib import Path

from hypothesis import given, settings

ROOT = Path(__file__).resolve().parents[1]


def _load_targets():
    spec = importlib.util.spec_from_file_location("fuzz_inputs", ROOT / "tests" / "test_fuzz_inputs.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules["fuzz_inputs"] = mod
    spec.loader.exec_module(mod)
    return mod


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scale", type=int, default=3, help="examples per target = the test's × SCALE")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore", RuntimeWarning)  # NaN arithmetic on the way to a refusal
    fz = _load_targets()
    tried: Counter[str] = Counter()
    outcome: Counter[tuple[str, str]] = Counter()
    failures: list[str] = []
    t0 = time.perf_counter()
    def campaign(target, d: Path):
        @settings(max_examples=target.examples * args.scale, **fz.FUZZ_SETTINGS)
        @given(target.strategy)
        def one(case):
            tried[target.category] += 1
            try:
                result = target.check(case, d)
            except fz.Hang as exc:
                result = "hang"
                failures.append(f"hang: {target.category} / {target.name}: {case!r:.200} ({exc})")
            except fz.Traceback_ as exc:
                result = "traceback"
                failures.append(f"traceback: {target.category} / {target.name}: {case!r:.200}: {exc}")
            outcome[(target.category, result)] += 1

        one()

    for target in fz.TARGETS:
        with tempfile.TemporaryDirectory() as tmp:
            campaign(target, Path(tmp))
    elapsed = time.perf_counter() - t0
    print(f"{'category':<16} {'inputs':>7} {'refused':>8} {'accepted':>9} {'tracebacks':>11} {'hangs':>6}")
    for cat in dict.fromkeys(t.category for t in fz.TARGETS):
        print(f"{cat:<16} {tried[cat]:>7} {outcome[(cat, 'refused')]:>8} {outcome[(cat, 'accepted')]:>9} "
              f"{outcome[(cat, 'traceback')]:>11} {outcome[(cat, 'hang')]:>6}")
    n_tb = sum(v for (_, r), v in outcome.items() if r == "traceback")
    n_hang = sum(v for (_, r), v in outcome.items() if r == "hang")
    print(f"{'total':<16} {sum(tried.values()):>7} {'':>8} {'':>9} {n_tb:>11} {n_hang:>6}")
    print(f"inputs tried: {sum(tried.values())}, tracebacks: {n_tb}, hangs: {n_hang} "
          f"({elapsed:.1f} s, budget {fz.BUDGET_S} s per input)")
    for f in failures[:10]:
        print(" ", f)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
