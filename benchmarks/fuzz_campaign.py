"""The bad-input campaign of issue 12, kept: malformed configurations, robot files, data files
and CLI arguments, each run with a time budget; prints the inputs tried per category and the
tracebacks and hangs found (both must be 0). Then the surfaces of issue 19 (``_fuzz_surfaces.py``):
damaged run-database records through runs/report/export/calibrate --resume, SIGTERM (once or
twice) at seeded random moments of a simulated calibration, and closed or early-closed stdout and
stderr; each prints the inputs tried, the exit codes, the internal errors and the hangs. Then the
families of issue 33 (``_fuzz_issue33.py``): record-level damage of every measured field, robot-file
typos, URDF structure, float limits, overflowing integers and a full disk; these count silent
acceptances too (exit 0 for an input that must be refused).

    .venv/bin/python benchmarks/fuzz_campaign.py [--scale N] [--only FAMILY[,FAMILY…]]

FAMILY: inputs, records, signals, pipes, fields, typos, urdf, floats, ints, disk (default: all).

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
#: the families of issue 33 (``_fuzz_issue33.py``): they count silent acceptances too
ISSUE33_FAMILIES = ("fields", "typos", "urdf", "floats", "ints", "disk")
ALL_FAMILIES = ("inputs", "records", "signals", "pipes", *ISSUE33_FAMILIES)


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
    ap.add_argument("--only", type=_families, help="these families, comma-separated: "
                    + ",".join(ALL_FAMILIES))
    args = ap.parse_args(argv)
    only = args.only or ALL_FAMILIES
    failures: list[str] = []
    n_tb = n_hang = n_tried = 0
    if "inputs" in only:
        n_tried, n_tb, n_hang = _inputs(args.scale, failures)
    if set(only) - {"inputs"}:
        n_tb_new, n_hang_new, n_tried_new = _new_surfaces(args.scale, only, failures)
        n_tb, n_hang, n_tried = n_tb + n_tb_new, n_hang + n_hang_new, n_tried + n_tried_new
    for f in failures:  # one line each, then the first few in full
        print(" ", f.splitlines()[0][:300])
    for f in failures[:3]:
        print("\n", f)
    n_silent = sum(f.startswith("silent acceptance") for f in failures)
    print(f"all families: {n_tried} tried, internal errors (tracebacks): {n_tb}, hangs: {n_hang}, "
          f"silent acceptances: {n_silent}")
    return 1 if failures else 0


def _families(text: str) -> tuple[str, ...]:
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    unknown = [n for n in names if n not in ALL_FAMILIES]
    if unknown or not names:
        raise argparse.ArgumentTypeError(f"{text!r}: families are {', '.join(ALL_FAMILIES)}")
    return names


def _new_surfaces(scale: int, only: tuple[str, ...], failures: list[str]) -> tuple[int, int, int]:
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import _fuzz_issue33 as f33
    import _fuzz_surfaces as fs

    families = {**fs.FAMILIES, **f33.FAMILIES}
    fams = [run(scale) for name, run in families.items() if name in only]
    codes = sorted({c for fam in fams for c in fam.by_exit})
    print()
    print(f"{'surface':<20} {'tried':>7} " + " ".join(f"{'exit ' + str(c):>8}" for c in codes)
          + f" {'internal':>9} {'hangs':>6} {'silent':>7} {'seconds':>8}")
    for fam in fams:
        print(f"{fam.name:<20} {fam.tried:>7} " + " ".join(f"{fam.by_exit[c]:>8}" for c in codes)
              + f" {fam.internal:>9} {fam.hangs:>6} {fam.silent:>7} {fam.elapsed_s:>8.1f}")
        failures.extend(fam.failures)
    n_int, n_hang = sum(f.internal for f in fams), sum(f.hangs for f in fams)
    n_tried, n_silent = sum(f.tried for f in fams), sum(f.silent for f in fams)
    print(f"surfaces tried: {n_tried}, internal errors: {n_int}, hangs: {n_hang}, silent acceptances: {n_silent} "
          f"({sum(f.elapsed_s for f in fams):.1f} s, budget {fs.BUDGET_S:.0f} s per command)")
    return n_int, n_hang, n_tried


def _inputs(scale: int, failures: list[str]) -> tuple[int, int, int]:
    warnings.simplefilter("ignore", RuntimeWarning)  # NaN arithmetic on the way to a refusal
    fz = _load_targets()
    tried: Counter[str] = Counter()
    outcome: Counter[tuple[str, str]] = Counter()
    t0 = time.perf_counter()
    def campaign(target, d: Path):
        @settings(max_examples=target.examples * scale, **fz.FUZZ_SETTINGS)
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
    return sum(tried.values()), n_tb, n_hang


if __name__ == "__main__":
    sys.exit(main())
